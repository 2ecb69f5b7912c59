"""pendant's OPC UA server: the Robotics address space over the service's database.

``pendant opcua --port 4840`` runs it as a process of its own, ``pendant serve --opcua-port
4840`` beside the REST service. It polls the database (``poll_s``, 0.2 s by default) and
writes what changed into the address space, so a REST change made by any worker on any host
reaches a subscribed client within a poll and a publishing interval. Methods on each
controller's pendant object: ``ReadFrame``, ``ExportFile`` (and the open sessions as a
variable). docs/opcua.md has the tree and an example client session.
"""

from __future__ import annotations

import asyncio
import gc
import logging
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import urlparse

from asyncua import Server, ua
from asyncua.common.utils import ServiceError
from asyncua.crypto import security_policies
from asyncua.server.binary_server_asyncio import BinaryServer, OPCUAProtocol
from asyncua.server.uaprocessor import UaProcessor
from cryptography import x509
from cryptography.hazmat.primitives.serialization import Encoding
from sqlalchemy.orm import Session, sessionmaker

from db import crud
from server.opcua import access, commit, pki, space
from server.opcua.state import CellReader, ControllerState, events_after, latest_event_id
from server.service.export import export_text
from server.service.transaction import retry_reason
from server.settings import LOOPBACK_HOSTS

log = logging.getLogger("pendant.opcua")
TABLES = {"tool": 16, "base": 32}
FORMATS = ("kuka", "abb", "fanuc", "ur", "json")


class CheckedPolicyFactory(security_policies.SecurityPolicyFactory):
    """asyncua's per-channel policy maker, checking the client's certificate first: trusted
    (``pki/trusted``) and valid now, else the channel is refused. On the None policy the
    client's certificate is dropped (nothing proves it is the client's)."""

    def __init__(self, base: security_policies.SecurityPolicyFactory,
                 trust_list: pki.TrustList) -> None:
        super().__init__(base.cls, base.mode, base.certificate, base.private_key,
                         base.permission_ruleset, base.certificate_chain)
        self.trust_list = trust_list

    def create(self, peer_certificate: bytes | None) -> security_policies.SecurityPolicy:
        if self.cls is security_policies.SecurityPolicyNone:
            peer_certificate = None
        else:
            self.trust_list.check(peer_certificate)
        access.CHANNEL.set(access.Channel(self.mode, peer_certificate))
        return super().create(peer_certificate)


async def _same_as_channel(cert: x509.Certificate, app: ua.ApplicationDescription) -> None:
    """CreateSession's client certificate must be the one its signed channel was opened with,
    and its ApplicationUri one the certificate names (OPC 10000-4 §5.6.2). (On a None channel
    the certificate proves nothing and is dropped.)"""
    ch = access.CHANNEL.get()
    if ch is None or ch.peer_certificate is None:
        return
    if cert.public_bytes(Encoding.DER) != ch.peer_certificate:
        raise ServiceError(ua.StatusCodes.BadCertificateInvalid)
    try:
        uris = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value \
            .get_values_for_type(x509.UniformResourceIdentifier)
    except x509.ExtensionNotFound:
        uris = []
    if app.ApplicationUri not in uris:
        raise ServiceError(ua.StatusCodes.BadCertificateUriInvalid)


CREATE = ua.NodeId(ua.ObjectIds.CreateSessionRequest_Encoding_DefaultBinary)
ACTIVATE = ua.NodeId(ua.ObjectIds.ActivateSessionRequest_Encoding_DefaultBinary)


