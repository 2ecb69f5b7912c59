"""Findings of an attacker's probe of the RWS and KVP faces, each a reproduction that failed on
the code before its fix: the faces started as tests/test_rws.py and tests/test_kvp.py start
them (uvicorn / asyncio on loopback, REST on the same database), driven by raw requests and by
the unmodified clients (abb-robot-client, py-openshowvar) where they can say it."""

from __future__ import annotations

import hashlib
import queue
import socket
import struct
import time
from collections.abc import Iterator

import pytest
import requests
from api_helpers import edit_slot, make_client, ok, wait_for
from browser_helpers import free_port

from server.kvp.server import KvpFace, serve_in_thread
from server.rws import app as rws_app, digest, ops
from server.rws.app import RwsFace, create_rws_app
from server.rws.service import serve_asgi

rws = pytest.importorskip("abb_robot_client.rws")

PASSWORD = {"expert": "expert-secret", "operator": "operator-secret", "leaver": "leaver-secret"}
STATE = "/rw/panel/ctrlstate?json=1"


@pytest.fixture(scope="module")
def cell(fresh_db) -> Iterator[dict]:
    """REST, the RWS face (an ABB controller, users with RWS secrets) and the KVP face (the
    demo KUKA controller, acting as the Expert) on one database."""
    with make_client(fresh_db()) as rest:
        cid = ok(rest.post("/controllers", json={"name": "abb-1", "robot": "abb_irb120"}))["id"]
        maker = rest.app.state.sessionmaker
        for name, role in (("expert", "Expert"), ("operator", "Operator"),
                           ("leaver", "Expert")):
            ok(rest.post("/users", json={"name": name, "role": role}))
            with maker() as db:
                ops.set_rws_ha1(db, name, digest.ha1(name, PASSWORD[name]))
                db.commit()
        port, kvp_port = free_port(), free_port()
        face = RwsFace(maker)
        running = serve_asgi(create_rws_app(face), "127.0.0.1", port, "rws-attack")
        kvp = serve_in_thread(KvpFace(maker, "expert"), "127.0.0.1", kvp_port)
        try:
            yield {"rest": rest, "cid": cid, "url": f"http://127.0.0.1:{port}", "face": face,
                   "kvp_port": kvp_port}
        finally:
            running.stop()
            kvp.stop()


def _md5(text: str) -> str:
    return hashlib.md5(text.encode()).hexdigest()


def _nonce(cell: dict) -> str:
    r = requests.get(cell["url"] + STATE)
    assert r.status_code == 401
    return digest.parse(r.headers["WWW-Authenticate"])["nonce"]


def test_a_digest_without_qop_cannot_be_replayed_with_a_new_cnonce(cell: dict) -> None:
    """A request signed without qop (RFC 2069: the response covers only HA1, nonce and HA2)
    is refused the second time; a replay that only added a ``cnonce`` and ``nc`` (not part of
    that response) was accepted: the face's seen-key took them from the header."""
    nonce, user = _nonce(cell), "expert"
    response = _md5(f"{digest.ha1(user, PASSWORD[user])}:{nonce}:{_md5('GET:' + STATE)}")
    header = (f'Digest username="{user}", realm="validusers", nonce="{nonce}", '
              f'uri="{STATE}", response="{response}"')
    assert requests.get(cell["url"] + STATE, headers={"Authorization": header}).status_code == 200
    assert requests.get(cell["url"] + STATE, headers={"Authorization": header}).status_code == 401
    for k in range(3):  # the captured request again, with parameters the response ignores
        replay = header + f', cnonce="replay{k}", nc=0000000{k + 1}'
        r = requests.get(cell["url"] + STATE, headers={"Authorization": replay})
        assert r.status_code == 401, (replay, r.status_code)


def test_logout_leaves_no_live_login_cookie(cell: dict) -> None:
    """``GET /logout`` ends the ABBCX login; its own answer set a new live cookie for the same
    user (the guard logged the request in again after the handler ended the session), so a
    client that "logged out" still held a cookie that opens subscription sockets."""
    s = requests.Session()
    s.auth = requests.auth.HTTPDigestAuth("expert", PASSWORD["expert"])
    assert s.get(cell["url"] + STATE).status_code == 200
    before = s.cookies.get("ABBCX")
    assert cell["face"].session_user(before) == "expert"
    r = s.get(cell["url"] + "/logout")
    assert r.status_code == 204
    assert cell["face"].session_user(before) is None
    after = s.cookies.get("ABBCX")
    assert after is None or cell["face"].session_user(after) is None, r.headers.get("set-cookie")


