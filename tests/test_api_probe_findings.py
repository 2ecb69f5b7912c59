"""The smaller findings of issue 9's probe, each kept as a regression test."""

from __future__ import annotations

import json

import pytest

from api_helpers import C, ok, open_session


def test_backup_nested_1000_deep_is_422(client):
    for depth in (1000, 100_000):
        text = "[" * depth + "]" * depth
        r = client.post(f"{C}/import", json={"format": "json", "text": text})
        assert r.status_code == 422, r.text
        assert r.json()["detail"][0]["loc"] == ["body", "text"]
        assert "nested too deep" in r.json()["detail"][0]["msg"]
    text = '{"format": "pendant-backup/1", "x": ' + "{" * 1000 + "}" * 1000 + "}"
    assert client.post(f"{C}/import", json={"format": "json", "text": text}).status_code == 422


JOINT = {"a_mm": 0.0, "alpha_deg": 90.0, "d_mm": 400.0}


def test_custom_robot_nested_500_deep_is_422(client):
    body = {"name": "deep", "custom_robot": {"dh_convention": "standard", "joints": [JOINT]}}
    for where in ("custom_robot", "joints"):
        text = json.dumps(body)
        nested = "[" * 500 + "]" * 500
        if where == "joints":
            text = text.replace('"joints": [', f'"joints": [{nested}, ')
        else:
            text = text.replace('"custom_robot": {', f'"custom_robot": {{"extra": {nested}, ')
        r = client.post("/controllers", content=text, headers={"content-type": "application/json"})
        assert r.status_code == 422, r.text


def test_custom_joint_with_lower_limit_above_180_deg(client):
    """A joint whose whole range lies beyond 180 deg: the controller is made, HOME inside."""
    joints = [dict(JOINT, q_min_deg=190.0, q_max_deg=300.0)] + [JOINT] * 5
    body = {"name": "wrapped", "custom_robot": {"dh_convention": "standard", "joints": joints}}
    c = ok(client.post("/controllers", json=body))
    assert 190.0 <= c["joints_deg"][0] <= 300.0


@pytest.mark.parametrize("method,path,allow", [
    ("POST", f"{C}/tools/1", "GET, HEAD, PUT"),
    ("PATCH", C, "DELETE, GET, HEAD"),
    ("DELETE", "/controllers", "GET, HEAD, POST"),
    ("PUT", f"{C}/sessions/1/save", "POST"),
])
def test_allow_header_on_405_names_every_method(client, method, path, allow):
    r = client.request(method, path)
    assert r.status_code == 405
    assert r.headers["allow"] == allow
    assert r.json()["detail"][0]["msg"].endswith(f"it has {allow}")


@pytest.mark.parametrize("body", [
    {"method": "tool.xyz_4point", "target_no": True},
    {"method": "base.3point", "target_no": 1, "params": {"tool_no": True}},
])
def test_booleans_are_no_slot_numbers(client, body):
    r = client.post(f"{C}/sessions", json=body)
    assert r.status_code == 422
    assert r.json()["detail"][0]["type"] == "int_type"


def test_booleans_are_no_active_tool_or_step(client):
    r = client.put(f"{C}/robot/active", json={"tool_no": True})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "tool_no"]
    assert ok(client.get(f"{C}/robot"))["active_tool_no"] == 0
    s = open_session(client, "tool.xyz_4point", 1)
    assert client.post(f"{s}/touch-up", json={"step": False}).status_code == 422


def test_openapi_documents_401_403_404_409(client):
    paths = client.get("/openapi.json").json()["paths"]
    save = paths["/controllers/{controller_id}/sessions/{session_id}/save"]["post"]["responses"]
    assert {"200", "401", "403", "404", "409", "422"} <= set(save)
    assert save["404"]["content"]["application/json"]["schema"]["$ref"] == \
        "#/components/schemas/Error"
    listing = paths["/controllers"]["get"]["responses"]
    assert {"401", "403"} <= set(listing) and "404" not in listing and "409" not in listing
    assert "401" not in paths["/auth/login"]["post"]["responses"]
    assert "403" not in paths["/auth/me"]["get"]["responses"]


# ------------------------------------------------------------- issue 21: round three's probe

