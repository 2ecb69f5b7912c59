"""The smaller findings of issue 9's probe, each kept as a regression test."""

from __future__ import annotations

import json

import pytest

from api_helpers import *  # noqa: F403
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