def test_a_revoked_users_open_subscription_stops(cell: dict) -> None:
    """Revoking a user ends their RWS access at once (docs/rws.md): a PERS subscription socket
    they had opened went on sending every new value of the symbol, with the permissions read
    when it opened."""
    got: queue.Queue = queue.Queue()
    c = rws.RWS(cell["url"], "leaver", PASSWORD["leaver"])
    sub = c.subscribe([rws.SubscriptionResourceRequest(rws.SubscriptionResourceType.PersVar,
                                                       rws.SubscriptionResourcePriority.High,
                                                       "tool5")], got.put)
    path = f"/controllers/{cell['cid']}/tools/5"
    try:
        wait_for(lambda: any(s.opened for s in cell["face"].subscriptions.values()
                             if s.owner == "leaver"))
        sent = False
        for k in range(50):  # edits until the socket's first look has a value to compare
            ok(edit_slot(cell["rest"], path, {"pose": {"z": 10.0 + k}}))
            try:
                sent = isinstance(got.get(timeout=1.0), rws.VariableValue)
            except queue.Empty:
                continue
            if sent:
                break
        assert sent, "the socket sends"
        assert cell["rest"].delete("/users/leaver").status_code == 204
        wait_for(lambda: not any(s.owner == "leaver"  # its next look ends the socket
                                 for s in cell["face"].subscriptions.values()))
        while not got.empty():
            got.get_nowait()
        ok(edit_slot(cell["rest"], path, {"pose": {"z": 999.5}}))
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            try:
                event = got.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                break
            assert not isinstance(event, rws.VariableValue), \
                f"a revoked user's socket sent {event.value}"
    finally:
        sub.close()


def test_a_deeply_nested_literal_is_a_400_not_a_500(cell: dict) -> None:
    """A RAPID literal of 1500 '[' (within the 2000-character limit; an Operator's login is
    enough, the literal is read before the permission is checked) or a module holding one made
    the ABB reader recurse past Python's stack: a 500 without RWS's error body, a traceback in
    the log and the connection reset. It is a 400 naming the reason, nothing is written, and
    the face goes on."""
    auth = requests.auth.HTTPDigestAuth("expert", PASSWORD["expert"])
    operator = requests.auth.HTTPDigestAuth("operator", PASSWORD["operator"])
    path = f"/controllers/{cell['cid']}/tools/1"
    before = cell["rest"].get(path).headers["etag"]
    url = cell["url"] + "/rw/rapid/symbol/data/RAPID/T_ROB1/tool1?action=set&json=1"
    r = requests.post(url, data={"value": "[" * 1500}, auth=operator)
    assert r.status_code == 400, (r.status_code, r.text[:200])
    assert "nests brackets more than 16 deep" in r.json()["_embedded"]["status"]["msg"]
    module = "MODULE M\n  PERS tooldata t1:=" + "[" * 1500 + ";\nENDMODULE\n"
    r = requests.put(cell["url"] + "/fileservice/$HOME/M.mod?json=1", data=module.encode(),
                     auth=auth)
    assert r.status_code == 400, (r.status_code, r.text[:200])
    assert cell["rest"].get(path).headers["etag"] == before
    assert requests.get(cell["url"] + STATE, auth=auth).status_code == 200


def _kvp_message(msg_id: int, name: str, value: str | None = None) -> bytes:
    """A KUKAVARPROXY request as py-openshowvar packs it (mode 0 read, 1 write)."""
    n = name.encode()
    if value is None:
        return struct.pack("!HHBH", msg_id, 3 + len(n), 0, len(n)) + n
    v = value.encode()
    return (struct.pack("!HHBH", msg_id, 5 + len(n) + len(v), 1, len(n)) + n
            + struct.pack("!H", len(v)) + v)


def _kvp_answer(sock: socket.socket) -> tuple[int, bytes, int]:
    """(msg_id, value, ok) of one answer; the connection closing before it is an error."""
    def exactly(k: int) -> bytes:
        data = b""
        while len(data) < k:
            chunk = sock.recv(k - len(data))
            assert chunk, "the face closed the connection without an answer"
            data += chunk
        return data

    msg_id, length = struct.unpack("!HH", exactly(4))
    body = exactly(length)
    (value_len,) = struct.unpack_from("!H", body, 1)
    return msg_id, body[3:3 + value_len], body[-1]


