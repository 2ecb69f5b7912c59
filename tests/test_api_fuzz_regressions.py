"""Regressions of what fuzzing the API found (schemathesis on the OpenAPI schema, and by hand):
each request once answered 500 or stored something a later read choked on. Now each is a 4xx
naming the field, and the controller stays readable.
"""

from __future__ import annotations

import json

import pytest
from api_helpers import C, calibrate, edit_slot, finish_job, ok, open_session, restore_slot, walk

HUGE_ID = 10**20  # beyond SQLite's 64-bit INTEGER


def assert_named(r, status: int, *loc) -> str:  # noqa: ANN001
    """The response is ``status`` with the first error at ``loc``; returns its message."""
    assert r.status_code == status, r.text
    item = r.json()["detail"][0]
    assert tuple(item["loc"][:len(loc)]) == loc, item
    assert item["msg"]
    return item["msg"]


# ------------------------------------------------------------------------ ids out of range

@pytest.mark.parametrize("url, loc", [
    (f"/controllers/{HUGE_ID}", "controller_id"),
    (f"/controllers/{HUGE_ID}/robot", "controller_id"),
    (f"/controllers/{HUGE_ID}/cell/clock", "controller_id"),
    (f"/controllers/{HUGE_ID}/sessions", "controller_id"),
    (f"/controllers/{HUGE_ID}/tools/1", "controller_id"),
    (f"{C}/sessions/{HUGE_ID}", "session_id"),
    (f"/recordings/{HUGE_ID}", "recording_id"),
    (f"/analysis/{HUGE_ID}", "analysis_id"),
])
def test_id_beyond_64_bit_is_not_found(client, url, loc):  # noqa: ANN001
    assert_named(client.get(url), 404, "path", loc)


def test_restore_of_a_huge_history_id_is_not_found(client):  # noqa: ANN001
    assert_named(restore_slot(client, f"{C}/tools/1", HUGE_ID), 404, "path", "history_id")


def test_touch_up_and_analyze_with_huge_ids_are_not_found(client):  # noqa: ANN001
    assert_named(client.post(f"/controllers/{HUGE_ID}/sessions/1/touch-up"), 404, "path")
    assert_named(client.post(f"/recordings/{HUGE_ID}/analyze"), 404, "path", "recording_id")


# ------------------------------------------------------------------------------ controllers

def test_controller_without_any_robot_names_robot(client):  # noqa: ANN001
    r = client.post("/controllers", json={"name": "x", "robot": None, "custom_robot": None})
    assert_named(r, 422, "body", "robot")


def test_cell_seed_beyond_64_bit_is_refused(client):  # noqa: ANN001
    assert_named(client.post("/controllers", json={"name": "x", "cell_seed": 2**63}), 422,
                 "body", "cell_seed")


def _custom(**joint) -> dict:
    row = {"a_mm": 100.0, "alpha_deg": 90.0, "d_mm": 0.0, **joint}
    return {"name": "c", "custom_robot": {"dh_convention": "standard", "joints": [row] * 6}}


def test_custom_robot_with_inverted_joint_limits_names_the_joint(client):  # noqa: ANN001
    r = client.post("/controllers", json=_custom(q_min_deg=10.0, q_max_deg=-10.0))
    msg = assert_named(r, 422, "body", "custom_robot", "joints", 0)
    assert "q_min_deg" in msg


def test_custom_robot_with_huge_dh_values_names_the_field(client):  # noqa: ANN001
    r = client.post("/controllers", json=_custom(a_mm=1e308))
    assert_named(r, 422, "body", "custom_robot", "joints", 0, "a_mm")
    body = _custom()
    body["custom_robot"]["base_pose"] = {"x": 1e308}
    assert_named(client.post("/controllers", json=body), 422,
                 "body", "custom_robot", "base_pose", "x")
    assert [c["name"] for c in ok(client.get("/controllers"))] == ["cell-1"]


# --------------------------------------------------------------------------- huge numbers

def test_physics_with_huge_values_is_refused_and_approach_still_works(client):  # noqa: ANN001
    r = client.put(f"{C}/cell/physics", json={"joint_offset_deg": [1e308] * 6})
    assert_named(r, 422, "body", "joint_offset_deg", 0)
    assert ok(client.get(f"{C}/cell/physics"))["rigid"]
    ok(client.post(f"{C}/robot/approach", json={"target": "reference_tip"}))