def _user(client, name: str, role: str) -> dict[str, str]:
    """A user with ``role``; the headers of a fresh token of theirs."""
    ok(client.post("/users", json={"name": name, "role": role}))
    return {"Authorization": "Bearer " + ok(client.post(f"/users/{name}/tokens", json={}))["token"]}


JOG = {"mode": "joint", "axis": "A1", "increment": 0.5}


def test_idempotency_keys_belong_to_their_user(client):
    """Item 3: an Operator replaying an Expert's keyed jog got the Expert's stored answer; now
    the Operator's request is one of its own (an Operator may jog: it runs again)."""
    expert, operator = _user(client, "eve", "Expert"), _user(client, "otto", "Operator")
    a1 = ok(client.get(f"{C}/robot"))["joints_deg"][0]
    key = {"Idempotency-Key": "jog-by-eve-1"}
    first = client.post(f"{C}/robot/jog", json=JOG, headers={**expert, **key})
    assert first.status_code == 200
    again = client.post(f"{C}/robot/jog", json=JOG, headers={**expert, **key})
    assert again.content == first.content  # the Expert's own replay
    theirs = client.post(f"{C}/robot/jog", json=JOG, headers={**operator, **key})
    assert theirs.status_code == 200 and theirs.content != first.content
    assert ok(client.get(f"{C}/robot"))["joints_deg"][0] - a1 == pytest.approx(1.0)
    # and a replay of the Operator's is the Operator's
    assert client.post(f"{C}/robot/jog", json=JOG,
                       headers={**operator, **key}).content == theirs.content


def test_token_creation_refuses_an_idempotency_key_and_stores_no_secret(client, db_url):
    """Item 3: the new token was stored in plain text with the keyed answer (24 h), and another
    Administrator replaying the key got the same working token."""
    from sqlalchemy import create_engine, text

    ok(client.post("/users", json={"name": "olga", "role": "Operator"}))
    before = len(ok(client.get("/audit")))
    r = client.post("/users/olga/tokens", json={}, headers={"Idempotency-Key": "tok-1"})
    assert r.status_code == 400, r.text
    assert r.json()["detail"][0]["loc"] == ["header", "Idempotency-Key"]
    assert "secret" in r.json()["detail"][0]["msg"]
    assert "pdt_" not in r.text
    assert [a["action"] for a in ok(client.get("/audit"))[before:]] == []  # no token made
    engine = create_engine(db_url)
    try:
        with engine.connect() as conn:
            bodies = [bytes(b or b"") for b in conn.execute(text(
                "SELECT body FROM idempotency_key")).scalars()]
    finally:
        engine.dispose()
    assert not any(b"pdt_" in b for b in bodies)
    assert client.post("/users/olga/tokens", json={}).status_code == 201  # without the key


def _field_refused(r, *loc) -> None:
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"][:len(loc) + 1] == ["body", *loc], r.text


def test_out_of_range_clock_is_422_and_a_touch_up_never_stores_it(client):
    """Item 4: PUT cell/clock 1e308 answered 200; a touch-up then stored t_s = 1e308 and the
    controller's own backup no longer restored."""
    for bad in (1e308, 1e10, -1.0):
        _field_refused(client.put(f"{C}/cell/clock", json={"clock_s": bad},
                                  headers={"If-Match": "*"}), "clock_s")
    assert ok(client.get(f"{C}/cell/clock"))["clock_s"] < 1e9
    ok(client.put(f"{C}/cell/clock", json={"clock_s": 1e9}, headers={"If-Match": "*"}))
    s = open_session(client, "tool.xyz_4point", 1)
    ok(client.post(f"{s}/touch-up"))
    text = client.get(f"{C}/export", params={"format": "json"}).text
    job = client.post(f"{C}/import", json={"format": "json", "text": text, "dry_run": True})
    assert job.status_code == 200, job.text  # the backup checks: it restores