def test_a_deeply_nested_kvp_value_is_a_refusal_and_the_connection_goes_on(cell: dict) -> None:
    """A write of ``{X {X {X ...`` (1300 levels, 3.9 KB: within the 4096-byte message) made the
    KRL reader recurse past Python's stack: the connection was closed without an answer (and
    a traceback logged), where every other bad value is a refusal (ok 0) saying why. Now a
    refusal; nothing is written and the same connection answers the next message."""
    path = "/controllers/1/bases/1"
    before = cell["rest"].get(path).headers["etag"]
    with socket.create_connection(("127.0.0.1", cell["kvp_port"]), timeout=10) as sock:
        for nested in ("{X " * 1300, "{M " * 1300):
            var = "BASE_DATA[1]" if nested.startswith("{X") else "LOAD_DATA[1]"
            sock.sendall(_kvp_message(11, var, nested))
            msg_id, value, ok_ = _kvp_answer(sock)
            assert (msg_id, ok_) == (11, 0) and b"more than 16 deep" in value, value
        sock.sendall(_kvp_message(12, "$OV_PRO"))
        assert _kvp_answer(sock) == (12, b"100", 1)
    assert cell["rest"].get(path).headers["etag"] == before


def test_a_captured_request_stays_refused_after_others_fill_the_replay_memory(
        cell: dict, monkeypatch) -> None:
    """The face remembers the used (nonce, cnonce, nc) up to SEEN_MAX and forgot the oldest
    first, while their nonces were still honoured: any login (an Operator's) sending SEEN_MAX
    requests pushed a captured Expert request out, which then replayed (measured with
    SEEN_MAX 4: 200). A nonce older than one forgotten is now refused as stale."""
    monkeypatch.setattr(digest, "SEEN_MAX", 4)
    nonce, user = _nonce(cell), "expert"
    ha2 = _md5("GET:" + STATE)
    response = _md5(f"{digest.ha1(user, PASSWORD[user])}:{nonce}:00000001:captured:auth:{ha2}")
    header = (f'Digest username="{user}", realm="validusers", nonce="{nonce}", uri="{STATE}", '
              f'response="{response}", qop=auth, nc=00000001, cnonce="captured"')
    assert requests.get(cell["url"] + STATE, headers={"Authorization": header}).status_code == 200
    operator = requests.Session()
    operator.auth = requests.auth.HTTPDigestAuth("operator", PASSWORD["operator"])
    for _ in range(6):
        assert operator.get(cell["url"] + STATE).status_code == 200
    r = requests.get(cell["url"] + STATE, headers={"Authorization": header})
    assert r.status_code == 401 and "stale=true" in r.headers["WWW-Authenticate"]
    assert operator.get(cell["url"] + STATE).status_code == 200  # a new nonce is honoured


def test_a_set_keeps_the_name_the_client_wrote_an_unnamed_slot_under(cell: dict) -> None:
    """A client fills the empty base slot 6 through its default symbol ``wobj6`` with a
    coordinated wobjdata (ufprog FALSE, ufmec "STN1"): 204, but the export names an unnamed
    coordinated base ``cwobj6``, so ``wobj6`` was gone right after the set (404 to
    abb-robot-client's get, a subscription to it silent). The slot now keeps the name the
    client wrote it under, and the symbol reads back."""
    c = rws.RWS(cell["url"], "expert", PASSWORD["expert"])
    value = '[FALSE,FALSE,"STN1",[[500,10,5],[1,0,0,0]],[[0,0,0],[1,0,0,0]]]'
    c.set_rapid_variable("wobj6", value)
    assert c.get_rapid_variable("wobj6") == value
    slot = ok(cell["rest"].get(f"/controllers/{cell['cid']}/bases/6"))
    assert (slot["kind"], slot["mech_unit"], slot["name"]) == ("coordinated_base", "STN1", "wobj6")
    c.set_rapid_variable("wobj6", value.replace("FALSE,FALSE,\"STN1\"", "FALSE,TRUE,\"\""))
    assert c.get_rapid_variable("wobj6").startswith("[FALSE,TRUE,")


