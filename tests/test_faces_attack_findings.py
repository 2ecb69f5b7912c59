"""Findings of an attacker's probe of the RWS and KVP faces, each a reproduction that failed on
the code before its fix: the faces started as tests/test_rws.py and tests/test_kvp.py start
them (uvicorn / asyncio on loopback, REST on the same database), driven by raw requests and by
the unmodified clients (abb-robot-client, py-openshowvar) where they can say it."""

from __future__ import annotations

import hashlib
import queue
import time
from collections.abc import Iterator

import pytest
import requests
from api_helpers import edit_slot, make_client, ok, wait_for
from browser_helpers import free_port

from server.rws import digest, ops
from server.rws.app import RwsFace, create_rws_app
from server.rws.service import serve_asgi

rws = pytest.importorskip("abb_robot_client.rws")

PASSWORD = {"expert": "expert-secret", "operator": "operator-secret", "leaver": "leaver-secret"}
STATE = "/rw/panel/ctrlstate?json=1"


@pytest.fixture(scope="module")
def cell(fresh_db) -> Iterator[dict]:
    """REST and the RWS face on one database: an ABB controller, users with RWS secrets."""
    with make_client(fresh_db()) as rest:
        cid = ok(rest.post("/controllers", json={"name": "abb-1", "robot": "abb_irb120"}))["id"]
        maker = rest.app.state.sessionmaker
        for name, role in (("expert", "Expert"), ("operator", "Operator"),
                           ("leaver", "Expert")):
            ok(rest.post("/users", json={"name": name, "role": role}))
            with maker() as db:
                ops.set_rws_ha1(db, name, digest.ha1(name, PASSWORD[name]))
                db.commit()
        port = free_port()
        face = RwsFace(maker)
        running = serve_asgi(create_rws_app(face), "127.0.0.1", port, "rws-attack")
        try:
            yield {"rest": rest, "cid": cid, "url": f"http://127.0.0.1:{port}", "face": face}
        finally:
            running.stop()


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
        time.sleep(0.6)  # the socket's first look (every 0.2 s) has the value to compare
        ok(edit_slot(cell["rest"], path, {"pose": {"z": 10.0}}))
        assert isinstance(got.get(timeout=5.0), rws.VariableValue), "the socket sends"
        assert cell["rest"].delete("/users/leaver").status_code == 204
        time.sleep(0.6)  # the socket's next look (every 0.2 s)
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
