"""The MES face: an OPC UA client (asyncua) on loopback against pendant's OPC UA server.

MES browses MotionDeviceSystem → MotionDevices → Axes, reads a tool frame, exports a file
and watches a REST change arrive through a subscription. The server runs in a thread of its
own with its own event loop, on the same SQLite file as the REST app.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import time
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from api_helpers import ADMIN_TOKEN, C, edit_slot, make_client, ok
from asyncua import Client, Node, ua
from browser_helpers import free_port
from opcua_helpers import client_certificate, namespaces, secure_client, start_face
from scipy.spatial.transform import Rotation

from server.opcua.pki import default_pki_dir
from server.opcua.space import PENDANT_URI
from server.service import transaction

MANDATORY = ua.NodeId(ua.ObjectIds.ModellingRule_Mandatory)


class LogRecords(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@pytest.fixture(scope="module")
def face(fresh_db, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:  # noqa: ANN001
    """The REST app (TestClient) and the OPC UA server on one SQLite file."""
    db_url = fresh_db("opcua")
    logs = LogRecords()
    logging.getLogger("asyncua").addHandler(logs)
    with make_client(db_url) as rest:
        running = start_face(rest.app.state.sessionmaker, tmp_path_factory.mktemp("face"))
        yield {"rest": rest, "server": running.server, "logs": logs, "db_url": db_url,
               "face": running, "cert": running.client}
        running.stop()
    logging.getLogger("asyncua").removeHandler(logs)


def on_client(face: dict, body, user: str | None = "admin",
              password: str | None = ADMIN_TOKEN) -> object:
    """Run ``body(client, ns)`` with an asyncua Client on the encrypted endpoint, logged in as
    ``user`` (the first Administrator by default; None: anonymous); ns = {di, rob, pendant}."""
    async def run() -> object:
        client = await secure_client(face["server"].endpoint, face["cert"], user, password)
        async with client:
            return await body(client, await namespaces(client))
    return asyncio.run(run())


def poll(face: dict, body, settled: Callable[[object], bool],
         timeout_s: float = 15.0) -> object:
    """``on_client(face, body)`` every 0.1 s until ``settled(outcome)`` or ``timeout_s`` ran out:
    the server takes a REST change from the database at its next poll (every 0.1 s here, later
    on a loaded machine). The outcome is what ``body`` returned, or the UaStatusCodeError it
    raised; the last one is returned, for the caller to assert on."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            outcome = on_client(face, body)
        except ua.UaStatusCodeError as err:
            outcome = err
        if settled(outcome) or time.monotonic() > deadline:
            return outcome
        time.sleep(0.1)


async def cell(client: Client, ns: dict, name: str = "cell-1") -> Node:
    return await client.nodes.objects.get_child([f"{ns['di']}:DeviceSet", f"{ns['pendant']}:{name}"])


async def pendant(client: Client, ns: dict, name: str = "cell-1") -> Node:
    return await client.nodes.objects.get_child([f"{ns['pendant']}:Pendant", f"{ns['pendant']}:{name}"])


def test_the_nodesets_load_without_errors(face: dict) -> None:
    errors = [r.getMessage() for r in face["logs"].records if r.levelno >= logging.ERROR]
    assert errors == []


def test_mes_browses_motion_devices_to_axes_and_reads_the_joints(face: dict) -> None:
    joints = ok(face["rest"].get(f"{C}/robot"))["joints_deg"]

    async def body(client: Client, ns: dict) -> tuple[list[str], list[float]]:
        devices = await (await cell(client, ns)).get_child([f"{ns['rob']}:MotionDevices"])
        (arm,) = await devices.get_children()
        axes = await (await arm.get_child([f"{ns['rob']}:Axes"])).get_children()
        names = [(await a.read_browse_name()).Name for a in axes]
        values = [await (await a.get_child([f"{ns['di']}:ParameterSet",
                                            f"{ns['rob']}:ActualPosition"])).read_value()
                  for a in axes]
        return [(await arm.read_browse_name()).Name] + names, values

    names, values = on_client(face, body)
    assert names == ["KUKA KR 6 R900 sixx", "A1", "A2", "A3", "A4", "A5", "A6"]
    assert values == pytest.approx(joints, abs=1e-12)


