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
import logging
from dataclasses import dataclass, field
from pathlib import Path

from asyncua import Server, ua
from sqlalchemy.orm import Session, sessionmaker

from db import crud
from server.opcua import access, commit, space
from server.opcua.state import ControllerState, events_after, latest_event_id, read_cells

log = logging.getLogger("pendant.opcua")
TABLES = {"tool": 16, "base": 32}
FORMATS = ("kuka", "abb", "fanuc", "ur", "json")


@dataclass
class PendantOpcUa:
    """The server, its cells' node handles and the last state read from the database."""

    make_session: sessionmaker[Session]
    endpoint: str = "opc.tcp://127.0.0.1:4840/pendant/"
    poll_s: float = 0.2
    auth: bool = True  # False: the --no-auth demo, everyone an Administrator (as on REST)
    pki_dir: Path | None = None  # the server's certificate and key (made on first start):
    # with it, a Basic256Sha256 SignAndEncrypt endpoint and certificate (X509) logins
    server: Server = field(init=False)
    cells: dict[int, space.CellNodes] = field(default_factory=dict, init=False)
    states: dict[int, ControllerState] = field(default_factory=dict, init=False)
    ns_ids: tuple[int, int, int] = field(default=(0, 0, 0), init=False)
    last_event_id: int = field(default=0, init=False)
    _events: object = field(default=None, init=False)  # the PendantEventType generator
    rules: access.PendantRules = field(init=False)
    _task: asyncio.Task | None = field(default=None, init=False)

    async def start(self) -> None:
        self.server = Server(user_manager=access.PendantUsers(self.make_session, self.auth))
        await self.server.init()
        self.server.set_endpoint(self.endpoint)
        self.rules = access.PendantRules(self.make_session, self.auth)
        policies = [ua.SecurityPolicyType.NoSecurity]
        identities: list[type] = [ua.AnonymousIdentityToken, ua.UserNameIdentityToken]
        if self.pki_dir is not None:
            await self._load_certificate(self.pki_dir)
            policies.append(ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt)
            identities.append(ua.X509IdentityToken)
        self.server.set_security_policy(policies, permission_ruleset=self.rules)
        self.server.set_identity_tokens(identities)
        self.server.set_server_name("pendant")
        await self.server.set_application_uri(space.PENDANT_URI)
        self.ns_ids = await space.load_nodesets(self.server)
        self._events = await space.event_generator(self.server, self.ns_ids[2])
        self.last_event_id = await asyncio.to_thread(latest_event_id, self.make_session)
        await self.sync()
        await self.server.start()
        self._task = asyncio.create_task(self._poll_forever(), name="pendant-opcua-poll")

    async def _load_certificate(self, pki: Path) -> None:
        """The server's application certificate (self-signed, made once, kept in ``pki``)."""
        import socket

        from asyncua.crypto.cert_gen import setup_self_signed_certificate
        from cryptography.x509.oid import ExtendedKeyUsageOID

        pki.mkdir(parents=True, exist_ok=True)
        key, cert = pki / "pendant-server-key.pem", pki / "pendant-server-cert.der"
        await setup_self_signed_certificate(
            key, cert, space.PENDANT_URI, socket.gethostname(),
            [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
            {"organizationName": "pendant", "commonName": "pendant OPC UA"})
        await self.server.load_certificate(str(cert))
        await self.server.load_private_key(str(key))

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

    async def sync(self) -> int:
        """Read every controller from the database and update the address space; returns writes."""
        new = await asyncio.to_thread(read_cells, self.make_session)
        writes = 0
        for cid in set(self.states) - set(new):  # deleted controllers leave the space
            nodes = self.cells.pop(cid)
            await space.remove(nodes.system)
            await space.remove(nodes.pendant)
            self.states.pop(cid)
        for cid, st in new.items():
            if cid not in self.cells:
                self.cells[cid] = await space.add_cell(self.server, self.ns_ids, st)
                await self._add_methods(cid, st.name, self.cells[cid])
            else:
                writes += await space.update_cell(self.cells[cid], self.states[cid], st)
            self.states[cid] = st
        for ev in await asyncio.to_thread(events_after, self.make_session, self.last_event_id):
            await space.raise_event(self._events, ev)
            self.last_event_id = ev.id
        return writes

    async def _add_methods(self, cid: int, name: str, nodes: space.CellNodes) -> None:
        ns = self.ns_ids[2]
        S, I32, D = ua.VariantType.String, ua.VariantType.Int32, ua.VariantType.Double

        def arg(name: str, variant: ua.VariantType, rank: int = -1, doc: str = "") -> ua.Argument:
            a = ua.Argument(Name=name, DataType=ua.NodeId(variant.value), ValueRank=rank,
                            Description=ua.LocalizedText(doc))
            if rank == 1:
                a.ArrayDimensions = [0]
            return a

        def read_frame(_parent: ua.NodeId, table: ua.Variant,
                       number: ua.Variant) -> list[ua.Variant] | ua.StatusCode:
            key = _slot_key(table.Value, number.Value)
            st = self.states[cid].slot(*key) if key else None
            if st is None:
                return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
            return [ua.Variant(st.name, S), ua.Variant(st.kind, S),
                    ua.Variant(list(st.pose), D), ua.Variant(st.version, ua.VariantType.UInt64)]

        async def export_file(_parent: ua.NodeId, fmt: ua.Variant) -> list[ua.Variant] | ua.StatusCode:
            if fmt.Value not in FORMATS:
                return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
            text = await asyncio.to_thread(self._export, cid, fmt.Value)
            return [ua.Variant(text, S)]

        async def commit_frame(_parent: ua.NodeId, table: ua.Variant, number: ua.Variant,
                               frame: ua.Variant, slot_name: ua.Variant,
                               expected: ua.Variant) -> list[ua.Variant] | ua.StatusCode:
            key = _slot_key(table.Value, number.Value)
            caller = access.CURRENT.get()
            if key is None or caller is None:
                return ua.StatusCode(ua.StatusCodes.BadInvalidArgument if key is None
                                     else ua.StatusCodes.BadUserAccessDenied)
            outcome = await asyncio.to_thread(
                commit.commit_frame, self.make_session, cid, *key, frame.Value, slot_name.Value,
                expected.Value, caller.audit_actor())
            if isinstance(outcome, ua.StatusCode):
                return outcome
            await self.sync()  # the client reads its own write at once
            return [ua.Variant(outcome, ua.VariantType.UInt64)]

        methods = (
            ("ReadFrame", read_frame,
             [arg("Table", S, doc="tool or base"), arg("Number", I32, doc="1..16 tools, 1..32 bases")],
             [arg("Name", S), arg("Kind", S), arg("Frame", D, 1, "KUKA X, Y, Z (mm), A, B, C (deg)"),
              arg("Version", ua.VariantType.UInt64)]),
            ("ExportFile", export_file, [arg("Format", S, doc="kuka, abb, fanuc, ur or json")],
             [arg("Text", S)]),
            ("CommitFrame", commit_frame,
             [arg("Table", S, doc="tool or base"), arg("Number", I32, doc="1..16 tools, 1..32 bases"),
              arg("Frame", D, 1, "KUKA X, Y, Z (mm), A, B, C (deg)"),
              arg("Name", S, doc="the slot's name; empty keeps it"),
              arg("ExpectedVersion", ua.VariantType.UInt64,
                  doc="the Version read before; a slot changed since is refused")],
             [arg("NewVersion", ua.VariantType.UInt64)]),
        )
        for method_name, func, inputs, outputs in methods:
            node = await nodes.pendant.add_method(
                ua.NodeId(f"Pendant.{name}.{method_name}", ns), ua.QualifiedName(method_name, ns),
                func, inputs, outputs)
            self.rules.method_names[node.nodeid] = method_name

    def _export(self, cid: int, fmt: str) -> str:
        from server.routers.export import export_text

        with self.make_session() as db:
            crud.get_controller(db, cid)
            return export_text(db, cid, fmt)


def _slot_key(table: object, number: object) -> tuple[str, int] | None:
    """The (table, number) a client asked for, or None where there is no such slot."""
    if table not in TABLES or isinstance(number, bool) or not isinstance(number, int):
        return None
    return (str(table), number) if 1 <= number <= TABLES[str(table)] else None


async def run(make_session: sessionmaker[Session], host: str, port: int, auth: bool = True,
              pki_dir: Path | None = None, parent_pid: int | None = None) -> None:
    """Serve until cancelled (``pendant opcua``), or until ``parent_pid`` (``pendant serve``,
    which started this face) is gone."""
    import os

    face = PendantOpcUa(make_session, f"opc.tcp://{host}:{port}/pendant/", auth=auth,
                        pki_dir=pki_dir)
    await face.start()
    log.warning("pendant OPC UA server at %s", face.endpoint)
    try:
        while parent_pid is None or os.getppid() == parent_pid:
            await asyncio.sleep(1.0)
    finally:
        await face.stop()
