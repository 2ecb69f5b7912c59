"""Who may do what over OPC UA: the REST service's users, roles and permissions (docs/security.md).

Logins (OPC 10000-4 §7.36 identity tokens), only on a signed and encrypted channel:

- *Username/password*: the user's name and one of its API tokens as the password (the same
  bearer token REST takes; ``pendant tokens create NAME``). The token must come encrypted
  with the server's key together with the session's server nonce (a plaintext password, or
  one captured from another session, is refused).
- *Certificate* (X509 identity token): a certificate registered for a user with
  ``pendant users cert NAME FILE``, with the client's signature over the server's
  certificate and nonce (the proof it holds the private key), valid now. The certificate a
  client opens its channel with is *not* a login.
- *Anonymous*: refused (``BadIdentityTokenRejected``), as REST answers 401 without a
  credential. With ``--no-auth`` (loopback only) everyone is an Administrator, as on REST.

Every request after login is checked against the login's token and the user's role at that
moment (a revoked token or user, or a changed role, takes effect within ``ttl_s``): reading
needs ``frames:read``; each of pendant's methods checks its own permission
(:data:`server.auth.permissions.OPCUA_METHODS`) and fails only its own call result. The user
of the current request is in :data:`CURRENT`, for the audit record (source ``opcua``).
"""

from __future__ import annotations

import contextvars
import secrets
import time
import uuid
from dataclasses import dataclass, field
from struct import error as StructError
from struct import unpack_from
from typing import Any

from asyncua import ua
from asyncua.common.utils import ServiceError
from asyncua.crypto import uacrypto
from asyncua.crypto.permission_rules import PermissionRuleset, User, UserRole
from asyncua.server.user_managers import UserManager
from asyncua.ua.ua_binary import struct_from_binary
from cryptography import x509
from sqlalchemy.orm import Session, sessionmaker

from server.auth import tokens
from server.auth.permissions import BACKUP_EXPORT, OPCUA_METHODS, required
from server.auth.tokens import certificate_secret
from server.opcua import pki

# requests that need no permission: opening and closing sessions and channels, discovery
SESSION_TYPES = {ua.NodeId(t) for t in (
    ua.ObjectIds.CreateSessionRequest_Encoding_DefaultBinary,
    ua.ObjectIds.ActivateSessionRequest_Encoding_DefaultBinary,
    ua.ObjectIds.CloseSessionRequest_Encoding_DefaultBinary,
    ua.ObjectIds.CloseSecureChannelRequest_Encoding_DefaultBinary,
    ua.ObjectIds.GetEndpointsRequest_Encoding_DefaultBinary,
    ua.ObjectIds.FindServersRequest_Encoding_DefaultBinary,
)}
# a discovery server's registrations: asyncua serves them without a session or a permission
# check, so the face refuses them itself (it is no discovery server)
REGISTER_TYPES = {ua.NodeId(t) for t in (
    ua.ObjectIds.RegisterServerRequest_Encoding_DefaultBinary,
    ua.ObjectIds.RegisterServer2Request_Encoding_DefaultBinary,
)}
# requests asyncua serves without a session (the rest need one: else BadSessionIdInvalid)
SESSIONLESS_TYPES = SESSION_TYPES | REGISTER_TYPES
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
# requests naming subscriptions: only their owner (the same user) may use them
_R = ua.ObjectIds
SUBSCRIPTION_REQUESTS: dict[ua.NodeId, tuple[type, str]] = {
    ua.NodeId(t): (params, attr) for t, params, attr in (
        (_R.TransferSubscriptionsRequest_Encoding_DefaultBinary,
         ua.TransferSubscriptionsParameters, "SubscriptionIds"),
        (_R.DeleteSubscriptionsRequest_Encoding_DefaultBinary,
         ua.DeleteSubscriptionsParameters, "SubscriptionIds"),
        (_R.SetPublishingModeRequest_Encoding_DefaultBinary,
         ua.SetPublishingModeParameters, "SubscriptionIds"),
        (_R.ModifySubscriptionRequest_Encoding_DefaultBinary,
         ua.ModifySubscriptionParameters, "SubscriptionId"),
        (_R.RepublishRequest_Encoding_DefaultBinary, ua.RepublishParameters, "SubscriptionId"),
        (_R.CreateMonitoredItemsRequest_Encoding_DefaultBinary,
         ua.CreateMonitoredItemsParameters, "SubscriptionId"),
        (_R.ModifyMonitoredItemsRequest_Encoding_DefaultBinary,
         ua.ModifyMonitoredItemsParameters, "SubscriptionId"),
        (_R.DeleteMonitoredItemsRequest_Encoding_DefaultBinary,
         ua.DeleteMonitoredItemsParameters, "SubscriptionId"),
        (_R.SetMonitoringModeRequest_Encoding_DefaultBinary,
         ua.SetMonitoringModeParameters, "SubscriptionId"),
        (_R.SetTriggeringRequest_Encoding_DefaultBinary, ua.SetTriggeringParameters,
         "SubscriptionId"),
        (_R.PublishRequest_Encoding_DefaultBinary, ua.PublishParameters,
         "SubscriptionAcknowledgements"),  # asyncua applied any subscription's acks
    )}