def test_a_tool_frame_reads_as_rest_has_it_and_rotates_the_same(face: dict) -> None:
    pose = {"x": 12.5, "y": -3.0, "z": 180.0, "a": 30.0, "b": -20.0, "c": 10.0}
    edited = edit_slot(face["rest"], f"{C}/tools/2", {"name": "torch", "pose": pose})
    ok(edited)
    version = int(edited.headers["ETag"].strip('W/"'))

    async def body(client: Client, ns: dict) -> tuple:
        obj = await pendant(client, ns)
        out = await obj.call_method(f"{ns['pendant']}:ReadFrame", "tool", 2)
        frame = await obj.get_child([f"{ns['pendant']}:Tools", f"{ns['pendant']}:Tool2",
                                     f"{ns['pendant']}:Frame"])
        return out, await frame.read_value()

    (name, kind, xyzabc, seen_version), frame = poll(  # the server's state has the edit
        face, body, lambda out: not isinstance(out, Exception) and out[0][3] == version)
    assert seen_version == version
    assert (name, kind) == ("torch", "tool")
    assert xyzabc == pytest.approx([12.5, -3.0, 180.0, 30.0, -20.0, 10.0])
    o = frame.Orientation  # OPC UA: A about X, B about Y, C about Z, intrinsic z-y'-x''
    R_opc = Rotation.from_euler("ZYX", [o.C, o.B, o.A], degrees=True).as_matrix()
    R_kuka = Rotation.from_euler("ZYX", [30.0, -20.0, 10.0], degrees=True).as_matrix()
    assert np.abs(R_opc - R_kuka).max() < 1e-12
    p = frame.CartesianCoordinates
    assert (p.X, p.Y, p.Z) == (12.5, -3.0, 180.0)


def test_a_rest_change_reaches_a_subscribed_client_within_a_second(face: dict) -> None:
    class Inbox:
        def __init__(self) -> None:
            self.seen: list[tuple[float, object]] = []

        def datachange_notification(self, node, val, data) -> None:
            self.seen.append((time.monotonic(), val))

    async def body(client: Client, ns: dict) -> float:
        name = await (await pendant(client, ns)).get_child(
            [f"{ns['pendant']}:Tools", f"{ns['pendant']}:Tool3", f"{ns['pendant']}:Name"])
        inbox = Inbox()
        sub = await client.create_subscription(50, inbox)
        await sub.subscribe_data_change(name)
        deadline = time.monotonic() + 10.0
        while not inbox.seen:  # the initial value arrives first
            assert time.monotonic() < deadline, "no initial value of the subscribed name"
            await asyncio.sleep(0.02)
        sent = time.monotonic()
        await asyncio.to_thread(edit_slot, face["rest"], f"{C}/tools/3", {"name": "spindle"})
        while time.monotonic() - sent < 3.0:
            arrived = [t for t, v in inbox.seen if v == "spindle"]
            if arrived:
                return arrived[0] - sent
            await asyncio.sleep(0.02)
        return float("inf")

    assert on_client(face, body) < 1.0