@pytest.mark.parametrize("body, loc", [
    ({"pose": {"x": 1e308}}, ("pose", "x")),
    ({"pose": {"a": 1e20}}, ("pose", "a")),
    ({"load": {"mass_kg": 1e308}}, ("load", "mass_kg")),
    ({"load": {"mass_kg": 1.0, "com_mm": [1e308, 0.0, 0.0]}}, ("load", "com_mm", 0)),
])
def test_slot_with_huge_numbers_is_refused(client, body, loc):  # noqa: ANN001
    assert_named(edit_slot(client, f"{C}/tools/1", body), 422, "body", *loc)
    assert ok(client.get(f"{C}/tools/1"))["pose"]["x"] == 0.0
    assert "1.0E+308" not in client.get(f"{C}/export?format=kuka").text


def test_touch_up_of_a_huge_flange_pose_is_refused(client):  # noqa: ANN001
    url = open_session(client, "tool.xyz_4point")
    r = client.post(f"{url}/touch-up", json={"flange_pose": {"x": 1e308, "y": 1e308}})
    assert_named(r, 422, "body", "flange_pose", "x")
    assert not ok(client.get(url))["steps"][0]["filled"]


def test_approach_with_huge_angles_is_refused(client):  # noqa: ANN001
    r = client.post(f"{C}/robot/approach", json={"target": "reference_tip", "around_deg": 1e308})
    assert_named(r, 422, "body", "around_deg")


# ------------------------------------------------------------------------------ analysis

def _beam_recording(client) -> dict:  # noqa: ANN001
    calibrate(client, "tool.xyz_4point", 1)
    url = open_session(client, "tool.light_barrier", 1)
    ok(client.post(f"{url}/run-cycle"))
    return ok(client.get(f"{url}/recording"))


def test_analyze_with_a_negative_seed_names_the_seed(client):  # noqa: ANN001
    url = open_session(client, "tool.xyz_4point")
    walk(client, url, extra=4)
    rid = ok(client.post("/recordings", json=ok(client.get(f"{url}/recording"))))["id"]
    assert_named(client.post(f"/recordings/{rid}/analyze?seed=-1"), 422, "query", "seed")
    assert client.post(f"/recordings/{rid}/analyze?seed=7").status_code == 202


def test_recording_with_a_huge_velocity_is_refused_naming_the_sample(client):  # noqa: ANN001
    doc = _beam_recording(client)
    doc["samples"][0]["tcp_velocity_mm_s"] = [20.0, 1e308, 0.0]
    msg = assert_named(client.post("/recordings", json=doc), 422,
                       "body", "samples", 0, "tcp_velocity_mm_s")
    assert "range" in msg
    s = ok(client.post(f"{C}/sessions", json={"method": "tool.light_barrier", "target_no": 2}))
    r = client.post(f"{C}/sessions/{s['id']}/beam-recording", json=doc)
    assert_named(r, 422, "body", "samples", 0, "tcp_velocity_mm_s")


# ------------------------------------------------------------------ JSON backup (import)

@pytest.fixture
def backup(client) -> dict:  # noqa: ANN001
    calibrate(client, "tool.xyz_4point", 1)
    walk(client, open_session(client, "tool.xyz_4point", 2))  # an open session with points
    return json.loads(client.get(f"{C}/export?format=json").text)


def _import(client, doc: dict | None = None, text: str | None = None):  # noqa: ANN001, ANN202
    return client.post(f"{C}/import", json={"format": "json", "text": text or json.dumps(doc)})


def _still_readable(client, n_sessions: int = 2) -> None:  # noqa: ANN001
    """Every read of the controller works and the sessions are the ones before the import."""
    assert len(ok(client.get(f"{C}/sessions"))) == n_sessions
    for url in ("/tools", "/bases", "/robot", "/export?format=kuka", "/export?format=json",
                "/tools/1/history"):
        assert client.get(C + url).status_code == 200, url