SUBSCRIPTIONS_PER_USER = 100  # of the server's 1000 (asyncua's max_subscriptions)
MIN_PUBLISHING_MS = 50.0  # a subscription's fastest publishing interval (asyncua grants any)
SESSIONS_PER_USER = 50  # activated at once, of the server's 1000 (InternalSession.max_connections)
# monitored items of one user's subscriptions (asyncua has no cap: ~1.5 KB each, so 100 000
# of one Operator took 143 MB); a plant's MES watching 300 cells' axes and frames needs ~16 000
MONITORED_ITEMS_PER_USER = 50_000
# standard methods a reader may call (OPC 10000-5 §9): they only read
READ_METHODS = {ua.NodeId(m) for m in (_R.Server_GetMonitoredItems, _R.Server_ResendData)}


def method_permission(method: str, fmt: object = None) -> set[str]:
    """What calling pendant's ``method`` needs: what its REST route needs (one table), and for
    ``ExportFile("json")`` (a backup) what ``GET /export?format=json`` also needs."""
    need = {required(*OPCUA_METHODS[method]) or "controllers:admin"}
    if method == "ExportFile" and fmt == "json":
        need.add(BACKUP_EXPORT)
    return need


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

    def may(self, need: set[str]) -> bool:
        return "*" in self.permissions or need <= self.permissions


NO_AUTH = Caller("no-auth", "Administrator", frozenset({"*"}))
CURRENT: contextvars.ContextVar[Caller | None] = contextvars.ContextVar("pendant_opcua_caller",
                                                                       default=None)


@dataclass(frozen=True)
class Channel:
    """The secure channel a connection's requests come on (set when it is opened: asyncua
    handles each connection's messages in one task, so this holds for all of them)."""

    mode: ua.MessageSecurityMode
    peer_certificate: bytes | None


CHANNEL: contextvars.ContextVar[Channel | None] = contextvars.ContextVar("pendant_opcua_channel",
                                                                        default=None)
# the address of the client a request comes from (the audit's client, as REST's and RWS's)
PEER: contextvars.ContextVar[str | None] = contextvars.ContextVar("pendant_opcua_peer",
                                                                 default=None)
# the session an ActivateSession is for (set by the face's processor before asyncua's handling)
ACTIVATING: contextvars.ContextVar[Any] = contextvars.ContextVar("pendant_opcua_activating",
                                                                default=None)


def _signed() -> bool:
    ch = CHANNEL.get()
    return ch is not None and ch.mode in (ua.MessageSecurityMode.Sign,
                                          ua.MessageSecurityMode.SignAndEncrypt)


class VerifiedCertificate(bytes):
    """An X509 identity token's certificate whose signature over the server's certificate and
    nonce was checked: only this is a certificate login (a channel's certificate is not)."""