def test_a_jog_moves_the_axis_actual_position(face: dict) -> None:
    before = ok(face["rest"].get(f"{C}/robot"))["joints_deg"][0]
    ok(face["rest"].post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A1", "increment": 2.5}))

    async def body(client: Client, ns: dict) -> float:
        devices = await (await cell(client, ns)).get_child([f"{ns['rob']}:MotionDevices"])
        (arm,) = await devices.get_children()
        a1 = await arm.get_child([f"{ns['rob']}:Axes", f"{ns['rob']}:A1",
                                  f"{ns['di']}:ParameterSet", f"{ns['rob']}:ActualPosition"])
        return await a1.read_value()

    assert poll(face, body, lambda a1: a1 != before) == pytest.approx(before + 2.5)


def test_export_file_is_the_rest_export(face: dict) -> None:
    rest_text = face["rest"].get(f"{C}/export", params={"format": "abb"}).text

    async def body(client: Client, ns: dict) -> str:
        return await (await pendant(client, ns)).call_method(f"{ns['pendant']}:ExportFile", "abb")

    assert on_client(face, body) == rest_text


def test_a_slot_outside_the_table_is_a_bad_argument(face: dict) -> None:
    async def body(client: Client, ns: dict) -> None:
        await (await pendant(client, ns)).call_method(f"{ns['pendant']}:ReadFrame", "tool", 17)

    with pytest.raises(ua.UaStatusCodeError) as err:
        on_client(face, body)
    assert err.value.code == ua.StatusCodes.BadInvalidArgument


def test_a_controller_made_over_rest_appears_and_leaves_when_deleted(face: dict) -> None:
    made = ok(face["rest"].post("/controllers", json={"name": "cell-7",
                                                      "robot": "abb_irb120"}))

    async def axes(client: Client, ns: dict) -> list[list[str]]:
        """The axes of each arm of cell-7."""
        devices = await (await cell(client, ns, "cell-7")).get_child([f"{ns['rob']}:MotionDevices"])
        return [[(await a.read_browse_name()).Name
                 for a in await (await arm.get_child([f"{ns['rob']}:Axes"])).get_children()]
                for arm in await devices.get_children()]

    one_arm = [[f"A{i}" for i in range(1, 7)]]
    assert poll(face, axes, lambda got: got == one_arm) == one_arm
    assert face["rest"].delete(f"/controllers/{made['id']}").status_code == 204
    gone = poll(face, axes, lambda got: isinstance(got, ua.UaStatusCodeError))
    assert isinstance(gone, ua.UaStatusCodeError), gone


async def mandatory_children(client: Client, type_node: Node) -> set[str]:
    """Browse names of the type's (and its supertypes') Mandatory instance declarations."""
    names: set[str] = set()
    node: Node | None = type_node
    while node is not None:
        for child in await node.get_children(refs=ua.ObjectIds.HierarchicalReferences):
            rules = await child.get_referenced_nodes(ua.ObjectIds.HasModellingRule)
            if any(r.nodeid == MANDATORY for r in rules):
                names.add((await child.read_browse_name()).to_string())
        supers = await node.get_referenced_nodes(ua.ObjectIds.HasSubtype, ua.BrowseDirection.Inverse)
        node = supers[0] if supers else None
    return names


async def missing_mandatory(client: Client, node: Node, path: str,
                            checked: list[str]) -> list[str]:
    """Every mandatory child of every instance below ``node`` that is not there; ``checked``
    collects each mandatory child that was looked for."""
    missing: list[str] = []
    children = await node.get_children(refs=ua.ObjectIds.HierarchicalReferences)
    have = {(await c.read_browse_name()).to_string() for c in children}
    type_id = await node.read_type_definition()
    if type_id is not None:
        for name in await mandatory_children(client, client.get_node(type_id)):
            checked.append(f"{path}/{name.split(':', 1)[-1]}")
            if name not in have:
                missing.append(f"{path}/{name}")
    for c in children:
        if await c.read_node_class() in (ua.NodeClass.Object, ua.NodeClass.Variable):
            missing += await missing_mandatory(
                client, c, f"{path}/{(await c.read_browse_name()).Name}", checked)
    return missing


def test_instances_have_every_mandatory_child_of_their_types(face: dict) -> None:
    checked: list[str] = []

    async def body(client: Client, ns: dict) -> list[str]:
        system = await cell(client, ns)
        frame = await (await pendant(client, ns)).get_child(
            [f"{ns['pendant']}:Tools", f"{ns['pendant']}:Tool1", f"{ns['pendant']}:Frame"])
        return (await missing_mandatory(client, system, "cell-1", checked)
                + await missing_mandatory(client, frame, "Tool1/Frame", checked))

    assert on_client(face, body) == []
    for expected in ("cell-1/MotionDevices", "cell-1/MotionDevices/KUKA KR 6 R900 sixx/Axes",
                     "Axes/A1/MotionProfile", "cell-1/Controllers/cell-1/CurrentUser",
                     "Tool1/Frame/CartesianCoordinates", "Tool1/Frame/Orientation/C"):
        assert expected in " ".join(checked), expected


def test_serve_with_an_opcua_port_starts_the_face_beside_the_rest_service(tmp_path) -> None:
    """``pendant serve --opcua-port --opcua-pki DIR``: both faces as processes on one SQLite
    file, the OPC UA face with the PKI folder it was given (one per instance on a host)."""
    import subprocess
    import sys

    import httpx

    from server.cli.main import main

    rest_port, ua_port = free_port(), free_port()
    db_url = f"sqlite:///{tmp_path / 'pendant.db'}"
    env = {**os.environ, "PENDANT_ADMIN_TOKEN": ADMIN_TOKEN}
    mes = client_certificate(tmp_path / "mes")
    own_pki = tmp_path / "cell-7-pki"
    assert main(["opcua", "trust", mes.cert, "--pki", str(own_pki)]) == 0
    assert default_pki_dir(db_url) == tmp_path / "pendant.db-opcua-pki"  # when none is given
    log = tmp_path / "serve.log"
    proc = subprocess.Popen([sys.executable, "-m", "server.cli", "serve", "--port", str(rest_port),
                             "--opcua-port", str(ua_port), "--opcua-pki", str(own_pki),
                             "--db", db_url, "--job-workers", "0"],
                            stdout=subprocess.DEVNULL, stderr=log.open("w"), env=env)

    async def a1() -> float:
        deadline = time.monotonic() + 120
        while True:
            try:
                client = await secure_client(f"opc.tcp://127.0.0.1:{ua_port}/pendant/", mes,
                                             "admin", ADMIN_TOKEN, timeout=5)
                async with client:
                    ns = await namespaces(client)
                    devices = await (await cell(client, ns)).get_child([f"{ns['rob']}:MotionDevices"])
                    (arm,) = await devices.get_children()
                    node = await arm.get_child([f"{ns['rob']}:Axes", f"{ns['rob']}:A2",
                                                f"{ns['di']}:ParameterSet",
                                                f"{ns['rob']}:ActualPosition"])
                    return await node.read_value()
            except (TimeoutError, OSError, ua.UaError):
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.5)

    try:
        value = asyncio.run(a1())
        joints = httpx.get(f"http://127.0.0.1:{rest_port}/controllers/1/robot",
                           headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}).json()["joints_deg"]
        assert value == pytest.approx(joints[1])
        assert f"pendant OPC UA server ready at opc.tcp://127.0.0.1:{ua_port}/pendant/" in \
            log.read_text()  # the OPC UA port opens after REST's: the log says when
        assert oct(own_pki.stat().st_mode & 0o777) == "0o700"
        assert not default_pki_dir(db_url).exists()
    finally:
        proc.terminate()
        proc.wait(timeout=20)


