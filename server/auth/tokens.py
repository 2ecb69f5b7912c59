"""Users, roles, API tokens and browser logins in the DB; secrets are kept only as SHA-256.

A token is ``pdt_`` + ``secrets.token_urlsafe(32)`` (256 random bits). With that much entropy a
single SHA-256 is the right store (no password stretching needed: nothing to guess), and
lookup is by the hash, so the secret never touches the DB or the logs.
"""

from __future__ import annotations

import hashlib
import secrets
import threading
import time
from dataclasses import dataclass
from datetime import datetime, timedelta

from sqlalchemy import event, select
from sqlalchemy.orm import Session

from db.auth_models import ApiToken, Role, User, WebSession
from db.crud import NotFound, StateConflict
from db.models import utcnow
from server.auth.permissions import DEFAULT_ROLES, IDLE_ROLE, PERMISSIONS

TOKEN_PREFIX = "pdt_"
BOOTSTRAP_USER = "admin"
CACHE_TTL_S = 0.5  # a verified token is trusted this long by one process (docs/security.md)
CACHE_MAX = 4096  # tokens remembered per process (the oldest entries go first)


def new_secret() -> str:
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def sha256(secret: str) -> str:
    return hashlib.sha256(secret.encode("utf-8")).hexdigest()


CERTIFICATE_PREFIX = "x509:sha256:"


def certificate_secret(der: bytes) -> str:
    """The token secret that stands for an X.509 certificate (its SHA-256 fingerprint): an OPC UA
    certificate login is a token of the user (``pendant users cert``), revocable and expiring.
    Anyone with the public certificate can compute it, so it is no bearer token or password:
    only a login that proved the certificate's key looks it up (:func:`actor_of_token`)."""
    return CERTIFICATE_PREFIX + hashlib.sha256(der).hexdigest()


def is_certificate_secret(secret: str) -> bool:
    return secret.startswith(CERTIFICATE_PREFIX)


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


def user_admins(db: Session) -> list[User]:
    """The active users whose role may administer users."""
    admin_roles = [r.name for r in list_roles(db) if "users:admin" in r.permissions]
    return [u for u in list_users(db) if u.role in admin_roles and u.revoked_at is None]


def revoke_user(db: Session, name: str) -> User:
    """Revoke a user with every token and browser login (the audit keeps their name); never the
    last active user who may administer users (StateConflict): nobody could then add a user
    or a token, and the first start's token could not be given to a new one."""
    u = get_user(db, name)
    if u.revoked_at is None and [a.id for a in user_admins(db)] == [u.id]:
        raise StateConflict(("path", "user_name"), f"{name!r} is the last active user who may "
                            "administer users; add another (e.g. an Administrator) first")
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


def actor_of_token(db: Session, secret: str, certificate: bool = False) -> tuple[User, Role] | None:
    """The user and role of a valid (known, unexpired, unrevoked) bearer token, else None. A
    certificate's secret (public data) only with ``certificate`` (a login that proved its key),
    and a token only without."""
    if is_certificate_secret(secret) != certificate:
        return None
    found = _actor_of_digest(db, sha256(secret))
    return None if found is None else found[0]


def _actor_of_digest(db: Session, digest: str) -> tuple[tuple[User, Role], datetime | None] | None:
    """((user, role), the token's expiry) of a valid token by its SHA-256, else None."""
    t = db.scalar(select(ApiToken).where(ApiToken.token_sha256 == digest))
    now = utcnow()
    if t is None or t.revoked_at is not None or (t.expires_at and t.expires_at <= now):
        return None
    u = db.get(User, t.user_id)
    if not _active(u):
        return None
    return (u, db.get(Role, u.role)), t.expires_at  # type: ignore[union-attr, return-value]