class SessionProcessor(UaProcessor):
    """A request on a channel without a (valid) session gets ``BadSessionIdInvalid``, as OPC
    10000-4 §7.29 has it, so a client makes a new session; a session whose login was revoked
    is closed at its next request and answered the same. asyncua answers
    ``BadUserAccessDenied``: after a restart of the face, node-opcua then resent its
    Publish requests at once, forever (thousands a second)."""

    peer_host: str | None = None  # the client's address (SessionProtocol sets it)

    async def _process_message(self, typeid, requesthdr, seqhdr, body):
        access.PEER.set(self.peer_host)
        if typeid in access.REGISTER_TYPES:  # else anyone's server was listed by FindServers
            raise ServiceError(ua.StatusCodes.BadServiceUnsupported)
        if self.session is None and typeid not in access.SESSIONLESS_TYPES:
            raise ServiceError(ua.StatusCodes.BadSessionIdInvalid)
        if typeid == ACTIVATE and self.session is None:
            return await self._activate_moved_session(typeid, requesthdr, seqhdr, body)
        rules = self._connection.security_policy.permissions
        if self.session is not None and typeid not in access.SESSION_TYPES and \
                isinstance(rules, access.PendantRules) and rules.revoked(self.session.user):
            # the login's token or user was revoked (or expired): the session ends, its
            # subscriptions with it (refusing each request made node-opcua resend at once)
            await self.session.close_session(True)
            self.session = None
            raise ServiceError(ua.StatusCodes.BadSessionIdInvalid)
        if typeid == ACTIVATE:
            access.ACTIVATING.set(self.session)  # not counted among its user's other sessions
        if typeid == CREATE and self.session is not None and not self.session.is_activated():
            # the channel's one session is replaced: asyncua kept the old one for ever (it
            # times out only once activated), so one channel could register sessions unbounded
            await self.session.close_session(True)
        done = await super()._process_message(typeid, requesthdr, seqhdr, body)
        if typeid == CREATE and self.session is not None:  # the client certificate it is bound to
            self.session.pendant_peer = self._connection.security_policy.peer_certificate
        return done

    async def _activate_moved_session(self, typeid, requesthdr, seqhdr, body):
        """A session moves to a new channel (a reconnect, OPC 10000-4 §5.6.3) only on a signed
        channel of the client certificate it was made with, and a failed activation leaves the
        channel without it (asyncua kept it there: the client went on as the session's user)."""
        peer = self._connection.security_policy.peer_certificate
        session = self.iserver.lookup_external_session(requesthdr.AuthenticationToken)
        if session is None or peer is None or getattr(session, "pendant_peer", None) != peer:
            raise ServiceError(ua.StatusCodes.BadSessionIdInvalid)
        access.ACTIVATING.set(session)
        try:
            return await super()._process_message(typeid, requesthdr, seqhdr, body)
        except BaseException:
            self.session = None
            if self._session_watchdog_task is not None:  # asyncua's, for the session it took
                self._session_watchdog_task.cancel()
            raise


PENDING_PER_HOST = 20  # connections of one host without an activated session


def _host(peer: object) -> str | None:
    return peer[0] if isinstance(peer, tuple) and peer else None


class SessionProtocol(OPCUAProtocol):
    """A connection; at most :data:`PENDING_PER_HOST` of one host without an activated session
    (asyncua's one cap is 1000 connections in all: one host's idle sockets, no certificate
    needed, refused everyone else's for the 30 s asyncua gives a connection to log in)."""

    def connection_made(self, transport) -> None:
        host = _host(transport.get_extra_info("peername"))
        pending = [c for c in self.clients if _host(c.peer_name) == host and not (
            c.processor is not None and c.processor.session is not None
            and c.processor.session.is_activated())]
        if len(pending) >= PENDING_PER_HOST:
            log.warning("OPC UA: refused a connection from %s: %d not logged in yet", host,
                        len(pending))
            transport.close()
            return
        super().connection_made(transport)
        if self.processor is not None:
            self.processor.__class__ = SessionProcessor
            self.processor.peer_host = host


class PendantBinaryServer(BinaryServer):
    def _make_protocol(self) -> OPCUAProtocol:
        return SessionProtocol(iserver=self.iserver, policies=self._policies, clients=self.clients,
                               closing_tasks=self.closing_tasks, limits=self.limits)