@dataclass
class PendantUser(User):
    """asyncua's session user, with the token secret the login was made with."""

    secret: str | None = None


def install_login_checks(iserver: Any) -> None:
    """Wrap asyncua's identity token handling: passwords only encrypted with the session's
    server nonce and certificate logins only with a verified signature, both on a signed
    channel. (asyncua accepts plaintext, never checks the nonce, and takes the channel's
    certificate as a certificate login.)"""
    verify_x509 = iserver.verify_x509_token

    def decrypt_user_token(isession: Any, token: ua.UserNameIdentityToken) -> tuple[str, str]:
        if not _signed() or not token.EncryptionAlgorithm or not token.Password:
            raise ServiceError(ua.StatusCodes.BadIdentityTokenInvalid)
        decrypt = {"http://www.w3.org/2001/04/xmlenc#rsa-oaep": uacrypto.decrypt_rsa_oaep,
                   "http://opcfoundation.org/UA/security/rsa-oaep-sha2-256":
                       uacrypto.decrypt_rsa_oaep_sha256}.get(token.EncryptionAlgorithm)
        if decrypt is None:  # rsa-1_5 (Basic128Rsa15) is not offered
            raise ServiceError(ua.StatusCodes.BadIdentityTokenInvalid)
        try:
            raw = decrypt(iserver.private_key, token.Password)
            length = unpack_from("<I", raw)[0]
        except (ValueError, TypeError, StructError):  # not encrypted with our key
            raise ServiceError(ua.StatusCodes.BadIdentityTokenInvalid) from None
        nonce = isession.nonce or b""
        body = raw[4:4 + length]
        if not nonce or length != len(body) or length < len(nonce) or body[-len(nonce):] != nonce:
            raise ServiceError(ua.StatusCodes.BadIdentityTokenInvalid)  # replayed or no nonce
        try:
            return token.UserName, body[:-len(nonce)].decode("utf-8")
        except UnicodeDecodeError:
            raise ServiceError(ua.StatusCodes.BadIdentityTokenInvalid) from None

    def verify_x509_token(isession: Any, token: ua.X509IdentityToken,
                          signature: ua.SignatureData) -> bytes:
        if not _signed():
            raise ServiceError(ua.StatusCodes.BadIdentityTokenRejected)
        der = verify_x509(isession, token, signature)  # raises without a valid signature
        if pki.check_time(x509.load_der_x509_certificate(der)) is not None:
            raise ServiceError(ua.StatusCodes.BadIdentityTokenRejected)
        return VerifiedCertificate(der)

    iserver.decrypt_user_token = decrypt_user_token
    iserver.verify_x509_token = verify_x509_token


def unguessable_subscription_ids(service: Any) -> None:
    """Subscription ids drawn at random (asyncua counts up from 78: easy to guess), at most
    :data:`SUBSCRIPTIONS_PER_USER` of one user (asyncua's one cap is the server's 1000: one
    user took them all, and everyone else's were refused), publishing every
    :data:`MIN_PUBLISHING_MS` at the fastest (at 0.001 ms, 100 of them took a core)."""
    create = service.create_subscription

    async def create_subscription(params: Any, callback: Any, session_id: ua.NodeId,
                                  *args: Any, **kwargs: Any) -> Any:
        users = _user_names(service)
        mine = [sub for sub in service.subscriptions.values()
                if users.get(sub.session_id) == users.get(session_id)]
        if users.get(session_id) is not None and len(mine) >= SUBSCRIPTIONS_PER_USER:
            raise ServiceError(ua.StatusCodes.BadTooManySubscriptions)
        params.RequestedPublishingInterval = max(params.RequestedPublishingInterval or 0.0,
                                                 MIN_PUBLISHING_MS)
        while True:
            service._sub_id_counter = secrets.randbelow(2 ** 31 - 2) + 1  # it adds one
            if service._sub_id_counter + 1 not in service.subscriptions:
                return await create(params, callback, session_id, *args, **kwargs)

    service.create_subscription = create_subscription