@pytest.mark.parametrize("change, loc", [
    (lambda d: d["sessions"][0].update(method="tool.magic"), ("sessions", 0, "method")),
    (lambda d: d["sessions"][0].update(target_table="zzz"), ("sessions", 0, "target_table")),
    (lambda d: d["sessions"][0].update(target_no=10**30), ("sessions", 0)),
    (lambda d: d["sessions"][0]["report"].update(sigma_mm="x"), ("sessions", 0, "report")),
    (lambda d: d["sessions"][0]["report"].update(residuals_mm=None), ("sessions", 0, "report")),
    (lambda d: d["sessions"][0].update(params={"tool_no": 99}), ("sessions", 0, "params")),
    (lambda d: d["sessions"][1]["points"][1].update(step=0), ("sessions", 1)),
    (lambda d: d["sessions"][1]["points"][0].update(joints_deg=["x"]),
     ("sessions", 1, "points", 0, "joints_deg", 0)),
    (lambda d: d["sessions"][1]["points"][0].update(source=10**30),
     ("sessions", 1, "points", 0, "source")),
    (lambda d: d["sessions"][1].update(id=10**30), ("sessions", 1, "id")),
    (lambda d: d["entries"][0].update(kind="fixed_tool"), ("entries", 0)),
    (lambda d: d["entries"][0].update(x_mm=None), ("entries", 0, "x_mm")),
    (lambda d: d["entries"][0].update(name=10**30), ("entries", 0, "name")),
    (lambda d: d["history"][0]["before"].update(b_deg="x"), ("history", 0, "before", "b_deg")),
    (lambda d: d["controller"].update(joints_deg=[0.0, 0.0]), ("controller", "joints_deg")),
    (lambda d: d.update(zz=1), ("zz",)),
])
def test_malformed_backup_is_refused_and_changes_nothing(client, backup, change, loc):  # noqa: ANN001
    change(backup)
    msg = assert_named(_import(client, backup), 422, "body", "text", *loc)
    assert "Error" not in msg  # a reason, not an exception's name
    _still_readable(client)


def test_backup_with_nan_is_refused(client, backup):  # noqa: ANN001
    text = json.dumps(backup).replace('"x_mm": 0.0', '"x_mm": NaN', 1)
    assert_named(_import(client, text=text), 422, "body", "text")
    _still_readable(client)


def test_valid_backup_still_round_trips(client, backup):  # noqa: ANN001
    job = finish_job(client, _import(client, backup))
    assert job["state"] == "done" and job["result"]["entries"] == 48, job
    _still_readable(client)
    after = json.loads(client.get(f"{C}/export?format=json").text)

    def entries(doc: dict) -> list[dict]:
        """The slots with each provenance session named by its method and target, not its id:
        a restore renumbers sessions (PostgreSQL never reuses an id; SQLite may)."""
        by_id = {sd["id"]: (sd["method"], sd["target_table"], sd["target_no"])
                 for sd in doc["sessions"]}
        return [{**e, "session_id": by_id.get(e["session_id"])} for e in doc["entries"]]

    assert entries(after) == entries(backup)


# ----------------------------------------------------------------- the framework's errors

def test_body_that_is_not_utf8_json_is_a_named_422(client):  # noqa: ANN001
    r = client.post(f"{C}/robot/jog", content=b"\x1bb\x12W}oQ\xff\xfe",
                    headers={"content-type": "application/json"})
    assert_named(r, 422, "body")


def test_unknown_route_and_method_have_the_house_shape(client):  # noqa: ANN001
    r = client.put(f"{C}/sessions/1/compute")
    assert "PUT" in assert_named(r, 405)
    assert "allow" in {k.lower() for k in r.headers}
    assert_named(client.get("/controllers/1/nothing-here"), 404, "path")


# ------------------------------------------------------------------- too few known points

@pytest.mark.parametrize("method, params", [
    ("base.indirect", {"tool_no": 1}), ("workpiece.indirect", {"fixed_tool_no": 1})])
def test_indirect_menu_with_three_known_points_is_refused_at_open(client, method, params):  # noqa: ANN001
    known = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0], [0.0, 100.0, 0.0]]  # the solvers need 4
    r = client.post(f"{C}/sessions", json={"method": method, "target_no": 2,
                                           "params": {**params, "known_points_mm": known}})
    assert_named(r, 422, "body", "params", "known_points_mm")
    assert ok(client.get(f"{C}/sessions")) == []