class PendantServer(Server):
    """asyncua's Server with the trust list on every channel and endpoints as a plant needs
    them: a None endpoint offers Anonymous only; a password is always encrypted with the
    session's server nonce (the token policy names the endpoint's security policy)."""

    trust_list: pki.TrustList

    async def start(self) -> None:
        """asyncua's ``Server.start`` with :class:`PendantBinaryServer`."""
        await self._setup_server_nodes()
        await self.iserver.start()
        try:
            host, port = self._get_bind_socket_info()
            self.bserver = PendantBinaryServer(self.iserver, host, port, self.limits)
            self.bserver.set_policies(self._policies)
            await self.bserver.start()
        except Exception:
            await self.iserver.stop()
            raise

    async def _setup_server_nodes(self) -> None:
        await super()._setup_server_nodes()
        self._policies = [CheckedPolicyFactory(p, self.trust_list) for p in self._policies]
        for edp in self.iserver.endpoints:
            if edp.SecurityMode == ua.MessageSecurityMode.None_:
                edp.UserIdentityTokens = [t for t in edp.UserIdentityTokens
                                          if t.TokenType == ua.UserTokenType.Anonymous]
            for t in edp.UserIdentityTokens:
                if t.TokenType == ua.UserTokenType.UserName:
                    t.SecurityPolicyUri = edp.SecurityPolicyUri


