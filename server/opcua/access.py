"""Who may do what over OPC UA: the REST service's users, roles and permissions (docs/security.md).

Logins (OPC 10000-4 §7.36 identity tokens):

- *Username/password*: the user's name and one of its API tokens as the password (the same
  bearer token REST takes; ``pendant tokens create NAME`` makes one).
- *Certificate* (X509 identity token): a certificate registered for a user with
  ``pendant users cert NAME FILE`` (stored as a token derived from the certificate's SHA-256
  fingerprint: revocable and expiring like any token).
- *Anonymous*: a session, but every Read, Browse, subscription and Call is refused
  (``BadUserAccessDenied``), as REST answers 401 without a credential. With ``--no-auth``
  everyone is an Administrator, as on REST.

Every request after login is checked against the user's role at that moment (a revoked user
or a changed role takes effect at once): reading needs ``frames:read``; each method its own
permission (``METHOD_PERMISSIONS``). The user of the current request is in :data:`CURRENT`,
for the audit record of what the method changes (source ``opcua``).
"""

from __future__ import annotations

import contextvars
import time
import uuid
from dataclasses import dataclass, field
from typing import Any

from asyncua import ua
from asyncua.ua.ua_binary import struct_from_binary
from asyncua.crypto.permission_rules import PermissionRuleset, User, UserRole
from asyncua.server.user_managers import UserManager
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from db.auth_models import User as DbUser
from server.auth import tokens
from server.auth.tokens import certificate_secret

# requests that need no permission: opening and closing sessions and channels, discovery
SESSION_TYPES = {ua.NodeId(t) for t in (
    ua.ObjectIds.CreateSessionRequest_Encoding_DefaultBinary,
    ua.ObjectIds.ActivateSessionRequest_Encoding_DefaultBinary,
    ua.ObjectIds.CloseSessionRequest_Encoding_DefaultBinary,
    ua.ObjectIds.CloseSecureChannelRequest_Encoding_DefaultBinary,
    ua.ObjectIds.GetEndpointsRequest_Encoding_DefaultBinary,
    ua.ObjectIds.FindServersRequest_Encoding_DefaultBinary,
)}
# changing the address space itself: nobody from outside
ADMIN_TYPES = {ua.NodeId(t) for t in (
    ua.ObjectIds.AddNodesRequest_Encoding_DefaultBinary,
    ua.ObjectIds.DeleteNodesRequest_Encoding_DefaultBinary,
    ua.ObjectIds.AddReferencesRequest_Encoding_DefaultBinary,
    ua.ObjectIds.DeleteReferencesRequest_Encoding_DefaultBinary,
    ua.ObjectIds.RegisterServerRequest_Encoding_DefaultBinary,
    ua.ObjectIds.RegisterServer2Request_Encoding_DefaultBinary,
    ua.ObjectIds.WriteRequest_Encoding_DefaultBinary,  # values change through methods only
)}
CALL = ua.NodeId(ua.ObjectIds.CallRequest_Encoding_DefaultBinary)

#: the permission each method needs, by its browse name
METHOD_PERMISSIONS = {"ReadFrame": "frames:read", "ExportFile": "frames:read",
                      "CommitFrame": "frames:commit"}


@dataclass(frozen=True)
class Caller:
    """The user behind an OPC UA request, with the role and permissions in force now."""

    name: str
    role: str
    permissions: frozenset[str]

    def audit_actor(self, client: str | None = None) -> dict[str, Any]:
        """As :func:`server.auth.audit.actor` has it, source ``opcua``, a new request id."""
        return {"user_name": self.name, "role": self.role, "source": "opcua",
                "request_id": str(uuid.uuid4()), "client": client}


NO_AUTH = Caller("no-auth", "Administrator", frozenset({"*"}))
CURRENT: contextvars.ContextVar[Caller | None] = contextvars.ContextVar("pendant_opcua_caller",
                                                                       default=None)


@dataclass
class PendantUsers(UserManager):
    """asyncua's login hook: a user of pendant's user table, or None (login refused)."""

    make_session: sessionmaker[Session]
    auth: bool = True

    def get_user(self, iserver: object, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> User | None:
        if not self.auth:
            return User(role=UserRole.User, name=NO_AUTH.name)
        if username is None and certificate is None:
            return User(role=UserRole.Anonymous)  # a session that may do nothing
        secret = password if username is not None else certificate_secret(bytes(certificate))
        if not secret:
            return None
        with self.make_session() as db:
            found = tokens.actor_of_token(db, secret)
        if found is None or (username is not None and found[0].name != username):
            return None
        return User(role=UserRole.User, name=found[0].name)


@dataclass
class PendantRules(PermissionRuleset):
    """asyncua's per-request check: the caller's role must grant what the request needs."""

    make_session: sessionmaker[Session]
    auth: bool = True
    method_names: dict[ua.NodeId, str] = field(default_factory=dict)  # method node -> name
    ttl_s: float = 1.0
    _cache: dict[str, tuple[float, Caller | None]] = field(default_factory=dict)

    def caller(self, name: str) -> Caller | None:
        """The user's role and permissions now (cached ``ttl_s``); None if revoked or gone."""
        hit = self._cache.get(name)
        if hit is not None and time.monotonic() - hit[0] < self.ttl_s:
            return hit[1]
        with self.make_session() as db:
            u = db.scalar(select(DbUser).where(DbUser.name == name))
            found = None
            if u is not None and u.revoked_at is None:
                found = Caller(u.name, u.role, tokens.role_permissions(db, u.role))
        self._cache[name] = (time.monotonic(), found)
        return found

    def needs(self, action_type: ua.NodeId, body: Any) -> set[str]:
        """What the request needs; ``body`` is the undecoded request (asyncua's Buffer), so a
        call is decoded from a copy to see which methods it names (unknown: frames:commit)."""
        if action_type == CALL:
            call = struct_from_binary(ua.CallParameters, body.copy())
            return {METHOD_PERMISSIONS.get(self.method_names.get(m.MethodId, ""), "frames:commit")
                    for m in call.MethodsToCall or []}
        return {"frames:read"}

    def check_validity(self, user: User | None, action_type: ua.NodeId, body: Any) -> bool:
        if action_type in SESSION_TYPES:
            return True
        if action_type in ADMIN_TYPES:
            return False
        if not self.auth:
            CURRENT.set(NO_AUTH)
            return True
        if user is None or user.role == UserRole.Anonymous or not user.name:
            return False
        caller = self.caller(user.name)
        if caller is None or not self.needs(action_type, body) <= caller.permissions:
            return False
        CURRENT.set(caller)  # the request that follows runs in this context (the audit's who)
        return True