def test_a_long_name_does_not_put_py_openshowvar_out_of_step(cell: dict) -> None:
    """REST takes a slot name of 64 characters; 64 four-byte characters made TOOL_NAME[n,]'s
    answer 268 bytes, past the 256 py-openshowvar reads at once: it answered None (the byte it
    took for the status was inside the name) and left the tail for the next read. A
    KRC4's TOOL_NAME is CHAR[24] (and the face's KUKA export cuts names to 24 characters):
    the face answers the first 24, and the client stays in step."""
    from py_openshowvar import openshowvar

    name = "\U0001F527" * 64  # a wrench, 4 bytes in UTF-8
    ok(edit_slot(cell["rest"], "/controllers/1/tools/7", {"name": name}))
    krc = openshowvar("127.0.0.1", cell["kvp_port"])
    try:
        assert krc.read("TOOL_NAME[7,]", debug=False) == ('"' + name[:24] + '"').encode()
        assert krc.read("$OV_PRO", debug=False) == b"100"
    finally:
        krc.close()


def test_a_subscription_of_many_resources_costs_one_look_at_the_symbols(cell: dict) -> None:
    """POST /subscription read the controller's module and slots again for every resource it
    names (about 58 ms each here): 300 resources, 19 KB, an Operator's login, held a worker
    thread and the database for 17 s, and a 64 KiB form names over 1000. It now reads the
    symbols once per request."""
    operator = requests.auth.HTTPDigestAuth("operator", PASSWORD["operator"])
    n = 300
    form = ([("resources", str(i)) for i in range(n)]
            + [(str(i), "/rw/rapid/symbol/data/RAPID/T_ROB1/tool1;value") for i in range(n)])
    started = time.monotonic()
    r = requests.post(cell["url"] + "/subscription", data=form, auth=operator)
    took = time.monotonic() - started
    assert r.status_code == 201, r.text[:200]
    assert took < 5.0, f"{n} resources took {took:.1f} s"


def test_a_partial_load_data_write_keeps_what_it_does_not_name(cell: dict) -> None:
    """docs/kvp.md: a partial aggregate changes only the components it names, as a KRL
    assignment does, and ``M -1`` clears a load. ``LOAD_DATA[n]={M 4.5}`` and
    ``LOAD_DATA[n]={M -1}`` were refused ("missing CM, J; expected M, CM, J"): only a whole
    load could be written. Now the mass changes and CM and J stay, ``{M -1}`` clears the load,
    each write one audit record."""
    from py_openshowvar import openshowvar

    path = "/controllers/1/tools/11"
    ok(edit_slot(cell["rest"], path, {"pose": {"z": 200.0}, "load": {
        "mass_kg": 3.2, "com_mm": [0.0, 0.0, 90.0], "inertia_kgm2": [0.1, 0.1, 0.05]}}))

    def audits() -> int:
        return sum(1 for a in ok(cell["rest"].get("/audit", params={"controller_id": 1}))
                   if (a["table"], a["number"], a["source"]) == ("tool", 11, "kvp"))

    krc = openshowvar("127.0.0.1", cell["kvp_port"])
    try:
        back = krc.write("LOAD_DATA[11]", "{M 4.5}", debug=False)
        assert back is not None and back.startswith(b"{LOAD: M 4.5, CM {FRAME: X 0.0, Y 0.0, "
                                                    b"Z 90.0"), back
        load = ok(cell["rest"].get(path))["load"]
        assert (load["mass_kg"], load["com_mm"], load["inertia_kgm2"]) == \
            (4.5, [0.0, 0.0, 90.0], [0.1, 0.1, 0.05])
        assert audits() == 1
        assert krc.write("LOAD_DATA[11]", "{M -1}", debug=False).startswith(b"{LOAD: M -1.0")
        assert ok(cell["rest"].get(path))["load"] is None and audits() == 2
    finally:
        krc.close()