@dataclass
class PendantOpcUa:
    """The server, its cells' node handles and the last state read from the database."""

    make_session: sessionmaker[Session]
    endpoint: str = "opc.tcp://127.0.0.1:4840/pendant/"
    poll_s: float = 0.2
    auth: bool = True  # False: the --no-auth demo, everyone an Administrator (as on REST)
    pki_dir: Path | None = None  # the server's certificate and key, the trust list (server.opcua.pki)
    none_endpoint: bool = False  # also a SecurityPolicy None endpoint (Anonymous only)
    server: Server = field(init=False)
    cells: dict[int, space.CellNodes] = field(default_factory=dict, init=False)
    states: dict[int, ControllerState] = field(default_factory=dict, init=False)
    ns_ids: tuple[int, int, int] = field(default=(0, 0, 0), init=False)
    last_event_id: int = field(default=0, init=False)
    _events: object = field(default=None, init=False)  # the PendantEventType generator
    _templates: dict = field(default_factory=dict, init=False)  # space.CellTemplate by shape
    _reader: CellReader = field(default_factory=CellReader, init=False)
    rules: access.PendantRules = field(init=False)
    _task: asyncio.Task | None = field(default=None, init=False)

    async def start(self) -> None:
        host = urlparse(self.endpoint).hostname or ""
        if not self.auth and host not in LOOPBACK_HOSTS:
            raise ValueError(f"host: no-auth serves loopback only (127.0.0.1, localhost, ::1), "
                             f"not {host}")
        if self.pki_dir is None:
            raise ValueError("pki_dir: the SignAndEncrypt endpoint needs the server's PKI folder")
        self.server = PendantServer(user_manager=access.PendantUsers(self.make_session, self.auth))
        await self.server.init()
        self.server.set_endpoint(self.endpoint)
        self.rules = access.PendantRules(self.make_session, self.auth, iserver=self.server.iserver)
        access.install_login_checks(self.server.iserver)
        access.unguessable_subscription_ids(self.server.iserver.subscription_service)
        access.bounded_monitored_items(self.server.iserver.subscription_service)
        access.unguessable_session_tokens(self.server.iserver)
        access.republish_with_status(self.server.iserver.subscription_service)
        cert, key = await pki.server_certificate(self.pki_dir, space.PENDANT_URI)
        await self.server.load_certificate(str(cert))
        await self.server.load_private_key(str(key))
        self.server.trust_list = pki.TrustList(self.pki_dir)
        self.server.set_certificate_validator(_same_as_channel)
        policies = [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]
        if self.none_endpoint:
            policies.append(ua.SecurityPolicyType.NoSecurity)
        # Anonymous: only the --no-auth demo (everyone an Administrator); else no login
        identities: list[type] = [ua.UserNameIdentityToken, ua.X509IdentityToken]
        if not self.auth:
            identities.append(ua.AnonymousIdentityToken)
        self.server.set_security_policy(policies, permission_ruleset=self.rules)
        self.server.set_identity_tokens(identities)
        self.server.set_server_name("pendant")
        await self.server.set_application_uri(space.PENDANT_URI)
        self.ns_ids = await space.load_nodesets(self.server)
        gc.freeze()  # the nodesets' nodes live as long as the face (see sync)
        self._events = await space.event_generator(self.server, self.ns_ids[2])
        self.last_event_id = await asyncio.to_thread(latest_event_id, self.make_session)
        await self.sync()
        await self.server.start()
        self._task = asyncio.create_task(self._poll_forever(), name="pendant-opcua-poll")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
        await self.server.stop()

    async def _poll_forever(self) -> None:
        while True:
            await asyncio.sleep(self.poll_s)
            try:
                await self.sync()
            except Exception:  # a DB hiccup must not end the face; say it and poll again
                log.exception("OPC UA poll of the database failed")

    async def end_revoked_sessions(self) -> int:
        """Close every session whose login was revoked or expired (its subscriptions with it:
        no more data goes out); returns how many. Run before each poll's writes."""
        sessions = [s for s in list(self.server.iserver._external_sessions.values())
                    if getattr(s.user, "secret", None)]
        if not sessions or not self.auth:
            return 0
        gone = await asyncio.to_thread(
            lambda: {s.user.secret for s in sessions if self.rules.caller(s.user.secret, fresh=True) is None})
        ended = 0
        for s in sessions:
            if s.user.secret in gone:
                log.warning("OPC UA: the login of %s was revoked or expired: session ended",
                            s.user.name)
                await s.close_session(True)  # and asyncua forgets it
                ended += 1
        return ended

    async def sync(self) -> int:
        """Read every controller from the database and update the address space; returns writes."""
        await self.end_revoked_sessions()
        new = await asyncio.to_thread(self._reader.read, self.make_session)
        writes = 0
        gone = {cid for cid in self.states
                if cid not in new or new[cid].node_key != self.states[cid].node_key}
        for cid in gone:  # deleted controllers leave the space (an id made again: a new one)
            nodes = self.cells.pop(cid)
            for method_id in [m for m in self.rules.method_names
                              if str(m.Identifier).startswith(f"{nodes.pendant.nodeid.Identifier}.")]:
                del self.rules.method_names[method_id]
            space.remove_ids(self.server, nodes.system.nodeid)
            space.remove_ids(self.server, nodes.pendant.nodeid)
            self.states.pop(cid)
        for cid, st in new.items():
            if cid not in self.cells:
                self.cells[cid] = await space.add_cell(self.server, self.ns_ids, st,
                                                       self._templates, METHODS)
                self._link_methods(cid, self.cells[cid])
                # a cell is ~20 000 long-lived objects: out of the cyclic GC's reach, else its
                # full collections (every few cells, ever longer) block the loop for seconds
                gc.freeze()
                await asyncio.sleep(0)  # clients are served between two new cells
            elif st is not self.states[cid]:  # the same object: nothing changed
                writes += await space.update_cell(self.cells[cid], self.states[cid], st)
            self.states[cid] = st
        for ev in await asyncio.to_thread(events_after, self.make_session, self.last_event_id):
            await space.raise_event(self._events, ev)
            self.last_event_id = ev.id
        return writes

    def _link_methods(self, cid: int, nodes: space.CellNodes) -> None:
        """The callbacks of the cell's method nodes (:data:`METHODS`), each checking its
        caller's permission and its arguments (:func:`_method`)."""
        S, D = ua.VariantType.String, ua.VariantType.Double

        async def read_frame(table: str, number: int) -> list[ua.Variant] | ua.StatusCode:
            key = _slot_key(table, number)
            st = self.states[cid].slot(*key) if key else None
            if st is None:
                return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
            return [ua.Variant(st.name, S), ua.Variant(st.kind, S),
                    ua.Variant(list(st.pose), D), ua.Variant(st.version, ua.VariantType.UInt64)]

        async def export_file(fmt: str) -> list[ua.Variant] | ua.StatusCode:
            if fmt not in FORMATS:
                return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
            try:
                text = await asyncio.to_thread(self._export, cid, fmt)
            except Exception as err:  # the database cannot answer now: REST's 503
                why = retry_reason(err)
                log.warning("opcua: ExportFile %s: %s", fmt, why)
                return ua.StatusCode(ua.StatusCodes.BadResourceUnavailable)
            return [ua.Variant(text, S)]

        async def commit_frame(table: str, number: int, frame: list[float], slot_name: str,
                               expected: int) -> list[ua.Variant] | ua.StatusCode:
            key = _slot_key(table, number)
            if key is None:
                return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
            caller = access.CURRENT.get()
            assert caller is not None  # checked by _method
            outcome = await asyncio.to_thread(
                commit.commit_frame, self.make_session, cid, *key, frame, slot_name,
                expected, caller.audit_actor(access.PEER.get()))
            if isinstance(outcome, ua.StatusCode):
                return outcome
            try:
                await self.sync()  # the client reads its own write at once
            except Exception:  # committed: the answer is its version whatever the read did
                log.exception("OPC UA read after a committed CommitFrame failed")
            return [ua.Variant(outcome, ua.VariantType.UInt64)]

        funcs = {"ReadFrame": read_frame, "ExportFile": export_file, "CommitFrame": commit_frame}
        for method_name, inputs, _outputs in METHODS:
            node = self.server.get_node(ua.NodeId(f"{nodes.pendant.nodeid.Identifier}.{method_name}",
                                                  self.ns_ids[2]))
            self.server.link_method(node, _method(method_name, funcs[method_name], inputs))
            self.rules.method_names[node.nodeid] = method_name

    def _export(self, cid: int, fmt: str) -> str:
        with self.make_session() as db:
            crud.get_controller(db, cid)
            return export_text(db, cid, fmt)


