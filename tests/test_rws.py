"""The RWS face driven by the unmodified ``abb-robot-client`` (its ``RWS`` class), as cell
software talks to an ABB controller: Digest login, tooldata through RAPID symbols, the arm's
jointtarget and robtarget, the panel, the file service and a PERS subscription; REST and the
face see each other's writes at once."""

from __future__ import annotations

import queue
import time
import subprocess
import sys
from collections.abc import Iterator

import numpy as np
import pytest
import requests
from api_helpers import edit_slot, make_client, ok
from browser_helpers import free_port

from server.rws import digest, ops
from server.rws.app import RwsFace, create_rws_app
from server.rws.service import serve_asgi
from server.service import transaction
from solvers.frames import Pose, abb_from_matrix

rws = pytest.importorskip("abb_robot_client.rws")

PASSWORD = {"expert": "expert-secret", "operator": "operator-secret"}
TOOL = "[TRUE,[[1.5,-2,180.25],[0.707106781186548,0,0,0.707106781186548]],[2.5,[0,0,60],[1,0,0,0],0.01,0.01,0.02]]"


@pytest.fixture(scope="module")
def cell(fresh_db, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """REST (TestClient) and the RWS face (uvicorn on loopback) on one database, an ABB
    controller, an Expert and an Operator with RWS secrets."""

    db_url = fresh_db()
    with make_client(db_url) as rest:
        cid = ok(rest.post("/controllers", json={"name": "abb-1", "robot": "abb_irb120"}))["id"]
        maker = rest.app.state.sessionmaker
        for name, role in (("expert", "Expert"), ("operator", "Operator")):
            ok(rest.post("/users", json={"name": name, "role": role}))
            with maker() as db:
                ops.set_rws_ha1(db, name, digest.ha1(name, PASSWORD[name]))
                db.commit()
        port = free_port()
        face = serve_asgi(create_rws_app(RwsFace(maker)), "127.0.0.1", port, "rws-test")
        try:
            yield {"rest": rest, "cid": cid, "url": f"http://127.0.0.1:{port}", "maker": maker}
        finally:
            face.stop()


def client(cell: dict, user: str = "expert", password: str | None = None) -> rws.RWS:
    return rws.RWS(cell["url"], user, password or PASSWORD[user])


def test_write_tooldata_through_rws_read_it_through_rest(cell: dict) -> None:
    """set_rapid_variable writes tool 1 (pose and load); REST shows it, with the audit's
    source rws and the Expert's name; get_rapid_variable gives the literal back."""
    c = client(cell)
    names = [s["name"] for s in c.get_rapid_variables()]
    assert "tool1" in names and "wobj1" in names
    c.set_rapid_variable("tool1", TOOL)
    slot = ok(cell["rest"].get(f"/controllers/{cell['cid']}/tools/1"))
    assert [slot["pose"][k] for k in "xyz"] == pytest.approx([1.5, -2.0, 180.25])
    assert [slot["pose"][k] for k in "abc"] == pytest.approx([90.0, 0.0, 0.0], abs=1e-9)
    assert slot["load"]["mass_kg"] == 2.5 and slot["load"]["com_mm"] == [0, 0, 60]
    assert slot["provenance"]["updated_by"] == "expert"
    audit = ok(cell["rest"].get("/audit", params={"controller_id": cell["cid"]}))
    last = [a for a in audit if a["table"] == "tool" and a["number"] == 1][-1]
    assert (last["source"], last["user"], last["action"]) == ("rws", "expert", "frame.edit")
    value = c.get_rapid_variable("tool1")
    assert value.startswith("[TRUE,[[1.5,-2,180.25],[0.70710678118654")
    assert value.endswith("[2.5,[0,0,60],[1,0,0,0],0.01,0.01,0.02]]")


def test_rest_edit_shows_in_rws_with_module_path(cell: dict) -> None:
    """A REST edit of base 2 reads back through RWS by module path, as wobjdata."""
    path = f"/controllers/{cell['cid']}/bases/2"
    ok(edit_slot(cell["rest"], path, {"name": "table", "pose": {"x": 500, "y": 10, "z": 5}}))
    c = client(cell)
    found = {s["name"]: s for s in c.get_rapid_variables()}
    assert found["table"]["dattyp"] == "wobjdata"
    assert c.get_rapid_variable("CalibData/table") == \
        '[FALSE,TRUE,"",[[500,10,5],[1,0,0,0]],[[0,0,0],[1,0,0,0]]]'


def test_operator_cannot_set_tooldata(cell: dict) -> None:
    """An Operator reads but cannot write: the RWS error shape, 403, nothing written."""
    before = ok(cell["rest"].get(f"/controllers/{cell['cid']}/tools/3"))
    c = client(cell, "operator")
    assert c.get_rapid_variable("tool3").startswith("[TRUE,")
    with pytest.raises(rws.ABBException) as err:
        c.set_rapid_variable("tool3", TOOL)
    assert "frames:commit" in str(err.value) and err.value.code < 0
    r = requests.post(f"{cell['url']}/rw/rapid/symbol/data/RAPID/T_ROB1/tool3?action=set&json=1",
                      data={"value": TOOL},
                      auth=requests.auth.HTTPDigestAuth("operator", PASSWORD["operator"]))
    assert r.status_code == 403 and "status" in r.json()["_embedded"]
    assert ok(cell["rest"].get(f"/controllers/{cell['cid']}/tools/3")) == before


def test_wrong_digest_is_401(cell: dict) -> None:
    """A wrong password: 401 with a Digest challenge, as RWS answers; the client raises."""
    with pytest.raises(rws.ABBException, match="wrong user name or password") as err:
        client(cell, "expert", "wrong").get_rapid_variable("tool1")
    assert err.value.code < 0
    r = requests.get(f"{cell['url']}/rw/panel/ctrlstate?json=1",
                     auth=requests.auth.HTTPDigestAuth("expert", "wrong"))
    assert r.status_code == 401
    assert r.headers["WWW-Authenticate"].startswith('Digest realm="validusers"')
    assert requests.get(f"{cell['url']}/rw/panel/ctrlstate?json=1").status_code == 401


def test_digest_tells_no_user_apart_and_never_answers_500(cell: dict) -> None:
    """An unknown user and a known one with a wrong password get the same 401; Digest
    parameters with non-ASCII characters (no login needed to send them) get a 401, not a 500
    with a traceback in the log."""
    def message(user: str, password: str) -> str:
        r = requests.get(f"{cell['url']}/rw/panel/ctrlstate?json=1",
                         auth=requests.auth.HTTPDigestAuth(user, password))
        assert r.status_code == 401
        return r.text

    assert message("nobody-here", "x") == message("expert", "wrong")
    r = requests.get(f"{cell['url']}/rw/panel/ctrlstate?json=1")
    nonce = r.headers["WWW-Authenticate"].split('nonce="')[1].split('"')[0]
    t = nonce.split(".")[0]
    for forged in (f'nonce="{t}.\u00e9\u00e9", response="{"0" * 32}"',
                   f'nonce="{nonce}", response="\u00e9\u00e9\u00e9", qop=auth, nc=00000001, '
                   'cnonce="abc"'):
        header = (f'Digest username="expert", realm="validusers", uri="/rw/panel/ctrlstate", '
                  + forged).encode("utf-8")
        r = requests.get(f"{cell['url']}/rw/panel/ctrlstate?json=1",
                         headers={"Authorization": header})
        assert r.status_code == 401, (forged, r.status_code, r.text[:200])


def test_jointtarget_and_robtarget_follow_a_rest_jog(cell: dict) -> None:
    """Jog A1 through REST; the jointtarget shows it and the robtarget of tool1 in wobj0 is
    the TCP REST gives for that tool in world."""
    rest, cid = cell["rest"], cell["cid"]
    ok(rest.post(f"/controllers/{cid}/robot/jog", json={"mode": "joint", "axis": "A1",
                                                       "increment": 12.5}))
    state = ok(rest.get(f"/controllers/{cid}/robot"))
    c = client(cell)
    jt = c.get_jointtarget()
    assert jt.robax == pytest.approx(state["joints_deg"], abs=1e-5)
    client(cell).set_rapid_variable("tool1", TOOL)
    ok(rest.put(f"/controllers/{cid}/robot/active", json={"tool_no": 1, "base_no": 0}))
    tcp = ok(rest.get(f"/controllers/{cid}/robot"))["tcp_pose"]
    rt = c.get_robtarget(tool="tool1", wobj="wobj0")
    assert rt.trans == pytest.approx([tcp["x"], tcp["y"], tcp["z"]], abs=1e-4)
    q = abb_from_matrix(Pose(*(tcp[k] for k in "xyzabc")).as_matrix())[1]
    assert abs(float(np.dot(rt.rot, q))) == pytest.approx(1.0, abs=1e-8)
    # in a work object: the TCP REST shows with that base active
    c.set_rapid_variable("wobj5", "[FALSE,TRUE,\"\",[[400,-50,20],[0.9659258262890683,0,0,"
                         "0.25881904510252074]],[[0,0,0],[1,0,0,0]]]")
    ok(rest.put(f"/controllers/{cid}/robot/active", json={"tool_no": 1, "base_no": 5}))
    tcp = ok(rest.get(f"/controllers/{cid}/robot"))["tcp_pose"]
    rt = c.get_robtarget(tool="tool1", wobj="wobj5", coordinate="Wobj")
    assert rt.trans == pytest.approx([tcp["x"], tcp["y"], tcp["z"]], abs=1e-4)
    with pytest.raises(rws.ABBException, match="coordinate"):
        c.get_robtarget(tool="tool1", wobj="wobj5", coordinate="Tool")


def test_panel_and_execution_states(cell: dict) -> None:
    c = client(cell)
    assert c.get_controller_state() == "motoron"
    assert c.get_operation_mode() == "MANR"
    assert c.get_execution_state().ctrlexecstate == "stopped"
    assert list(c.get_tasks()) == ["T_ROB1"]


def test_bad_input_gets_rws_errors_and_service_goes_on(cell: dict) -> None:
    """Unknown symbol, malformed literal, wrong type: the RWS error naming the field; the
    slot is untouched and the next request is served."""
    c = client(cell)
    c.set_rapid_variable("tool1", TOOL)
    with pytest.raises(rws.ABBException, match="no symbol"):
        c.get_rapid_variable("no_such_tool")
    with pytest.raises(rws.ABBException, match="value"):
        c.set_rapid_variable("tool1", "[TRUE,[[1,2],[1,0,0,0]],")
    with pytest.raises(rws.ABBException, match="quaternion"):
        c.set_rapid_variable("tool1", "[TRUE,[[1,2,3],[2,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]]")
    with pytest.raises(rws.ABBException, match="robhold"):
        c.set_rapid_variable("tool1", "[FALSE,[[1,2,3],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]]")
    with pytest.raises(rws.ABBException, match="no symbol"):
        c.set_rapid_variable("wobj1;x", "[1]")
    assert c.get_rapid_variable("tool1").startswith("[TRUE,[[1.5,-2,180.25]")


def test_rws_password_cli_stores_only_the_ha1(cell: dict, tmp_path) -> None:
    """``pendant users rws-password NAME`` reads the secret from stdin and stores its HA1."""
    db_url = cell["rest"].app.state.settings.db_url
    ok(cell["rest"].post("/users", json={"name": "cli-user", "role": "Operator"}))
    with cell["maker"]() as db:
        ops.set_rws_ha1(db, "cli-user", digest.ha1("cli-user", "first-secret"))
        db.commit()
    assert client(cell, "cli-user", "first-secret").get_operation_mode() == "MANR"
    r = subprocess.run([sys.executable, "-m", "server.cli", "users", "rws-password", "cli-user",
                        "--db", db_url], input="new-secret\n", check=False, capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert ops.rws_ha1(cell["maker"], "cli-user") == digest.ha1("cli-user", "new-secret")
    assert client(cell, "cli-user", "new-secret").get_operation_mode() == "MANR"
    with pytest.raises(rws.ABBException, match="wrong user name or password"):
        client(cell, "cli-user", "first-secret").get_operation_mode()
    r = subprocess.run([sys.executable, "-m", "server.cli", "users", "rws-password", "nobody",
                        "--db", db_url], input="x\n", check=False, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "nobody" in r.stderr


def test_file_service_reads_the_export_and_a_put_imports(cell: dict) -> None:
    """read_file gives the module as REST's export; upload_file imports it (a changed tool
    shows in REST); a module that does not parse is refused whole, and an Operator may not
    import."""
    rest, cid = cell["rest"], cell["cid"]
    c = client(cell)
    c.set_rapid_variable("tool1", TOOL)
    text = c.read_file("$HOME/CalibData.mod").decode()
    r = rest.get(f"/controllers/{cid}/export", params={"format": "abb"})
    assert r.status_code == 200 and text == r.text
    assert [f for f in c.list_files("$HOME")] == ["CalibData.mod"]
    new = text.replace("PERS tooldata tool1:=[TRUE,[[1.5,-2,180.25]",
                       "PERS tooldata tool1:=[TRUE,[[1.5,-2,181.75]")
    assert new != text
    c.upload_file("$HOME/CalibData.mod", new.encode())
    assert ok(rest.get(f"/controllers/{cid}/tools/1"))["pose"]["z"] == 181.75
    history = ok(rest.get(f"/controllers/{cid}/tools/1/history"))
    assert history[-1]["reason"] == "import"
    before = ok(rest.get(f"/controllers/{cid}/tools/1"))
    with pytest.raises(Exception, match="Bad Request"):
        c.upload_file("$HOME/CalibData.mod", new.replace("ENDMODULE", "").encode())
    r = requests.put(f"{cell['url']}/fileservice/$HOME/CalibData.mod", data=text.encode(),
                     auth=requests.auth.HTTPDigestAuth("operator", PASSWORD["operator"]))
    assert r.status_code == 403 and "data:import" in r.json()["_embedded"]["status"]["msg"]
    assert ok(rest.get(f"/controllers/{cid}/tools/1")) == before


def test_subscription_sees_a_rest_edit(cell: dict) -> None:
    """A PERS subscription (robapi2_subscription WebSocket) gets tool4's new value when
    REST edits the slot."""
    got: queue.Queue = queue.Queue()
    c = client(cell)
    sub = c.subscribe([rws.SubscriptionResourceRequest(rws.SubscriptionResourceType.PersVar,
                                                       rws.SubscriptionResourcePriority.High,
                                                       "tool4")], got.put)
    try:
        path = f"/controllers/{cell['cid']}/tools/4"
        opened = False
        for k in range(50):  # until the socket is open, every edit is a new value
            ok(edit_slot(cell["rest"], path, {"pose": {"z": 40.0 + k}}))
            try:
                opened = isinstance(got.get(timeout=1.0), rws.VariableValue)
            except queue.Empty:
                continue
            if opened:
                break
        assert opened, "no subscription event arrived"
        ok(edit_slot(cell["rest"], path, {"pose": {"z": 123.25}}))  # the edit to see
        deadline, z = time.monotonic() + 10.0, None
        while z != 123.25 and time.monotonic() < deadline:
            event = got.get(timeout=max(deadline - time.monotonic(), 0.01))
            if isinstance(event, rws.VariableValue):
                assert event.value.startswith("[TRUE,[[0,0,"), event.value
                z = float(event.value.split("[[0,0,")[1].split("]")[0])
        assert z == 123.25 == ok(cell["rest"].get(path))["pose"]["z"]
    finally:
        sub.close()


def test_another_sites_form_and_a_foreign_host_are_refused(cell: dict) -> None:
    """A browser that keeps Digest credentials for the robot's address sends them with any
    page's form: a command with another site's Origin is refused (403) and writes nothing, as
    on REST; a client that sends no Origin (requests, RobotStudio) is served. With the
    service's host names (pendant serve passes them), a foreign Host is refused (400)."""
    from starlette.testclient import TestClient

    url = f"{cell['url']}/rw/rapid/symbol/data/RAPID/T_ROB1/tool4?action=set&json=1"
    auth = requests.auth.HTTPDigestAuth("expert", PASSWORD["expert"])
    before = ok(cell["rest"].get(f"/controllers/{cell['cid']}/tools/4"))
    r = requests.post(url, data={"value": TOOL}, auth=auth,
                      headers={"Origin": "http://evil.example"})
    assert r.status_code == 403, r.text
    assert ok(cell["rest"].get(f"/controllers/{cell['cid']}/tools/4")) == before
    assert requests.post(url, data={"value": TOOL}, auth=auth).status_code == 204
    app = create_rws_app(RwsFace(cell["maker"]), ("localhost", "127.0.0.1"))
    with TestClient(app, base_url="http://evil.example") as foreign:
        assert foreign.get("/rw/panel/ctrlstate?json=1").status_code == 400
    with TestClient(app, base_url="http://127.0.0.1:8610") as own:
        assert own.get("/rw/panel/ctrlstate?json=1").status_code == 401  # served: log in


def test_a_chunked_body_is_refused_once_it_passes_the_limit(cell: dict) -> None:
    """A chunked body (no Content-Length) is refused with 413 as soon as it passes 64 KiB:
    the face does not wait for it, nor keep it, whole (200 MiB took 300 MB of memory)."""
    import hashlib
    import socket

    def md5(text: str) -> str:
        return hashlib.md5(text.encode()).hexdigest()  # noqa: S324 -- HTTP Digest is MD5

    uri = "/rw/rapid/symbol/data/RAPID/T_ROB1/tool1?action=set"
    challenge = requests.get(f"{cell['url']}{uri}").headers["WWW-Authenticate"]
    nonce = challenge.split('nonce="')[1].split('"')[0]
    ha1 = md5(f"expert:validusers:{PASSWORD['expert']}")
    response = md5(f"{ha1}:{nonce}:00000001:c0ffee:auth:{md5('POST:' + uri)}")
    host, port = cell["url"].removeprefix("http://").split(":")
    with socket.create_connection((host, int(port)), timeout=10) as s:
        s.sendall((f"POST {uri} HTTP/1.1\r\nHost: {host}\r\nTransfer-Encoding: chunked\r\n"
                   "Content-Type: application/x-www-form-urlencoded\r\n"
                   f'Authorization: Digest username="expert", realm="validusers", '
                   f'nonce="{nonce}", uri="{uri}", qop=auth, nc=00000001, cnonce="c0ffee", '
                   f'response="{response}"\r\n\r\n').encode())
        chunk = b"a" * 16384
        for _ in range(6):  # 96 KiB, and the body never ends
            s.sendall(b"%x\r\n" % len(chunk) + chunk + b"\r\n")
        head = s.recv(4096)
    assert head.startswith(b"HTTP/1.1 413"), head[:200]


def test_oversize_and_stalled_requests_do_not_stall_the_face(cell: dict) -> None:
    """A body beyond 64 KiB is refused in RWS's error shape; a client that sends half a
    request holds up no one else."""
    auth = requests.auth.HTTPDigestAuth("expert", PASSWORD["expert"])
    r = requests.post(f"{cell['url']}/rw/rapid/symbol/data/RAPID/T_ROB1/tool1?action=set&json=1",
                      data={"value": "[" * 70000}, auth=auth)
    assert r.status_code == 413 and r.json()["_embedded"]["status"]["code"] < 0
    host, port = cell["url"].removeprefix("http://").split(":")
    import socket

    with socket.create_connection((host, int(port)), timeout=10) as half:
        half.sendall(b"POST /rw/rapid/symbol/data/RAPID/T_ROB1/tool1?action=set HTTP/1.1\r\n"
                     b"Host: x\r\nContent-Length: 100\r\n\r\nvalue=")
        assert client(cell).get_operation_mode() == "MANR"


def _subscribe(tc, auth) -> str:  # noqa: ANN001
    """POST /subscription of tool4's value as abb-robot-client sends it; the socket's number."""
    r = tc.post("/subscription", auth=auth, data={
        "resources": ["1"], "1": "/rw/rapid/symbol/data/RAPID/T_ROB1/tool4;value", "1-p": "1"})
    assert r.status_code == 201, r.text
    return r.headers["Location"].rsplit("/", 1)[1]


def _socket_headers(tc, **extra: str) -> dict[str, str]:  # noqa: ANN001
    """A browser's handshake to the face: its Host and the login's ABBCX cookie (Starlette's
    test client sends neither on a WebSocket by itself)."""
    return {"Host": "127.0.0.1:8610", "Cookie": f"ABBCX={tc.cookies['ABBCX']}", **extra}


def test_another_sites_page_cannot_open_a_subscription_socket(cell: dict) -> None:
    """A browser opens any site's WebSocket with the robot's cookies (the ABBCX login) and lets
    that page read what comes: a socket opened with another site's Origin, or to a Host not
    served, is refused before it opens; from the face's own page it opens."""
    import httpx
    from starlette.testclient import TestClient
    from starlette.websockets import WebSocketDisconnect

    app = create_rws_app(RwsFace(cell["maker"]), ("127.0.0.1",))
    auth = httpx.DigestAuth("expert", PASSWORD["expert"])
    proto = ["robapi2_subscription"]
    with TestClient(app, base_url="http://127.0.0.1:8610") as tc:
        n = _subscribe(tc, auth)  # the login's ABBCX cookie is kept by the client
        for origin in ("http://evil.example", "null"):
            with pytest.raises(WebSocketDisconnect) as refused:
                with tc.websocket_connect(f"/poll/{n}", subprotocols=proto,
                                          headers=_socket_headers(tc, Origin=origin)):
                    pass
            assert refused.value.code == 1008
        with pytest.raises(WebSocketDisconnect):
            with tc.websocket_connect(f"/poll/{n}", subprotocols=proto,
                                      headers=_socket_headers(tc, Host="evil.example")):
                pass
        with tc.websocket_connect(f"/poll/{n}", subprotocols=proto, headers=_socket_headers(
                tc, Origin="http://127.0.0.1:8610")) as ws:
            assert ws.accepted_subprotocol == "robapi2_subscription"
            with pytest.raises(WebSocketDisconnect):  # one socket per subscription
                with tc.websocket_connect(f"/poll/{n}", subprotocols=proto,
                                          headers=_socket_headers(tc)):
                    pass


def test_subscriptions_never_opened_do_not_pile_up(cell: dict, monkeypatch) -> None:
    """A client that subscribes and never opens the socket: a user holds a bounded number of
    subscriptions (429 past it, naming the limit), and one not opened in time is dropped."""
    import httpx
    from starlette.testclient import TestClient

    from server.rws import app as rws_app

    monkeypatch.setattr(rws_app, "SUBS_PER_USER", 3)
    face = RwsFace(cell["maker"])
    auth = httpx.DigestAuth("expert", PASSWORD["expert"])
    with TestClient(create_rws_app(face), base_url="http://127.0.0.1:8610") as tc:
        for _ in range(3):
            _subscribe(tc, auth)
        r = tc.post("/subscription?json=1", auth=auth, data={
            "resources": ["1"], "1": "/rw/rapid/symbol/data/RAPID/T_ROB1/tool4;value"})
        assert r.status_code == 429 and "at most 3" in r.text, r.text
        assert len(face.subscriptions) == 3
        monkeypatch.setattr(rws_app, "SUB_OPEN_WITHIN_S", 0.0)  # the three are now too old
        _subscribe(tc, auth)
        assert len(face.subscriptions) == 1


def test_a_login_cookie_unused_too_long_opens_no_socket(cell: dict, monkeypatch) -> None:
    """The ABBCX cookie of a login is forgotten once unused for SESSION_IDLE_S: a copy of it
    opens no subscription socket afterwards (it worked for as long as the service ran)."""
    import httpx
    from starlette.testclient import TestClient
    from starlette.websockets import WebSocketDisconnect

    from server.rws import app as rws_app

    auth = httpx.DigestAuth("expert", PASSWORD["expert"])
    with TestClient(create_rws_app(RwsFace(cell["maker"])), base_url="http://127.0.0.1:8610") as tc:
        r = tc.post("/subscription", auth=auth, data={
            "resources": ["1"], "1": "/rw/rapid/symbol/data/RAPID/T_ROB1/tool4;value"})
        assert r.status_code == 201 and "max-age=1800" in r.headers["set-cookie"].lower()
        n = r.headers["Location"].rsplit("/", 1)[1]
        with tc.websocket_connect(f"/poll/{n}", subprotocols=["robapi2_subscription"],
                                  headers=_socket_headers(tc)) as ws:
            assert ws.accepted_subprotocol == "robapi2_subscription"  # the login is live
        n = _subscribe(tc, auth)
        monkeypatch.setattr(rws_app, "SESSION_IDLE_S", -1.0)  # every login now unused too long
        with pytest.raises(WebSocketDisconnect) as refused:
            with tc.websocket_connect(f"/poll/{n}", subprotocols=["robapi2_subscription"],
                                      headers=_socket_headers(tc)):
                pass
        assert refused.value.code == 1008


def test_a_subscription_number_of_thousands_of_digits_is_refused(cell: dict) -> None:
    """``/poll/<5000 digits>`` (no login needed to send it) closes the socket as an unknown
    subscription does; it was a 500 (Python's int() refusing the string)."""
    from starlette.testclient import TestClient
    from starlette.websockets import WebSocketDisconnect

    with TestClient(create_rws_app(RwsFace(cell["maker"])), base_url="http://127.0.0.1:8610") as tc:
        for path in ("/poll/" + "1" * 5000, "/poll/\u0663", "/poll/-1"):
            with pytest.raises(WebSocketDisconnect) as refused:
                with tc.websocket_connect(path, headers={"Host": "127.0.0.1:8610"}):
                    pass
            assert refused.value.code == 1008, path


def test_a_busy_database_is_a_503_to_retry_in_rws_shape(cell: dict, monkeypatch) -> None:
    """Another writer holds the database past the writers' wait: the RAPID write answers 503
    with Retry-After and an RWS status naming the reason (it was a 500 with a traceback in the
    log), nothing is written, and the same write goes through once the database is free."""
    maker = cell["maker"]
    if maker.kw["bind"].dialect.name != "sqlite":
        pytest.skip("SQLite's writers' turn held; PostgreSQL locks the controller's row")
    monkeypatch.setattr(transaction, "TURN_TIMEOUT_S", 0.3)
    url = f"{cell['url']}/rw/rapid/symbol/data/RAPID/T_ROB1/tool5?action=set&json=1"
    auth = requests.auth.HTTPDigestAuth("expert", PASSWORD["expert"])
    before = ok(cell["rest"].get(f"/controllers/{cell['cid']}/tools/5"))
    holder = transaction.writer(maker)
    with holder, transaction.writers_turn(holder):  # the other writer's turn
        r = requests.post(url, data={"value": TOOL}, auth=auth)
    assert r.status_code == 503 and r.headers["Retry-After"] == "1", r.text
    status = r.json()["_embedded"]["status"]
    assert status["code"] < 0 and "locked by another writer" in status["msg"]
    assert ok(cell["rest"].get(f"/controllers/{cell['cid']}/tools/5")) == before
    assert requests.post(url, data={"value": TOOL}, auth=auth).status_code == 204