def bounded_monitored_items(service: Any) -> None:
    """At most :data:`MONITORED_ITEMS_PER_USER` monitored items in all of one user's
    subscriptions (asyncua has no cap)."""
    create_items = service.create_monitored_items

    async def create_monitored_items(params: Any) -> Any:
        sub = service.subscriptions.get(params.SubscriptionId)
        users = _user_names(service)
        owner = None if sub is None else users.get(sub.session_id)
        if owner is not None:
            held = sum(len(s.monitored_item_srv._monitored_items)
                       for s in service.subscriptions.values() if users.get(s.session_id) == owner)
            if held + len(params.ItemsToCreate or []) > MONITORED_ITEMS_PER_USER:
                raise ServiceError(ua.StatusCodes.BadTooManyMonitoredItems)
        return await create_items(params)

    service.create_monitored_items = create_monitored_items


def _user_names(service: Any) -> dict[ua.NodeId, str | None]:
    """Each session's user name, by session id."""
    return {s.session_id: getattr(s.user, "name", None)
            for s in service.iserver._external_sessions.values()}


def unguessable_session_tokens(iserver: Any) -> None:
    """Sessions' AuthenticationTokens of 32 random bytes (asyncua counts up from 1000: a
    client that guessed one could name another client's session on a channel of its own)."""
    create = iserver.create_session

    def create_session(*args: Any, **kwargs: Any) -> Any:
        session = create(*args, **kwargs)
        if session.external:
            iserver.unregister_external_session(session)
            session.auth_token = ua.NodeId(secrets.token_bytes(32), 0, ua.NodeIdType.ByteString)
            iserver.register_external_session(session)
        return session

    iserver.create_session = create_session


def republish_with_status(service: Any) -> None:
    """Republish of a message the server no longer holds answers ``BadMessageNotAvailable``
    (of an unknown subscription ``BadSubscriptionIdInvalid``), as OPC 10000-4 §5.13.6 has it.
    asyncua answers Good with an empty message: after a restart of the face, node-opcua asked
    again at once, forever (~2,500 requests/s)."""
    def republish(params: ua.RepublishParameters) -> ua.NotificationMessage:
        sub = service.subscriptions.get(params.SubscriptionId)
        if sub is None:
            raise ServiceError(ua.StatusCodes.BadSubscriptionIdInvalid)
        if params.RetransmitSequenceNumber not in sub._not_acknowledged_results:
            raise ServiceError(ua.StatusCodes.BadMessageNotAvailable)
        return sub.republish(params.RetransmitSequenceNumber)

    service.republish = republish