class TokenCache:
    """Verified bearer tokens of this process, each trusted for at most ``CACHE_TTL_S``.

    A request whose token was verified less than ``CACHE_TTL_S`` ago skips the three lookups
    (token, user, role) and the thread they need. The bound on revocation: a change of a
    token, user or role made by *this* process empties the cache when it is flushed and again
    when it commits (hooks :func:`_forget_on_change`, :func:`_forget_on_commit`), and every
    emptying starts a new *generation*: a lookup that began in an older generation (it may
    have read the row before the revoke committed) stores nothing. So here a revoked token is
    refused on its next request after the commit; another process (the CLI, another worker or
    host) refuses it within ``CACHE_TTL_S``. An entry never outlives the token's own expiry.
    Keys are the secrets' SHA-256, never the secrets.
    """

    def __init__(self, ttl_s: float = CACHE_TTL_S, max_entries: int = CACHE_MAX) -> None:
        self.ttl_s, self.max_entries = ttl_s, max_entries
        self._entries: dict[str, tuple[float, Actor]] = {}
        self._lock = threading.Lock()
        self.generation = 0  # +1 at every clear

    def get(self, digest: str) -> Actor | None:
        hit = self._entries.get(digest)
        if hit is None or hit[0] <= time.monotonic():
            return None
        return hit[1]

    def put(self, digest: str, actor: Actor, expires_at: datetime | None,
            generation: int | None = None) -> bool:
        """Remember ``actor``, unless the cache was emptied since ``generation`` (the value of
        :attr:`generation` read before the lookup began); True if it was stored."""
        until = time.monotonic() + self.ttl_s
        if expires_at is not None:  # never trusted past the token's own expiry
            until = min(until, time.monotonic() + (expires_at - utcnow()).total_seconds())
        with self._lock:
            if generation is not None and generation != self.generation:
                return False
            if len(self._entries) >= self.max_entries:
                self._entries.pop(next(iter(self._entries)))
            self._entries[digest] = (until, actor)
            return True

    def clear(self) -> None:
        with self._lock:
            self._entries.clear()
            self.generation += 1


CACHE = TokenCache()
_AUTH_ROWS = (ApiToken, User, Role)
_CHANGED = "pendant_auth_changed"  # Session.info key: this transaction changed auth rows


def _forget_on_change(db: Session, _ctx: object, _instances: object) -> None:
    """Empty :data:`CACHE` when a flush changes a token, user or role (revocations included),
    and mark the session so that its commit empties it again."""
    if any(isinstance(o, _AUTH_ROWS) for o in (*db.dirty, *db.deleted)):
        db.info[_CHANGED] = True
        CACHE.clear()


def _forget_on_commit(db: Session) -> None:
    """After the commit of a change of auth rows: empty :data:`CACHE` once more (a lookup
    between the flush and the commit read the old row and may have stored it)."""
    if db.info.pop(_CHANGED, False):
        CACHE.clear()


def _forget_mark(db: Session, _previous: object = None) -> None:
    db.info.pop(_CHANGED, None)


def install_cache_hook() -> None:
    """Hook every ORM session (idempotent)."""
    if not event.contains(Session, "before_flush", _forget_on_change):
        event.listen(Session, "before_flush", _forget_on_change)
    if not event.contains(Session, "after_commit", _forget_on_commit):
        event.listen(Session, "after_commit", _forget_on_commit)
    if not event.contains(Session, "after_soft_rollback", _forget_mark):
        event.listen(Session, "after_soft_rollback", _forget_mark)


def verified_actor(db_factory, digest: str) -> Actor | None:  # noqa: ANN001
    """The actor of a valid bearer token by its SHA-256, read from the DB (``db_factory()``
    gives a session) and remembered in :data:`CACHE` (unless the cache was emptied while it
    was read); None for an unknown, expired or revoked token. Callers look in
    ``CACHE.get(digest)`` first (it needs no thread)."""
    generation = CACHE.generation
    with db_factory() as db:
        found = _actor_of_digest(db, digest)
    if found is None:
        return None
    (user, role), expires_at = found
    actor = Actor(user.name, role.name, frozenset(role.permissions), "api")
    CACHE.put(digest, actor, expires_at, generation)
    return actor


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
    admins = user_admins(db)
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