def _arg(name: str, variant: ua.VariantType, rank: int = -1, doc: str = "") -> ua.Argument:
    a = ua.Argument(Name=name, DataType=ua.NodeId(variant.value), ValueRank=rank,
                    Description=ua.LocalizedText(doc))
    if rank == 1:
        a.ArrayDimensions = [0]
    return a


_S, _I32, _D, _U64 = (ua.VariantType.String, ua.VariantType.Int32, ua.VariantType.Double,
                      ua.VariantType.UInt64)
METHODS: tuple[tuple[str, list[ua.Argument], list[ua.Argument]], ...] = (
    # each controller's pendant object's methods: name, input and output arguments
    ("ReadFrame",
     [_arg("Table", _S, doc="tool or base"), _arg("Number", _I32, doc="1..16 tools, 1..32 bases")],
     [_arg("Name", _S), _arg("Kind", _S), _arg("Frame", _D, 1, "KUKA X, Y, Z (mm), A, B, C (deg)"),
      _arg("Version", _U64)]),
    ("ExportFile", [_arg("Format", _S, doc="kuka, abb, fanuc, ur or json")], [_arg("Text", _S)]),
    ("CommitFrame",
     [_arg("Table", _S, doc="tool or base"), _arg("Number", _I32, doc="1..16 tools, 1..32 bases"),
      _arg("Frame", _D, 1, "KUKA X, Y, Z (mm), A, B, C (deg)"),
      _arg("Name", _S, doc="the slot's name; empty keeps it"),
      _arg("ExpectedVersion", _U64, doc="the Version read before; a slot changed since is refused")],
     [_arg("NewVersion", _U64)]),
)