def test_plan_recording_joints_and_plan_workspace_in_range(client):
    """Item 4: /plan/recording stored joints of +-1e308; /plan took a workspace of -1e308."""
    poses = [[0.0, -90.0, 90.0, 0.0, 90.0, 0.0]] * 4
    bad = [p[:] for p in poses]
    bad[2][1] = 1e308
    _field_refused(client.post("/plan/recording", json={"robot": "ur10", "joints_deg": bad}),
                   "joints_deg", 2, 1)
    bad[2][1] = 400.0  # a number, but outside ur10's joint 2 limits
    r = client.post("/plan/recording", json={"robot": "ur10", "joints_deg": bad})
    _field_refused(r, "joints_deg", 2, 1)
    assert "joint 2" in r.json()["detail"][0]["msg"]
    short = [p[:5] for p in poses]
    _field_refused(client.post("/plan/recording", json={"robot": "ur10", "joints_deg": short}),
                   "joints_deg", 0)
    ws = [-1e308, -500.0, 0.0, 800.0, 500.0, 900.0]
    _field_refused(client.post("/plan", json={"robot": "ur10", "effects": ["joint_offset"],
                                              "workspace": ws}), "workspace", 0)


def test_clock_and_webhooks_are_audited(client):
    """Item 5: PUT cell/clock and POST /webhooks left no audit record."""
    ok(client.put(f"{C}/cell/clock", json={"clock_s": 3600.0}, headers={"If-Match": "*"}))
    hook = client.post("/webhooks", json={"url": "http://127.0.0.1:9/hook",
                                          "secret": "s" * 20})
    assert hook.status_code == 201
    assert client.delete(f"/webhooks/{hook.json()['id']}").status_code == 204
    records = ok(client.get("/audit"))
    clock = [r for r in records if r["action"] == "emulator.clock"]
    assert len(clock) == 1 and clock[0]["after"] == {"clock_s": 3600.0}
    assert clock[0]["controller_id"] == 1 and clock[0]["user"] == "admin"
    made = [r for r in records if r["action"] == "webhook.create"]
    assert len(made) == 1 and made[0]["after"]["url"] == "http://127.0.0.1:9/hook"
    assert "s" * 20 not in json.dumps(records)  # never the signing secret
    assert [r["action"] for r in records].count("webhook.delete") == 1
    r = client.post("/webhooks", json={"url": "http://127.0.0.1:9/x"},
                    headers={"Idempotency-Key": "hook-1"})
    assert r.status_code == 400  # its answer holds the secret: never stored


def test_audit_filters_by_extkin(client):
    """Item 5: records name the table extkin, and ?table=extkin gave 422."""
    r = client.get("/audit", params={"table": "extkin"})
    assert r.status_code == 200, r.text
    assert client.get("/audit", params={"table": "nonsense"}).status_code == 422


def test_two_500s_are_404_and_422(client):
    """Item 6."""
    anonymous = type(client)(client.app, raise_server_exceptions=False)
    assert anonymous.get("/index.html%00.js").status_code == 404
    assert anonymous.get("/pendant.js%00").status_code == 404
    r = client.get("/audit", params={"controller_id": 1180591620717411303424})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "controller_id"]


def test_a_session_state_filter_that_no_session_can_have_is_422(client):
    """Item 9: ?state=junk answered [] (a typo looked like "no sessions")."""
    open_session(client, "tool.xyz_4point", 1)
    assert len(ok(client.get(f"{C}/sessions", params={"state": "open"}))) == 1
    r = client.get(f"{C}/sessions", params={"state": "junk"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "state"]


def test_sqlite_out_of_memory_in_a_job_is_the_memory_limit():
    """Item 9: a job whose process hit a low --job-memory-mb while SQLite opened the database
    failed as a 500 ``worker``; it is the memory limit (413), as a MemoryError is."""
    import sqlite3

    from sqlalchemy.exc import OperationalError

    from server.jobs.worker import _error_of, out_of_memory

    wrapped = OperationalError("PRAGMA journal_mode=WAL", {}, sqlite3.OperationalError(
        "out of memory"))
    assert out_of_memory(wrapped) and out_of_memory(MemoryError())
    assert _error_of(wrapped)["status"] == 413
    assert _error_of(wrapped)["detail"][0]["type"] == "memory_limit"
    locked = OperationalError("BEGIN", {}, sqlite3.OperationalError("database is locked"))
    assert not out_of_memory(locked) and _error_of(locked)["status"] == 500


def test_an_unknown_slot_kind_filter_is_422_naming_it(client):
    """Item 9: ``?kind=nonsense`` answered ``[]``; a filter no slot can match is a mistake."""
    r = client.get(f"{C}/tools", params={"kind": "nonsense"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"][-1] == "kind", r.text
    assert client.get(f"{C}/tools", params={"kind": "tool"}).status_code == 200