def test_a_frame_committed_over_rest_arrives_as_an_opcua_event(face: dict) -> None:
    class Inbox:
        def __init__(self) -> None:
            self.events: list[tuple[float, object]] = []

        def event_notification(self, event) -> None:
            self.events.append((time.monotonic(), event))

    async def body(client: Client, ns: dict) -> tuple[float, object]:
        inbox = Inbox()
        sub = await client.create_subscription(50, inbox)
        etype = await client.nodes.base_event_type.get_child([f"{ns['pendant']}:PendantEventType"])
        await sub.subscribe_events(client.nodes.server, etype)  # live once it answers
        sent = time.monotonic()
        await asyncio.to_thread(edit_slot, face["rest"], f"{C}/bases/4", {"name": "fixture"})
        while time.monotonic() - sent < 3.0:
            if inbox.events:
                t, ev = inbox.events[0]
                return t - sent, ev
            await asyncio.sleep(0.02)
        return float("inf"), None

    delay, ev = on_client(face, body)
    assert delay < 1.0
    assert (ev.Kind, ev.Controller) == ("frame-committed", "cell-1")
    payload = json.loads(ev.Payload)
    assert (payload["table"], payload["number"], payload["name"]) == ("base", 4, "fixture")


def user_with_role(face: dict, name: str, role: str) -> str:
    """A user of ``role`` made over REST by the Administrator; returns its token."""
    ok(face["rest"].post("/users", json={"name": name, "role": role}))
    return ok(face["rest"].post(f"/users/{name}/tokens", json={}))["token"]


async def commit(client: Client, ns: dict, number: int, frame: list[float], name: str,
                 version: int) -> int:
    return await (await pendant(client, ns)).call_method(
        f"{ns['pendant']}:CommitFrame", "tool", number, frame, name,
        ua.Variant(version, ua.VariantType.UInt64))


