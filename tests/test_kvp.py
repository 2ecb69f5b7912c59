"""The KVP face driven by the unmodified ``py-openshowvar`` client, as cell software talks to a
KRC4 through KUKAVARPROXY: jog through REST and read $AXIS_ACT, write BASE_DATA and read it
through REST; the acting user's role decides writes; bad messages get the protocol's error
and never stall the face."""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Iterator

import pytest
from api_helpers import C, edit_slot, make_client, ok, wait_for
from browser_helpers import free_port

from server.kvp import server as kvp
from server.kvp.server import KvpFace, serve_in_thread
from server.service import transaction

openshowvar = pytest.importorskip("py_openshowvar").openshowvar


@pytest.fixture(scope="module")
def cell(fresh_db, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """REST (TestClient) and the KVP face on loopback, acting as the Expert "cellpc", on the
    demo KUKA controller."""

    db_url = fresh_db()
    with make_client(db_url) as rest:
        ok(rest.post("/users", json={"name": "cellpc", "role": "Expert"}))
        maker = rest.app.state.sessionmaker
        port = free_port()
        face = KvpFace(maker, "cellpc")
        running = serve_in_thread(face, "127.0.0.1", port)
        try:
            yield {"rest": rest, "port": port, "face": face}
        finally:
            running.stop()


def connect(cell: dict) -> openshowvar:
    c = openshowvar("127.0.0.1", cell["port"])
    return c


def numbers(krl: bytes, keys: str | list[str]) -> list[float]:
    """The components ``keys`` of a KRL aggregate as printed (``{E6AXIS: A1 1.0, ...}``)."""
    text = krl.decode()
    parts = dict(p.strip().split(" ", 1) for p in text[text.index(":") + 1:-1].split(","))
    return [float(parts[k]) for k in keys]


def test_jog_through_rest_read_axis_act_through_kvp(cell: dict) -> None:
    rest = cell["rest"]
    ok(rest.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A2", "increment": -7.25}))
    joints = ok(rest.get(f"{C}/robot"))["joints_deg"]
    c = connect(cell)
    try:
        value = c.read("$AXIS_ACT", debug=False)
        assert value.startswith(b"{E6AXIS: A1 ")
        assert numbers(value, ["A1", "A2", "A3", "A4", "A5", "A6"]) == \
            pytest.approx(joints, abs=1e-9)
        tcp = ok(rest.get(f"{C}/robot"))["tcp_pose"]
        pos = c.read("$POS_ACT", debug=False)
        assert numbers(pos, list("XYZABC")) == pytest.approx([tcp[k] for k in "xyzabc"],
                                                             abs=1e-6)
        assert c.read("$OV_PRO", debug=False) == b"100"
    finally:
        c.close()


def test_write_base_data_through_kvp_read_through_rest(cell: dict) -> None:
    """BASE_DATA[4] written as KRL; REST shows it with the audit source kvp; a partial
    aggregate changes only what it names; BASE_NAME too."""
    rest = cell["rest"]
    c = connect(cell)
    try:
        back = c.write("BASE_DATA[4]", "{X 650.5,Y -120.0,Z 12.0,A 90.0,B 0.0,C 180.0}",
                       debug=False)
        assert back == b"{FRAME: X 650.5, Y -120.0, Z 12.0, A 90.0, B 0.0, C 180.0}"
        slot = ok(rest.get(f"{C}/bases/4"))
        assert [slot["pose"][k] for k in "xyzabc"] == \
            pytest.approx([650.5, -120.0, 12.0, 90.0, 0.0, 180.0])
        assert slot["provenance"]["updated_by"] == "cellpc"
        audit = [a for a in ok(rest.get("/audit", params={"controller_id": 1}))
                 if a["table"] == "base" and a["number"] == 4]
        assert (audit[-1]["source"], audit[-1]["user"]) == ("kvp", "cellpc")
        c.write("BASE_DATA[4]", "{FRAME: Z 20.5}", debug=False)
        assert ok(rest.get(f"{C}/bases/4"))["pose"]["z"] == 20.5
        assert ok(rest.get(f"{C}/bases/4"))["pose"]["x"] == 650.5
        assert c.write("BASE_NAME[4,]", '"fixture A"', debug=False) == b'"fixture A"'
        assert ok(rest.get(f"{C}/bases/4"))["name"] == "fixture A"
    finally:
        c.close()


def test_rest_edit_tool_and_load_read_through_kvp(cell: dict) -> None:
    rest = cell["rest"]
    ok(edit_slot(rest, f"{C}/tools/2", {"name": "gripper", "pose": {"z": 155.5, "a": 45},
                                        "load": {"mass_kg": 3.2, "com_mm": [0, 0, 80]}}))
    ok(rest.put(f"{C}/robot/active", json={"tool_no": 2}))
    c = connect(cell)
    try:
        assert c.read("TOOL_DATA[2]", debug=False) == \
            b"{FRAME: X 0.0, Y 0.0, Z 155.5, A 45.0, B 0.0, C 0.0}"
        assert c.read("$TOOL", debug=False) == c.read("TOOL_DATA[2]", debug=False)
        assert c.read("TOOL_NAME[2,]", debug=False) == b'"gripper"'
        assert c.read("$ACT_TOOL", debug=False) == b"2"
        assert c.read("LOAD_DATA[2]", debug=False).startswith(b"{LOAD: M 3.2, CM {FRAME: X 0.0,")
        c.write("LOAD_DATA[2]", "{M 4.0,CM {X 0,Y 0,Z 90,A 0,B 0,C 0},J {X 0.1,Y 0.1,Z 0.05}}",
                debug=False)
        assert ok(rest.get(f"{C}/tools/2"))["load"]["mass_kg"] == 4.0
        assert c.write("$ACT_BASE", "4", debug=False) == b"4"
        assert ok(rest.get(f"{C}/robot"))["active_base_no"] == 4
        # audited as REST's PUT .../robot/active is: one op.set_active, the face its source
        last = ok(rest.get("/audit", params={"controller_id": 1}))[-1]
        assert (last["action"], last["source"], last["user"]) == \
            ("op.set_active", "kvp", "cellpc")
    finally:
        c.close()


def raw(port: int, msg_id: int, mode: int, name: bytes, value: bytes | None = None) -> bytes:
    content = struct.pack("!BH", mode, len(name)) + name
    if value is not None:
        content += struct.pack("!H", len(value)) + value
    return struct.pack("!HH", msg_id, len(content)) + content


def answer_of(sock: socket.socket) -> tuple[int, str, bool]:
    head = b""
    while len(head) < 4:
        chunk = sock.recv(4 - len(head))
        if not chunk:
            raise ConnectionError("closed")
        head += chunk
    msg_id, length = struct.unpack("!HH", head)
    body = b""
    while len(body) < length:
        body += sock.recv(length - len(body))
    (value_len,) = struct.unpack_from("!H", body, 1)
    return msg_id, body[3:3 + value_len].decode(), body[-1] == 1


def test_bad_input_gets_the_protocols_error(cell: dict) -> None:
    """Unknown variable, malformed literal, write-protected variable: status 0 with the
    reason; nothing changed; the connection goes on."""
    before = ok(cell["rest"].get(f"{C}/tools/5"))
    with socket.create_connection(("127.0.0.1", cell["port"]), timeout=10) as s:
        s.sendall(raw(cell["port"], 7, 0, b"$NO_SUCH_VAR"))
        msg_id, text, good = answer_of(s)
        assert (msg_id, good) == (7, False) and "not a variable pendant serves" in text
        s.sendall(raw(cell["port"], 8, 1, b"TOOL_DATA[5]", b"{X 1,Y 2,Z}"))
        msg_id, text, good = answer_of(s)
        assert (msg_id, good) == (8, False) and "TOOL_DATA[5].Z" in text
        s.sendall(raw(cell["port"], 9, 1, b"TOOL_DATA[5]", b"{X 1e9}"))
        msg_id, text, good = answer_of(s)
        assert not good and "TOOL_DATA[5].X" in text
        s.sendall(raw(cell["port"], 10, 1, b"$AXIS_ACT", b"{A1 0}"))
        assert "write-protected" in answer_of(s)[1]
        s.sendall(raw(cell["port"], 11, 0, b"TOOL_DATA[99]"))
        assert "out of range" in answer_of(s)[1]
        s.sendall(raw(cell["port"], 12, 0, b"$OV_PRO"))
        assert answer_of(s) == (12, "100", True)
        # digits of other scripts are not KRL's (Python's \\d and float() take them)
        s.sendall(raw(cell["port"], 13, 0, "TOOL_DATA[\u0663]".encode()))
        assert "not a variable pendant serves" in answer_of(s)[1]
        s.sendall(raw(cell["port"], 14, 1, b"$ACT_TOOL", "\u0663".encode()))
        assert "expected an INT slot number" in answer_of(s)[1]
        s.sendall(raw(cell["port"], 15, 1, b"TOOL_DATA[5]", "{X \u0663}".encode()))
        assert answer_of(s)[2] is False
    assert ok(cell["rest"].get(f"{C}/tools/5")) == before


def test_oversize_and_half_sent_messages_never_stall_the_face(cell: dict, monkeypatch) -> None:
    """An oversize message gets its error and the connection closes; a half-sent one is
    closed after the frame timeout; meanwhile another client is served."""
    monkeypatch.setattr(kvp, "FRAME_TIMEOUT_S", 1.0)
    with socket.create_connection(("127.0.0.1", cell["port"]), timeout=10) as big:
        big.sendall(struct.pack("!HH", 3, 60000) + b"\x00" * 100)
        msg_id, text, good = answer_of(big)
        assert (msg_id, good) == (3, False) and "at most 4096" in text
        assert big.recv(1) == b""  # closed
    half = socket.create_connection(("127.0.0.1", cell["port"]), timeout=10)
    half.sendall(raw(cell["port"], 4, 0, b"$OV_PRO")[:6])  # header and part of the content
    c = connect(cell)
    try:
        t0 = time.monotonic()
        assert c.read("$OV_PRO", debug=False) == b"100"  # served while the other one hangs
        assert time.monotonic() - t0 < 1.0
    finally:
        c.close()
    half.settimeout(10)
    assert half.recv(1) == b""  # the face closed the half-sent message's connection
    half.close()


def test_operator_user_reads_but_cannot_write(cell: dict) -> None:
    """The face acts as its configured user: as an Operator, reads pass, writes are refused
    (py-openshowvar answers None for a refusal) and the slot is unchanged."""
    rest = cell["rest"]
    ok(rest.post("/users", json={"name": "viewer", "role": "Operator"}))
    port = free_port()
    running = serve_in_thread(KvpFace(rest.app.state.sessionmaker, "viewer"), "127.0.0.1", port)
    try:
        c = openshowvar("127.0.0.1", port)
        before = ok(rest.get(f"{C}/bases/6"))
        assert c.read("BASE_DATA[6]", debug=False).startswith(b"{FRAME: X ")
        assert c.write("BASE_DATA[6]", "{X 1}", debug=False) is None
        assert ok(rest.get(f"{C}/bases/6")) == before
        c.close()
        with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
            s.sendall(raw(port, 5, 1, b"BASE_DATA[6]", b"{X 1}"))
            assert "frames:commit" in answer_of(s)[1]
    finally:
        running.stop()


def test_a_write_its_user_may_make_is_answered_as_done_without_read_permission(cell: dict) -> None:
    """A site role that may select frames (robot:jog) and commit them (frames:commit) but not
    read them: its $ACT_TOOL and TOOL_DATA writes are applied and answered as done, with what
    they wrote, as REST answers a PUT (the answer was a refusal 'needs frames:read' after the
    write had committed)."""
    from server.auth import tokens

    rest = cell["rest"]
    with rest.app.state.sessionmaker() as db:
        tokens.add_role(db, "Setter", ["robot:jog", "frames:commit"])
        tokens.add_user(db, "setter", "Setter")
        db.commit()
    port = free_port()
    running = serve_in_thread(KvpFace(rest.app.state.sessionmaker, "setter"), "127.0.0.1", port)
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
            s.sendall(raw(port, 1, 1, b"$ACT_TOOL", b"5"))
            assert answer_of(s) == (1, "5", True)
            s.sendall(raw(port, 2, 1, b"TOOL_DATA[7]", b"{X 12.5}"))
            msg_id, text, good = answer_of(s)
            assert (msg_id, good) == (2, True) and text.startswith("{FRAME: X 12.5"), text
            s.sendall(raw(port, 3, 0, b"TOOL_DATA[7]"))  # a read still needs frames:read
            msg_id, text, good = answer_of(s)
            assert (msg_id, good) == (3, False) and "frames:read" in text
        assert ok(rest.get(f"{C}/robot"))["active_tool_no"] == 5
        assert ok(rest.get(f"{C}/tools/7"))["pose"]["x"] == 12.5
    finally:
        running.stop()


def test_a_partial_write_keeps_a_change_another_face_made_meanwhile(cell: dict, monkeypatch) -> None:
    """``TOOL_DATA[9] := {X 5.0}`` keeps Y..C as they are. A person's REST edit of Y committed
    between the face's read of the slot and its write is kept (the write carried the version
    it merged with, and merged again); it was overwritten with the old Y."""
    from server.rws import ops

    rest = cell["rest"]
    ok(edit_slot(rest, f"{C}/tools/9", {"pose": {"x": 1.0, "y": 2.0, "z": 3.0}}))
    real_slot, edits = ops.slot, []

    def slot_then_a_person_edits(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        read = real_slot(*args, **kwargs)
        if not edits:  # once: between this read and the face's write
            edits.append(ok(edit_slot(rest, f"{C}/tools/9", {"pose": {"y": 222.0}})))
        return read

    monkeypatch.setattr(ops, "slot", slot_then_a_person_edits)
    c = connect(cell)
    try:
        back = c.write("TOOL_DATA[9]", "{X 5.0}", debug=False)
    finally:
        c.close()
    assert edits and back.startswith(b"{FRAME: X 5.0, Y 222.0, Z 3.0"), back
    pose = ok(rest.get(f"{C}/tools/9"))["pose"]
    assert (pose["x"], pose["y"], pose["z"]) == (5.0, 222.0, 3.0)


def test_a_partial_write_that_keeps_meeting_other_writers_is_refused_whole(cell: dict,
                                                                           monkeypatch) -> None:
    """Another writer changes the slot between every read and write: after three merges the
    write is refused naming the variable, and nothing of it is written."""
    from server.rws import ops

    rest = cell["rest"]
    ok(edit_slot(rest, f"{C}/tools/10", {"pose": {"x": 1.0}}))
    real_slot, edits = ops.slot, []

    def slot_then_another_edit(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        read = real_slot(*args, **kwargs)
        edits.append(ok(edit_slot(rest, f"{C}/tools/10", {"pose": {"y": float(len(edits))}})))
        return read

    monkeypatch.setattr(ops, "slot", slot_then_another_edit)
    with socket.create_connection(("127.0.0.1", cell["port"]), timeout=10) as s:
        s.sendall(raw(cell["port"], 4, 1, b"TOOL_DATA[10]", b"{X 5.0}"))
        msg_id, text, good = answer_of(s)
    assert (msg_id, good) == (4, False) and text.startswith("TOOL_DATA[10]: changed by another"), text
    assert len(edits) == 3 and ok(rest.get(f"{C}/tools/10"))["pose"]["x"] == 1.0


def test_a_long_refusal_does_not_put_the_client_out_of_step(cell: dict) -> None:
    """py-openshowvar reads an answer in one recv(256): a refusal naming a long unknown
    variable (and the variables pendant serves) was ~270 bytes, and the client's next reads
    returned the tail of it, then $OV_PRO's value for $ACT_TOOL. Refusals fit now; each
    read gets its own value."""
    rest = cell["rest"]
    c = connect(cell)
    try:
        assert c.read("NO_SUCH_VARIABLE_" + "X" * 80, debug=False) is None
        assert c.read("$OV_PRO", debug=False) == b"100"
        active = ok(rest.get(f"{C}/robot"))["active_tool_no"]
        assert c.read("$ACT_TOOL", debug=False) == str(active).encode()
        assert c.read("TOOL_DATA[1]", debug=False).startswith(b"{FRAME: X ")
        name = "\u00e9" * 200  # a refusal cut between characters, never inside one
        with socket.create_connection(("127.0.0.1", cell["port"]), timeout=10) as s:
            s.sendall(raw(cell["port"], 9, 0, name.encode()))
            msg_id, text, good = answer_of(s)
            assert (msg_id, good) == (9, False) and text.endswith("...") and len(text.encode()) <= 240
    finally:
        c.close()


def test_connections_held_open_and_silent_lock_no_client_out(cell: dict, monkeypatch) -> None:
    """As many silent connections as the face takes: a new client is still served (the one
    idle longest is closed for it); they used to hold every place for the idle timeout."""
    monkeypatch.setattr(kvp, "MAX_CONNECTIONS", 4)
    silent = [socket.create_connection(("127.0.0.1", cell["port"]), timeout=10)
              for _ in range(4)]
    try:
        wait_for(lambda: cell["face"].connections >= 4)  # the face has taken them all
        c = connect(cell)
        assert c.read("$OV_PRO", debug=False) == b"100"
        c.close()
        silent[0].settimeout(10)
        assert silent[0].recv(1) == b""  # the one idle longest made room
    finally:
        for s in silent:
            s.close()


def test_only_allowed_clients_are_served(cell: dict) -> None:
    face = KvpFace(None, "cellpc", allowed=("10.1.2.3",))  # type: ignore[arg-type]
    assert face.allows("127.0.0.1") and face.allows("::1") and face.allows("10.1.2.3")
    assert not face.allows("10.1.2.4") and not face.allows(None)


def test_a_revoked_user_ends_the_faces_answers(cell: dict) -> None:
    """The face acts as its user as the database has it now: revoked, every message is
    refused naming why."""
    rest = cell["rest"]
    ok(rest.post("/users", json={"name": "leaver", "role": "Expert"}))
    port = free_port()
    running = serve_in_thread(KvpFace(rest.app.state.sessionmaker, "leaver"), "127.0.0.1", port)
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
            s.sendall(raw(port, 1, 0, b"$OV_PRO"))
            assert answer_of(s) == (1, "100", True)
            assert rest.delete("/users/leaver").status_code < 300
            s.sendall(raw(port, 2, 0, b"$OV_PRO"))
            msg_id, text, good = answer_of(s)
            assert (msg_id, good) == (2, False) and "revoked" in text
    finally:
        running.stop()


def test_a_busy_database_is_a_refusal_to_retry_and_the_connection_goes_on(
        cell: dict, monkeypatch) -> None:
    """Another writer holds the database past the writers' wait (a long restore, the CLI): the
    write is refused with the reason, nothing is written, the same connection answers the
    next message (it was ended, with a traceback in the log)."""
    rest = cell["rest"]
    maker = rest.app.state.sessionmaker
    if maker.kw["bind"].dialect.name != "sqlite":
        pytest.skip("SQLite's writers' turn held; PostgreSQL locks the controller's row")
    monkeypatch.setattr(transaction, "TURN_TIMEOUT_S", 0.3)
    before = ok(rest.get(f"{C}/tools/6"))
    with socket.create_connection(("127.0.0.1", cell["port"]), timeout=10) as s:
        holder = transaction.writer(maker)
        with holder, transaction.writers_turn(holder):  # the other writer's turn
            s.sendall(raw(cell["port"], 21, 1, b"TOOL_DATA[6]", b"{X 7.5}"))
            msg_id, text, good = answer_of(s)
        assert (msg_id, good) == (21, False) and "locked by another writer" in text, text
        assert "nothing was written" in text
        s.sendall(raw(cell["port"], 22, 0, b"$OV_PRO"))
        assert answer_of(s) == (22, "100", True)
    assert ok(rest.get(f"{C}/tools/6")) == before


def test_a_write_whose_read_back_meets_a_busy_database_is_answered_as_done(
        cell: dict, monkeypatch) -> None:
    """The write committed, then the database could not answer the read of the value back:
    the write is answered as done, with the value as sent (it was refused as 'nothing was
    written', which was false)."""
    from sqlalchemy.exc import TimeoutError as PoolTimeout
    from server.kvp import variables

    read = variables.read

    def busy_after_the_write(face, name, after_write=False):  # noqa: ANN001
        if after_write:
            raise PoolTimeout("every connection busy")
        return read(face, name, after_write=after_write)

    monkeypatch.setattr(variables, "read", busy_after_the_write)
    with socket.create_connection(("127.0.0.1", cell["port"]), timeout=10) as s:
        s.sendall(raw(cell["port"], 31, 1, b"TOOL_DATA[7]", b"{X 9.5}"))
        assert answer_of(s) == (31, "{X 9.5}", True)
    monkeypatch.setattr(variables, "read", read)
    assert ok(cell["rest"].get(f"{C}/tools/7"))["pose"]["x"] == 9.5