def test_a_client_that_never_reads_its_answers_locks_no_client_out(cell: dict,
                                                                   monkeypatch) -> None:
    """A client that sends reads and never reads the answers fills the socket: the face's
    write of the next answer waited for room with no time limit, so the connection stayed
    "in the middle of a message" for ever and could not be closed to make room; as many such
    clients as the face takes (here 2) locked every other client out until the service
    restarted. An answer the client takes no room for within the message time limit now
    ends that connection, and the next client is served."""
    from py_openshowvar import openshowvar

    from server.kvp import server as kvp

    monkeypatch.setattr(kvp, "MAX_CONNECTIONS", 2)
    monkeypatch.setattr(kvp, "FRAME_TIMEOUT_S", 1.0)
    # 200 000 messages of 7 bytes whose name runs past them: each answered at once with a
    # refusal of 45 bytes (9 MB), far more than the sockets hold; none is ever read
    flood = struct.pack("!HHBH", 1, 3, 0, 200) * 200_000
    hogs = []
    try:
        for _ in range(2):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            s.connect(("127.0.0.1", cell["kvp_port"]))
            s.sendall(flood)
            hogs.append(s)

        # the scenario, not a wait for a state: the hogs flood for 6 s, long enough for the
        # face to fill their sockets (the face's send buffers take seconds to fill, and until
        # then a hog is often between two messages, where it could be closed for room)
        time.sleep(6.0)

        def served() -> bool:  # a new client, once the face has dropped a hog (1 s each)
            krc = openshowvar("127.0.0.1", cell["kvp_port"])
            try:
                return krc.read("$OV_PRO", debug=False) == b"100"
            except (OSError, struct.error):
                return False  # refused while both hogs are mid-message
            finally:
                krc.close()

        wait_for(served, timeout=30.0)  # on the old face: never
    finally:
        for s in hogs:
            s.close()


