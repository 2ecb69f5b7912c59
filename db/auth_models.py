"""Users, roles, API tokens, browser sessions and the audit trail (revision 0003_auth).

Secrets are never stored: a token or a browser session is kept as the SHA-256 of its random
value (``secrets.token_urlsafe(32)``, 256 bits, so a fast hash is enough; see
server/auth/tokens.py). The audit table has no foreign key: deleting a controller or
restoring a backup cascades through the tables it owns and never reaches the audit.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import JSON, ForeignKey, String
from sqlalchemy.orm import Mapped, mapped_column

from db.models import NO_ID_REUSE, Base, utcnow


class Role(Base):
    """A role: a named set of permissions (the defaults Operator .. Administrator, or a site's)."""

    __tablename__ = "auth_role"

    name: Mapped[str] = mapped_column(String(32), primary_key=True)
    permissions: Mapped[list[str]] = mapped_column(JSON)  # server.auth.permissions.PERMISSIONS
    description: Mapped[str] = mapped_column(String(200), default="")


class User(Base):
    """A person (or a cell computer) with one role; revoked users keep their audit records."""

    __tablename__ = "auth_user"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    role: Mapped[str] = mapped_column(ForeignKey("auth_role.name"))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    revoked_at: Mapped[datetime | None]
    # revision 0009: the RWS face's HTTP Digest secret, kept as its HA1 =
    # MD5("name:realm:password") (server/rws/digest.py; pendant users rws-password NAME)
    rws_ha1: Mapped[str | None] = mapped_column(String(64))


class ApiToken(Base):
    """A bearer token of a user: its SHA-256, expiry, revocation."""

    __tablename__ = "auth_token"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("auth_user.id", ondelete="CASCADE"),
                                         index=True)
    token_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    label: Mapped[str] = mapped_column(String(64), default="")
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    expires_at: Mapped[datetime | None]
    revoked_at: Mapped[datetime | None]


class WebSession(Base):
    """A browser login: the cookie's SHA-256, its CSRF token, the last request (idle timeout)."""

    __tablename__ = "auth_web_session"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("auth_user.id", ondelete="CASCADE"),
                                         index=True)
    cookie_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    csrf_token: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    last_seen_at: Mapped[datetime] = mapped_column(default=utcnow)
    expires_at: Mapped[datetime]
    ended_at: Mapped[datetime | None]


class AuditRecord(Base):
    """One change: who, when, from where, what, before -> after. Append-only, no foreign key."""

    __tablename__ = "audit_record"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    at: Mapped[datetime] = mapped_column(default=utcnow, index=True)
    user_name: Mapped[str | None] = mapped_column(String(64), index=True)
    role: Mapped[str | None] = mapped_column(String(32))
    source: Mapped[str] = mapped_column(String(16))  # api | pendant | cli | opcua | system
    request_id: Mapped[str | None] = mapped_column(String(64))
    client: Mapped[str | None] = mapped_column(String(64))
    action: Mapped[str] = mapped_column(String(32))  # frame.calibration, controller.delete, ...
    controller_id: Mapped[int | None] = mapped_column(index=True)
    entry_table: Mapped[str | None] = mapped_column(String(8))
    number: Mapped[int | None]
    session_id: Mapped[int | None]
    before: Mapped[dict[str, Any] | None]
    after: Mapped[dict[str, Any] | None]
    quality: Mapped[dict[str, Any] | None]  # a calibration's rms/max/95 % bound (mm)
