"""Users, roles, API tokens and browser logins in the DB; secrets are kept only as SHA-256.

A token is ``pdt_`` + ``secrets.token_urlsafe(32)`` (256 random bits). With that much entropy a
single SHA-256 is the right store (no password stretching needed: nothing to guess), and
lookup is by the hash, so the secret never touches the DB or the logs.
"""

from __future__ import annotations

import hashlib
import secrets
from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.auth_models import ApiToken, Role, User, WebSession
from db.crud import NotFound, StateConflict
from db.models import utcnow
from server.auth.permissions import DEFAULT_ROLES, IDLE_ROLE, PERMISSIONS

TOKEN_PREFIX = "pdt_"
BOOTSTRAP_USER = "admin"


def new_secret() -> str:
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def sha256(secret: str) -> str:
    return hashlib.sha256(secret.encode("utf-8")).hexdigest()


def certificate_secret(der: bytes) -> str:
    """The token secret that stands for an X.509 certificate (its SHA-256 fingerprint): an OPC UA
    certificate login is a token of the user (``pendant users cert``), revocable and expiring."""
    return "x509:sha256:" + hashlib.sha256(der).hexdigest()


@dataclass(frozen=True)
class Actor:
    """Who is asking: the user, the role in effect (Operator after the idle timeout), its
    permissions and the face the request came through (api | pendant | cli)."""

    name: str | None
    role: str | None
    permissions: frozenset[str]
    source: str
    idle: bool = False

    def can(self, permission: str) -> bool:
        return permission in self.permissions


# ---------------------------------------------------------------------------------- roles

def role_permissions(db: Session, role: str) -> frozenset[str]:
    r = db.get(Role, role)
    return frozenset(r.permissions) if r is not None else frozenset()


def list_roles(db: Session) -> list[Role]:
    return list(db.scalars(select(Role).order_by(Role.name)))


def add_role(db: Session, name: str, permissions: list[str], description: str = "") -> Role:
    """A site-defined role; every permission must be one of PERMISSIONS."""
    unknown = [p for p in permissions if p not in PERMISSIONS]
    if unknown:
        raise ValueError(f"permissions: unknown {', '.join(unknown)}; one of "
                         f"{', '.join(PERMISSIONS)}")
    if not name or len(name) > 32:
        raise ValueError("name: 1..32 characters")
    if db.get(Role, name) is not None:
        raise StateConflict(("body", "name"), f"a role named {name!r} exists already")
    r = Role(name=name, permissions=list(permissions), description=description)
    db.add(r)
    db.flush()
    return r


def ensure_default_roles(db: Session) -> None:
    """The default roles exist (revision 0003_auth seeds them; a DB made otherwise gets them)."""
    for name, perms in DEFAULT_ROLES.items():
        if db.get(Role, name) is None:
            db.add(Role(name=name, permissions=list(perms), description="default role"))
    db.flush()


# ---------------------------------------------------------------------------------- users

def get_user(db: Session, name: str) -> User:
    u = db.scalar(select(User).where(User.name == name))
    if u is None:
        raise NotFound(("user_name",), f"no user {name!r}")
    return u


def list_users(db: Session) -> list[User]:
    return list(db.scalars(select(User).order_by(User.id)))


def add_user(db: Session, name: str, role: str) -> User:
    if not name or len(name) > 64 or not name.isprintable():
        raise ValueError("name: 1..64 printable characters")
    if db.get(Role, role) is None:
        roles = ", ".join(r.name for r in list_roles(db))
        raise ValueError(f"role: unknown role {role!r}; one of {roles}")
    if db.scalar(select(User).where(User.name == name)) is not None:
        raise StateConflict(("body", "name"), f"a user named {name!r} exists already")
    u = User(name=name, role=role)
    db.add(u)
    db.flush()
    return u


def revoke_user(db: Session, name: str) -> User:
    """Revoke a user with every token and browser login (the audit keeps their name)."""
    u = get_user(db, name)
    now = utcnow()
    u.revoked_at = u.revoked_at or now
    for t in db.scalars(select(ApiToken).where(ApiToken.user_id == u.id,
                                               ApiToken.revoked_at.is_(None))):
        t.revoked_at = now
    for s in db.scalars(select(WebSession).where(WebSession.user_id == u.id,
                                                 WebSession.ended_at.is_(None))):
        s.ended_at = now
    db.flush()
    return u