def test_a_subscriber_sending_on_its_socket_does_not_make_it_look_faster(
        cell: dict, monkeypatch) -> None:
    """A subscription socket looks for changed values every 0.2 s, each look an export of the
    module and the slots (tens of ms of a worker thread). Each message the client sent on the
    socket ended the wait early and started a look: a client sending small frames as fast as
    it could made its socket look hundreds of times a second (an Operator holds 64 such
    sockets, the face's worker threads are 40). Messages now wait for the next look."""
    from websockets.sync.client import connect

    looks: list[float] = []
    real = rws_app._symbols

    def counted(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        looks.append(time.monotonic())
        return real(*args, **kwargs)

    s = requests.Session()
    s.auth = requests.auth.HTTPDigestAuth("operator", PASSWORD["operator"])
    r = s.post(cell["url"] + "/subscription", data={
        "resources": ["1"], "1": "/rw/rapid/symbol/data/RAPID/T_ROB1/tool4;value"})
    assert r.status_code == 201, r.text
    monkeypatch.setattr(rws_app, "_symbols", counted)
    with connect(r.headers["Location"], subprotocols=["robapi2_subscription"],
                 additional_headers={"Cookie": f"ABBCX={s.cookies['ABBCX']}"}) as ws:
        started = time.monotonic()
        while time.monotonic() - started < 1.0:
            ws.send("x")
            time.sleep(0.001)
        time.sleep(0.3)
    during = [t for t in looks if started <= t <= started + 1.0]
    assert len(during) <= 1.0 / rws_app.POLL_S + 2, f"{len(during)} looks in 1 s"


def test_a_long_authorization_header_does_not_stall_the_face(cell: dict) -> None:
    """No login needed: ``Authorization: Digest aaaa...`` (60 000 letters, no '=') made the
    Digest parameter pattern backtrack quadratically in the face's event loop: 18.7 s with
    nothing answered, by the face, to anyone (2 s for 20 000 letters). The header is read in
    linear time, and one longer than a Digest header has any need for is no credential."""
    for header in ("Digest " + "a" * 60_000, "Digest x=\"" + "a" * 60_000,
                   "Digest " + "a " * 30_000, "Digest " + "a" * 3000 + "=" + "b" * 3000):
        started = time.monotonic()
        r = requests.get(cell["url"] + STATE, headers={"Authorization": header}, timeout=60)
        took = time.monotonic() - started
        assert r.status_code == 401 and took < 1.0, (header[:20], r.status_code, took)
    auth = requests.auth.HTTPDigestAuth("expert", PASSWORD["expert"])
    assert requests.get(cell["url"] + STATE, auth=auth).status_code == 200


def test_a_face_serving_the_first_controller_stays_on_it_when_that_is_deleted(fresh_db) -> None:
    """Without --rws-controller / --kvp-controller a face serves the first ABB (KUKA)
    controller, and it looked that up at every request: once that controller was deleted, the
    cell PC's next writes went into the next one, another robot's tool slots, without a word.
    The face now keeps the controller it first served; when that is gone it refuses."""
    from py_openshowvar import openshowvar
    from starlette.testclient import TestClient
    import httpx

    with make_client(fresh_db()) as rest:
        maker = rest.app.state.sessionmaker
        first = ok(rest.post("/controllers", json={"name": "abb-a", "robot": "abb_irb120"}))
        other = ok(rest.post("/controllers", json={"name": "abb-b", "robot": "abb_irb120"}))
        kuka = ok(rest.get("/controllers/1"))["robot"]
        kuka_other = ok(rest.post("/controllers", json={"name": "cell-2", "robot": kuka}))
        ok(rest.post("/users", json={"name": "expert", "role": "Expert"}))
        with maker() as db:
            ops.set_rws_ha1(db, "expert", digest.ha1("expert", PASSWORD["expert"]))
            db.commit()
        auth = httpx.DigestAuth("expert", PASSWORD["expert"])
        kvp_port = free_port()
        kvp = serve_in_thread(KvpFace(maker, "expert"), "127.0.0.1", kvp_port)
        tool = "[TRUE,[[0,0,123],[1,0,0,0]],[1,[0,0,50],[1,0,0,0],0,0,0]]"
        set_ = "/rw/rapid/symbol/data/RAPID/T_ROB1/tool1?action=set&json=1"
        try:
            with TestClient(create_rws_app(RwsFace(maker)), base_url="http://127.0.0.1") as tc:
                krc = openshowvar("127.0.0.1", kvp_port)
                assert tc.post(set_, data={"value": tool}, auth=auth).status_code == 204
                assert krc.write("TOOL_DATA[1]", "{Z 77}", debug=False) is not None
                assert ok(rest.get(f"/controllers/{first['id']}/tools/1"))["pose"]["z"] == 123
                assert ok(rest.get("/controllers/1/tools/1"))["pose"]["z"] == 77
                assert rest.delete(f"/controllers/{first['id']}").status_code == 204
                assert rest.delete("/controllers/1").status_code == 204
                r = tc.post(set_, data={"value": tool}, auth=auth)
                assert r.status_code == 404, r.text
                assert krc.write("TOOL_DATA[1]", "{Z 77}", debug=False) is None
                krc.close()
            assert ok(rest.get(f"/controllers/{other['id']}/tools/1"))["pose"]["z"] == 0
            assert ok(rest.get(f"/controllers/{kuka_other['id']}/tools/1"))["pose"]["z"] == 0
        finally:
            kvp.stop()


def test_a_binary_frame_on_a_subscription_socket_is_ignored(cell: dict) -> None:
    """A client's messages on its subscription socket are ignored; a binary one was read as
    text (Starlette's receive_text: KeyError 'text'), an unhandled error in the log that
    dropped the socket without a close frame. The socket now goes on sending values."""
    from websockets.sync.client import connect

    s = requests.Session()
    s.auth = requests.auth.HTTPDigestAuth("expert", PASSWORD["expert"])
    r = s.post(cell["url"] + "/subscription", data={
        "resources": ["1"], "1": "/rw/rapid/symbol/data/RAPID/T_ROB1/tool12;value"})
    assert r.status_code == 201, r.text
    with connect(r.headers["Location"], subprotocols=["robapi2_subscription"],
                 additional_headers={"Cookie": f"ABBCX={s.cookies['ABBCX']}"}) as ws:
        ws.send(b"\x00\x01")
        got = ""
        for k in range(50):  # edits until the socket's first look has a value to compare
            ok(edit_slot(cell["rest"], f"/controllers/{cell['cid']}/tools/12",
                         {"pose": {"z": 12.5 + k}}))
            try:
                got = ws.recv(timeout=1.0)
                break
            except TimeoutError:
                continue
        assert "[[0,0,1" in got, got  # still open, sending values


def test_the_replay_memory_does_not_grow_with_the_cnonce_a_client_chooses(cell: dict) -> None:
    """The face remembers every used (nonce, cnonce, nc) for replays, up to 100 000 of them;
    the cnonce is the client's choice, and the triple was kept as sent: a login sending
    cnonces of 3 000 characters made each entry some 3 KB (measured 3.1 KB), 300 MB at the
    limit. An entry is now a fixed-size digest of the triple."""
    import sys

    seen = cell["face"].seen
    before = set(seen._seen)
    ha1, ha2 = digest.ha1("operator", PASSWORD["operator"]), _md5("GET:" + STATE)
    for k in range(20):
        nonce, cnonce = _nonce(cell), f"{k:04d}" + "c" * 3000
        response = _md5(f"{ha1}:{nonce}:00000001:{cnonce}:auth:{ha2}")
        header = (f'Digest username="operator", realm="validusers", nonce="{nonce}", '
                  f'uri="{STATE}", response="{response}", qop=auth, nc=00000001, '
                  f'cnonce="{cnonce}"')
        r = requests.get(cell["url"] + STATE, headers={"Authorization": header})
        assert r.status_code == 200, r.text[:200]
    new = [key for key in seen._seen if key not in before]
    assert len(new) == 20
    per_entry = sum(sys.getsizeof(key) + sum(sys.getsizeof(part) for part in key)
                    if isinstance(key, tuple) else sys.getsizeof(key) for key in new) / 20
    assert per_entry < 200, f"{per_entry:.0f} bytes per remembered use"


def test_a_role_that_may_write_but_not_read_writes_through_rws_as_through_rest(
        cell: dict) -> None:
    """(Last in the file: its import replaces the module the symbols come from.)

    One permission table on every face: a site role with frames:commit and data:import but
    not frames:read may PUT a tool slot and POST an import on REST, and write BASE_DATA through
    KVP; RWS refused its set and its fileservice PUT with 403 "needs permission frames:read"
    (both read the module before writing). They now need what docs/rws.md says: frames:commit,
    data:import; the set is audited under that user, and reading stays refused."""
    from server.auth import tokens

    with cell["face"].make_session() as db:
        tokens.add_role(db, "Writer", ["frames:commit", "data:import"])
        db.commit()
    ok(cell["rest"].post("/users", json={"name": "writer", "role": "Writer"}))
    with cell["face"].make_session() as db:
        ops.set_rws_ha1(db, "writer", digest.ha1("writer", "writer-secret"))
        db.commit()
    auth = requests.auth.HTTPDigestAuth("writer", "writer-secret")
    symbol = cell["url"] + "/rw/rapid/symbol/data/RAPID/T_ROB1/tool9"
    r = requests.post(symbol + "?action=set&json=1", auth=auth,
                      data={"value": "[TRUE,[[0,0,99.5],[1,0,0,0]],[2,[0,0,40],[1,0,0,0],0,0,0]]"})
    assert r.status_code == 204, r.text[-200:]
    slot = ok(cell["rest"].get(f"/controllers/{cell['cid']}/tools/9"))
    assert (slot["pose"]["z"], slot["provenance"]["updated_by"]) == (99.5, "writer")
    assert requests.get(symbol + "?json=1", auth=auth).status_code == 403
    module = ("MODULE Cell\n  PERS tooldata gun:=[TRUE,[[0,0,100],[1,0,0,0]],"
              "[1,[0,0,50],[1,0,0,0],0,0,0]];\nENDMODULE\n")
    r = requests.put(cell["url"] + "/fileservice/$HOME/Cell.mod?json=1", data=module.encode(),
                     auth=auth)
    assert r.status_code == 201, r.text[-200:]
    assert requests.get(cell["url"] + "/fileservice/$HOME/Cell.mod", auth=auth).status_code == 403


def test_one_users_logins_do_not_push_out_another_users(monkeypatch) -> None:
    """A Digest client that sends no cookie back (curl, a script) gets a new ABBCX login with
    each request, and the face keeps SESSIONS_MAX of them, least recently used first: one
    logged-in user's requests pushed every other user's login out (their subscription sockets
    could no longer open). A user's own oldest login goes past LOGINS_PER_USER."""
    monkeypatch.setattr(rws_app, "SESSIONS_MAX", 200)
    face = RwsFace(make_session=None)  # type: ignore[arg-type]  (logins only)
    eva = face.login(None, "eva")
    flood = [face.login(None, "mallory") for _ in range(1000)]
    assert face.session_user(eva) == "eva"
    assert face.session_user(flood[-1]) == "mallory"
    assert sum(user == "mallory" for user, _ in face.sessions.values()) <= 64
    face.forget(eva)  # a logout
    assert face.session_user(eva) is None and "eva" not in face.logins