INTEGERS = {ua.VariantType.SByte, ua.VariantType.Byte, ua.VariantType.Int16,
            ua.VariantType.UInt16, ua.VariantType.Int32, ua.VariantType.UInt32,
            ua.VariantType.Int64, ua.VariantType.UInt64}


def _accepts(decl: ua.Argument, v: object) -> bool:
    """Whether the Variant ``v`` fits the declared argument: its type (any integer type for an
    integer argument, in range for an unsigned one) and scalar or one-dimensional array."""
    if not isinstance(v, ua.Variant) or v.is_array != (decl.ValueRank == 1):
        return False
    want = ua.VariantType(decl.DataType.Identifier)
    if want == v.VariantType:
        return True
    if want in INTEGERS and v.VariantType in INTEGERS:
        values = v.Value if v.is_array else [v.Value]
        lo, hi = (0, 2 ** 64 - 1) if want == ua.VariantType.UInt64 else (-2 ** 31, 2 ** 31 - 1)
        return all(lo <= x <= hi for x in values)
    return False


def _method(name: str, func, inputs: list[ua.Argument]):
    """asyncua's method callback around ``func(*values)``: first the caller's permission for
    this call (:func:`access.method_permission`, one table with REST), then the arguments'
    count and types (OPC 10000-4 §5.11.2: BadArgumentsMissing, BadTooManyArguments,
    BadTypeMismatch with the offending argument's result). A refusal fails this call only."""
    async def call(_parent: ua.NodeId, *args: ua.Variant) -> ua.CallMethodResult | list | ua.StatusCode:
        caller = access.CURRENT.get()
        fmt = args[0].Value if name == "ExportFile" and args else None
        if caller is None or not caller.may(access.method_permission(name, fmt)):
            return ua.StatusCode(ua.StatusCodes.BadUserAccessDenied)
        if len(args) < len(inputs):
            return ua.StatusCode(ua.StatusCodes.BadArgumentsMissing)
        if len(args) > len(inputs):
            return ua.StatusCode(ua.StatusCodes.BadTooManyArguments)
        fits = [_accepts(d, v) for d, v in zip(inputs, args)]
        if not all(fits):
            return ua.CallMethodResult(
                StatusCode=ua.StatusCode(ua.StatusCodes.BadInvalidArgument),
                InputArgumentResults=[ua.StatusCode() if ok else
                                      ua.StatusCode(ua.StatusCodes.BadTypeMismatch)
                                      for ok in fits])
        return await func(*[v.Value for v in args])
    return call


def _slot_key(table: object, number: object) -> tuple[str, int] | None:
    """The (table, number) a client asked for, or None where there is no such slot."""
    if table not in TABLES or isinstance(number, bool) or not isinstance(number, int):
        return None
    return (str(table), number) if 1 <= number <= TABLES[str(table)] else None


async def run(make_session: sessionmaker[Session], host: str, port: int, auth: bool = True,
              pki_dir: Path | None = None, parent_pid: int | None = None,
              none_endpoint: bool = False) -> None:
    """Serve until cancelled (``pendant opcua``), or until ``parent_pid`` (``pendant serve``,
    which started this face) is gone."""
    import os

    face = PendantOpcUa(make_session, f"opc.tcp://{host}:{port}/pendant/", auth=auth,
                        pki_dir=pki_dir, none_endpoint=none_endpoint)
    await face.start()
    log.warning("pendant OPC UA server ready at %s (%s; PKI %s)", face.endpoint,
                "Basic256Sha256 SignAndEncrypt" + (" and None (Anonymous only)"
                                                   if none_endpoint else ""), pki_dir)
    try:
        while parent_pid is None or os.getppid() == parent_pid:
            await asyncio.sleep(1.0)
    finally:
        await face.stop()