def create_token(db: Session, user: User, days: float | None = 90.0, label: str = "",
                 secret: str | None = None) -> str:
    """A new bearer token of ``user`` (returned once, stored hashed); ``days`` None = no expiry."""
    if user.revoked_at is not None:
        raise StateConflict(("path", "user_name"), f"user {user.name!r} is revoked")
    if days is not None and not 0 < days <= 3650:
        raise ValueError("days: must be > 0 and <= 3650")
    secret = secret or new_secret()
    expires = None if days is None else utcnow() + timedelta(days=days)
    db.add(ApiToken(user_id=user.id, token_sha256=sha256(secret), label=label[:64],
                    expires_at=expires))
    db.flush()
    return secret


def list_tokens(db: Session, user: User | None = None) -> list[ApiToken]:
    q = select(ApiToken).order_by(ApiToken.id)
    return list(db.scalars(q if user is None else q.where(ApiToken.user_id == user.id)))


def revoke_token(db: Session, token_id: int) -> ApiToken:
    t = db.get(ApiToken, token_id)
    if t is None:
        raise NotFound(("token_id",), f"no token {token_id}")
    t.revoked_at = t.revoked_at or utcnow()
    db.flush()
    return t


def _active(u: User | None) -> bool:
    return u is not None and u.revoked_at is None


def actor_of_token(db: Session, secret: str) -> tuple[User, Role] | None:
    """The user and role of a valid (known, unexpired, unrevoked) bearer token, else None."""
    t = db.scalar(select(ApiToken).where(ApiToken.token_sha256 == sha256(secret)))
    now = utcnow()
    if t is None or t.revoked_at is not None or (t.expires_at and t.expires_at <= now):
        return None
    u = db.get(User, t.user_id)
    if not _active(u):
        return None
    return u, db.get(Role, u.role)  # type: ignore[union-attr, return-value]


# -------------------------------------------------------------------------- browser logins

def start_web_session(db: Session, user: User, lifetime_s: float) -> tuple[str, str]:
    """A browser login of ``user``: (cookie secret, CSRF token)."""
    cookie, csrf = new_secret(), secrets.token_urlsafe(32)
    now = utcnow()
    db.add(WebSession(user_id=user.id, cookie_sha256=sha256(cookie), csrf_token=csrf,
                      created_at=now, last_seen_at=now,
                      expires_at=now + timedelta(seconds=lifetime_s)))
    db.flush()
    return cookie, csrf


def web_session(db: Session, cookie: str) -> tuple[WebSession, User] | None:
    s = db.scalar(select(WebSession).where(WebSession.cookie_sha256 == sha256(cookie)))
    if s is None or s.ended_at is not None or s.expires_at <= utcnow():
        return None
    u = db.get(User, s.user_id)
    return (s, u) if _active(u) else None  # type: ignore[return-value]


def web_actor(db: Session, s: WebSession, u: User, idle_timeout_s: float,
              now: datetime | None = None) -> Actor:
    """The login's actor; after ``idle_timeout_s`` without a command, the role is Operator."""
    now = now or utcnow()
    idle = (now - s.last_seen_at).total_seconds() > idle_timeout_s
    role = IDLE_ROLE if idle and u.role != IDLE_ROLE else u.role
    perms = role_permissions(db, role)
    if idle:  # never more than the user's own role
        perms &= role_permissions(db, u.role)
    return Actor(u.name, role, perms, "pendant", idle)


# ------------------------------------------------------------------------------ bootstrap

def bootstrap_admin(db: Session, secret: str | None) -> str | None:
    """On first start (no active user may administer users) create an Administrator.

    Its token is ``secret`` (from the environment / settings) or a new one, returned so the
    CLI can print it once; None when an administrator exists already (``secret``, if given
    and unknown, is then added to the first administrator, so a fixed deployment token works
    across restarts)."""
    ensure_default_roles(db)
    admin_roles = [r.name for r in list_roles(db) if "users:admin" in r.permissions]
    admins = [u for u in list_users(db) if u.role in admin_roles and u.revoked_at is None]
    if admins:
        if secret and db.scalar(select(ApiToken).where(
                ApiToken.token_sha256 == sha256(secret))) is None:
            create_token(db, admins[0], days=None, label="bootstrap", secret=secret)
        return None
    name, k = BOOTSTRAP_USER, 1
    while db.scalar(select(User).where(User.name == name)) is not None:
        k += 1
        name = f"{BOOTSTRAP_USER}{k}"
    u = add_user(db, name, "Administrator")
    return create_token(db, u, days=None if secret else 1.0, label="bootstrap", secret=secret)