def test_an_anonymous_session_is_refused(face: dict) -> None:
    """As REST answers 401 without a credential: no session without a login."""
    async def body(client: Client, ns: dict) -> object:
        return await (await cell(client, ns)).read_browse_name()

    with pytest.raises(ua.UaStatusCodeError) as err:
        on_client(face, body, user=None)
    assert err.value.code == ua.StatusCodes.BadIdentityTokenRejected


def test_a_wrong_password_is_refused_at_login(face: dict) -> None:
    async def body(client: Client, ns: dict) -> None:
        return None

    with pytest.raises(ua.UaStatusCodeError) as err:
        on_client(face, body, user="admin", password="pdt_not-a-token")
    assert err.value.code in (ua.StatusCodes.BadUserAccessDenied, ua.StatusCodes.BadIdentityTokenRejected,
                              ua.StatusCodes.BadIdentityTokenInvalid)


def test_an_expert_commits_a_frame_rest_sees_it_and_the_audit_names_the_user(face: dict) -> None:
    token = user_with_role(face, "erik", "Expert")
    version = int(face["rest"].get(f"{C}/tools/7").headers["ETag"].strip('W/"'))

    async def body(client: Client, ns: dict) -> int:
        return await commit(client, ns, 7, [10.0, -20.0, 150.0, 90.0, 0.0, 180.0], "drill",
                            version)

    new_version = on_client(face, body, user="erik", password=token)

    async def level(client: Client, ns: dict) -> str:
        ctrl = await (await cell(client, ns)).get_child(
            [f"{ns['rob']}:Controllers", f"{ns['rob']}:cell-1", f"{ns['rob']}:CurrentUser",
             f"{ns['rob']}:Level"])
        return await ctrl.read_value()

    assert on_client(face, level) == "Expert"  # Robotics CurrentUser: the last writer's role
    slot = ok(face["rest"].get(f"{C}/tools/7"))
    assert slot["name"] == "drill"
    assert [slot["pose"][k] for k in "xyzabc"] == pytest.approx([10, -20, 150, 90, 0, 180])
    assert new_version == version + 1
    (rec,) = [r for r in ok(face["rest"].get("/audit", params={"user": "erik"}))
              if r.get("number") == 7]
    assert (rec["source"], rec["role"]) == ("opcua", "Expert")


def test_an_operators_commit_is_user_access_denied_and_changes_nothing(face: dict) -> None:
    token = user_with_role(face, "otto", "Operator")
    before = ok(face["rest"].get(f"{C}/tools/8"))

    async def body(client: Client, ns: dict) -> int:
        return await commit(client, ns, 8, [1.0, 2.0, 3.0, 0.0, 0.0, 0.0], "nope", 1)

    with pytest.raises(ua.UaStatusCodeError) as err:
        on_client(face, body, user="otto", password=token)
    assert err.value.code == ua.StatusCodes.BadUserAccessDenied
    assert ok(face["rest"].get(f"{C}/tools/8")) == before

    async def read(client: Client, ns: dict) -> list:
        return await (await pendant(client, ns)).call_method(f"{ns['pendant']}:ReadFrame", "tool", 8)

    assert on_client(face, read, user="otto", password=token)[0] == before["name"]


def test_a_stale_version_is_refused_and_a_bad_frame_is_a_bad_argument(face: dict) -> None:
    version = int(face["rest"].get(f"{C}/tools/9").headers["ETag"].strip('W/"'))
    ok(edit_slot(face["rest"], f"{C}/tools/9", {"name": "edited over REST"}))

    async def stale(client: Client, ns: dict) -> int:
        return await commit(client, ns, 9, [0.0] * 6, "late", version)

    with pytest.raises(ua.UaStatusCodeError) as err:
        on_client(face, stale)
    assert err.value.code == ua.StatusCodes.BadInvalidState
    assert ok(face["rest"].get(f"{C}/tools/9"))["name"] == "edited over REST"

    async def bad(client: Client, ns: dict) -> int:
        return await commit(client, ns, 9, [0.0, 0.0, 1e12, 0.0, 0.0, 0.0], "far", version + 1)

    with pytest.raises(ua.UaStatusCodeError) as err:
        on_client(face, bad)
    assert err.value.code == ua.StatusCodes.BadInvalidArgument