@dataclass
class PendantUsers(UserManager):
    """asyncua's login hook: a user of pendant's user table, or None (login refused)."""

    make_session: sessionmaker[Session]
    auth: bool = True

    def get_user(self, iserver: object, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> User | None:
        if CHANNEL.get() is None:
            return None  # a discovery-only channel (no endpoint of that policy is offered)
        if not self.auth:
            return PendantUser(role=UserRole.User, name=NO_AUTH.name)
        if username is not None:
            secret = password
        elif isinstance(certificate, VerifiedCertificate):
            secret = certificate_secret(bytes(certificate))
        else:
            return None  # anonymous, or only a channel's certificate: not a login
        if not secret:
            return None
        with self.make_session() as db:  # a password is never a certificate's fingerprint
            found = tokens.actor_of_token(db, secret, certificate=username is None)
        if found is None or (username is not None and found[0].name != username):
            return None
        this = ACTIVATING.get()
        others = [s for s in getattr(iserver, "_external_sessions", {}).values()
                  if s is not this and s.is_activated()
                  and getattr(s.user, "name", None) == found[0].name]
        if len(others) >= SESSIONS_PER_USER:  # else one user's sessions locked everyone out
            raise ServiceError(ua.StatusCodes.BadTooManySessions)
        return PendantUser(role=UserRole.User, name=found[0].name, secret=secret)


@dataclass
class PendantRules(PermissionRuleset):
    """asyncua's per-request check: the caller's token and role must grant what it needs."""

    make_session: sessionmaker[Session]
    auth: bool = True
    method_names: dict[ua.NodeId, str] = field(default_factory=dict)  # method node -> name
    ttl_s: float = 0.5
    iserver: Any = None  # for the owners of subscriptions
    _cache: dict[str, tuple[float, Caller | None]] = field(default_factory=dict)

    def caller(self, secret: str, fresh: bool = False) -> Caller | None:
        """The login's user, role and permissions now (cached ``ttl_s`` unless ``fresh``);
        None if its token or user was revoked, or expired."""
        hit = self._cache.get(secret)
        if not fresh and hit is not None and time.monotonic() - hit[0] < self.ttl_s:
            return hit[1]
        with self.make_session() as db:  # a session's secret: its login checked it
            found = tokens.actor_of_token(db, secret, tokens.is_certificate_secret(secret))
            caller = None if found is None else Caller(
                found[0].name, found[0].role, tokens.role_permissions(db, found[0].role))
        if len(self._cache) > 10_000:
            self._cache.clear()
        self._cache[secret] = (time.monotonic(), caller)
        return caller

    def revoked(self, user: User | None) -> bool:
        """Whether the session's login no longer holds (its token or user revoked, expired)."""
        secret = getattr(user, "secret", None)
        return self.auth and bool(secret) and self.caller(secret) is None

    def needs(self, action_type: ua.NodeId, body: Any) -> set[str]:
        """What the request needs; ``body`` is the undecoded request (asyncua's Buffer), so a
        call is decoded from a copy to see which methods it names. pendant's methods check
        their own permission (a refusal fails only that call's result); a standard method that
        only reads needs ``frames:read``, any other ``controllers:admin``. A call of pendant's
        methods alone needs nothing more here, so a role with ``frames:commit`` but not
        ``frames:read`` commits as REST's PUT lets it; any other request needs ``frames:read``."""
        if action_type != CALL:
            return {"frames:read"}
        need: set[str] = set()
        for m in struct_from_binary(ua.CallParameters, body.copy()).MethodsToCall or []:
            if m.MethodId not in self.method_names:
                need.add("frames:read" if m.MethodId in READ_METHODS else "controllers:admin")
        return need

    def owners_ok(self, action_type: ua.NodeId, body: Any, caller: Caller) -> bool:
        """Every subscription the request names belongs to a session of the same user."""
        params_type, attr = SUBSCRIPTION_REQUESTS[action_type]
        ids = getattr(struct_from_binary(params_type, body.copy()), attr)
        ids = [getattr(i, "SubscriptionId", i) for i in (ids if isinstance(ids, list) else [ids])]
        if not ids:  # a Publish that acknowledges nothing
            return True
        if self.iserver is None:
            return False
        subs = self.iserver.subscription_service.subscriptions
        sessions = {s.session_id: s for s in self.iserver._external_sessions.values()}
        for sid in ids:
            sub = subs.get(sid)
            if sub is None:
                continue  # asyncua answers BadSubscriptionIdInvalid
            owner = sessions.get(sub.session_id)
            if owner is None or getattr(owner.user, "name", None) != caller.name:
                return False
        return True

    def check_validity(self, user: User | None, action_type: ua.NodeId, body: Any) -> bool:
        if action_type in SESSION_TYPES:
            return True
        if action_type in ADMIN_TYPES:
            return False
        if not self.auth:
            CURRENT.set(NO_AUTH)
            return True
        secret = getattr(user, "secret", None)
        if not secret:
            return False
        caller = self.caller(secret)
        if caller is None or not caller.may(self.needs(action_type, body)):
            return False
        if action_type in SUBSCRIPTION_REQUESTS and not self.owners_ok(action_type, body, caller):
            return False
        CURRENT.set(caller)  # the request that follows runs in this context (the audit's who)
        return True