def test_a_registered_certificate_logs_in_over_the_encrypted_endpoint(face: dict,
                                                                    tmp_path) -> None:
    from server.cli.main import main

    user_cert = client_certificate(tmp_path / "user", "mes-cell-3")
    stranger = client_certificate(tmp_path / "other", "stranger")  # valid, but no user's
    ok(face["rest"].post("/users", json={"name": "mes-cell-3", "role": "Expert"}))
    assert main(["users", "cert", "mes-cell-3", user_cert.cert, "--db", face["db_url"]]) == 0
    version = int(face["rest"].get(f"{C}/tools/11").headers["ETag"].strip('W/"'))

    async def login(identity) -> int:
        client = await secure_client(face["server"].endpoint, face["cert"], identity=identity)
        async with client:
            ns = {"pendant": await client.get_namespace_index(PENDANT_URI)}
            return await commit(client, ns, 11, [5.0, 5.0, 90.0, 0.0, 0.0, 0.0], "scanner",
                                version)

    assert asyncio.run(login(user_cert)) == version + 1
    (rec,) = [r for r in ok(face["rest"].get("/audit", params={"user": "mes-cell-3"}))
              if r.get("number") == 11]
    assert (rec["source"], rec["role"]) == ("opcua", "Expert")
    with pytest.raises(ua.UaStatusCodeError) as err:
        asyncio.run(login(stranger))
    assert err.value.code == ua.StatusCodes.BadUserAccessDenied
    assert ok(face["rest"].get(f"{C}/tools/11"))["name"] == "scanner"


def test_a_busy_database_is_resource_unavailable_and_changes_nothing(face: dict,
                                                                     monkeypatch) -> None:
    """Another writer holds the database past the writers' wait: CommitFrame answers
    BadResourceUnavailable (REST's 503; it was a BadUnexpectedError), nothing is written, and
    the same commit goes through once the database is free."""
    maker = face["rest"].app.state.sessionmaker
    if maker.kw["bind"].dialect.name != "sqlite":
        pytest.skip("SQLite's writers' turn held; PostgreSQL locks the controller's row")
    monkeypatch.setattr(transaction, "TURN_TIMEOUT_S", 0.3)
    version = int(face["rest"].get(f"{C}/tools/10").headers["ETag"].strip('W/"'))
    before = ok(face["rest"].get(f"{C}/tools/10"))

    async def busy(client: Client, ns: dict) -> int:
        holder = transaction.writer(maker)
        with holder, transaction.writers_turn(holder):  # the other writer's turn
            return await commit(client, ns, 10, [5.0, 6.0, 7.0, 0.0, 0.0, 0.0], "held", version)

    with pytest.raises(ua.UaStatusCodeError) as err:
        on_client(face, busy)
    assert err.value.code == ua.StatusCodes.BadResourceUnavailable
    assert ok(face["rest"].get(f"{C}/tools/10")) == before

    async def free(client: Client, ns: dict) -> int:
        return await commit(client, ns, 10, [5.0, 6.0, 7.0, 0.0, 0.0, 0.0], "held", version)

    assert on_client(face, free) == version + 1
    assert ok(face["rest"].get(f"{C}/tools/10"))["name"] == "held"


def test_an_export_the_database_cannot_answer_now_is_resource_unavailable(face: dict,
                                                                          monkeypatch) -> None:
    """ExportFile reads the database: when it cannot answer now (every connection busy), the
    call answers BadResourceUnavailable, as CommitFrame and REST's 503 do (it was
    BadUnexpectedError), and the next call answers the file."""
    from sqlalchemy.exc import TimeoutError as PoolTimeout

    def busy(cid: int, fmt: str) -> str:
        raise PoolTimeout("every connection busy")

    async def body(client: Client, ns: dict) -> str:
        return await (await pendant(client, ns)).call_method(f"{ns['pendant']}:ExportFile", "abb")

    monkeypatch.setattr(face["server"], "_export", busy)
    with pytest.raises(ua.UaStatusCodeError) as err:
        on_client(face, body)
    assert err.value.code == ua.StatusCodes.BadResourceUnavailable
    monkeypatch.undo()
    assert on_client(face, body) == face["rest"].get(f"{C}/export", params={"format": "abb"}).text
