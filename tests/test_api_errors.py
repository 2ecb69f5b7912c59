"""Bad input is refused with a 422 naming the field and the reason; nothing taught is lost."""

from __future__ import annotations

import json

from api_helpers import C, approach, edit_slot, ok, open_session, walk


def _detail(r):  # noqa: ANN001, ANN202
    assert r.status_code == 422, r.text
    return r.json()["detail"][0]


def test_nan_joints_are_named(client):
    body = '{"joints_deg": [0, NaN, 90, 0, 90, 0]}'
    d = _detail(client.put(f"{C}/robot/joints", content=body, headers={"content-type": "application/json"}))
    assert d["loc"][:2] == ["body", "joints_deg"]
    url = open_session(client, "tool.xyz_4point", 1)
    d = _detail(client.post(f"{url}/touch-up", content='{"joints_deg": [0, 0, Infinity, 0, 0, 0]}',
                            headers={"content-type": "application/json"}))
    assert d["loc"][:2] == ["body", "joints_deg"]
    d = _detail(client.post(f"{url}/touch-up", json={"joints_deg": [0, -90, 90, 0, 125, 0]}))
    assert d["loc"] == ["body", "joints_deg", 4] and "A5 (joint 5)" in d["msg"]  # as the page names it
    assert ok(client.get(url))["steps"][0]["filled"] is False


def test_unknown_field_is_rejected(client):
    d = _detail(client.post(f"{C}/sessions", json={"method": "tool.xyz_4point", "target_no": 1, "colour": "red"}))
    assert d["loc"] == ["body", "colour"]
    d = _detail(client.post(f"{C}/robot/approach", json={"target": "reference_tip", "tilt": 30}))
    assert d["loc"] == ["body", "tilt"]


def test_unknown_method_and_wrong_joint_count(client):
    d = _detail(client.post(f"{C}/sessions", json={"method": "tool.magic", "target_no": 1}))
    assert d["loc"] == ["body", "method"]
    d = _detail(client.put(f"{C}/robot/joints", json={"joints_deg": [0, 0, 0]}))
    assert d["loc"] == ["body", "joints_deg"] and "6 joints" in d["msg"]


def test_joint_limit_names_joint_value_and_limit(client):
    d = _detail(client.put(f"{C}/robot/joints", json={"joints_deg": [0, -90, 90, 0, 130, 0]}))
    assert d["loc"] == ["body", "joints_deg", 4]
    assert "joint 5" in d["msg"] and "130" in d["msg"] and "120" in d["msg"]
    ok(client.put(f"{C}/robot/joints", json={"joints_deg": [0, -90, 90, 0, 119, 0]}))
    d = _detail(client.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A5", "increment": 2}))
    assert "joint 5" in d["msg"] and "121" in d["msg"]
    assert ok(client.get(f"{C}/robot"))["joints_deg"][4] == 119  # the refused jog did not move


def test_cartesian_jog_names_the_joint_at_its_limit(client):
    ok(client.put(f"{C}/robot/joints", json={"joints_deg": [0, -90, 90, 0, 119.5, 0]}))
    d = _detail(client.post(f"{C}/robot/jog", json={"mode": "world", "axis": "Z", "increment": 20}))
    assert d["loc"] == ["body", "joints_deg", 4] and "A5 (joint 5)" in d["msg"]  # as the page names it and "120" in d["msg"]
    ok(client.put(f"{C}/robot/joints", json={"joints_deg": [0, -90, 90, 0, 90, 0]}))
    for _ in range(4):  # out to the edge of the workspace
        r = client.post(f"{C}/robot/jog", json={"mode": "world", "axis": "X", "increment": 100})
    d = _detail(r)
    assert d["loc"][:2] == ["body", "increment"] or d["loc"][:2] == ["body", "joints_deg"]


def test_unreachable_target_and_unknown_target(client):
    d = _detail(client.post(f"{C}/robot/approach", json={"target": "moon"}))
    assert d["loc"] == ["body", "target"] and "reference_tip" in d["msg"]


def test_degenerate_compute_keeps_the_points(client):
    """Three base points on one line: 422 naming the point; all three stay taught."""
    from api_helpers import calibrate
    calibrate(client, "tool.xyz_4point", 1)
    url = open_session(client, "base.3point", 2, tool_no=1)
    for target in ("base_origin", "base_origin", "base_x"):
        approach(client, target)
        ok(client.post(f"{url}/touch-up"))
    d = _detail(client.post(f"{url}/compute"))
    assert d["loc"][0] == "body" and d["msg"]
    s = ok(client.get(url))
    assert s["state"] == "open" and all(st["filled"] for st in s["steps"])
    approach(client, "base_xy")  # re-teach step 2 and compute again
    ok(client.post(f"{url}/touch-up", json={"step": 1}))
    approach(client, "base_x")
    ok(client.post(f"{url}/touch-up", json={"step": 1}))
    approach(client, "base_xy")
    ok(client.post(f"{url}/touch-up", json={"step": 2}))
    ok(client.post(f"{url}/compute"))


def test_missing_step_is_named(client):
    url = open_session(client, "tool.abc_2point", 1)
    ok(client.post(f"{url}/touch-up", json={"step": 2}))
    d = _detail(client.post(f"{url}/compute"))
    assert d["loc"] == ["body", "points", 0] and "not taught" in d["msg"]


def test_state_errors_are_409_and_404(client):
    url = open_session(client, "tool.xyz_4point", 1)
    r = client.post(f"{url}/save")
    assert r.status_code == 409 and "compute" in r.json()["detail"][0]["msg"]
    ok(client.post(f"{url}/discard"))
    assert client.post(f"{url}/touch-up").status_code == 409
    r = client.get(f"{C}/sessions/999")
    assert r.status_code == 404 and r.json()["detail"][0]["loc"] == ["path", "session_id"]
    assert client.get("/controllers/42/tools/1").status_code == 404
    r = client.get(f"{C}/tools/17")  # a KUKA-kind controller has 16 tools: the answer says so
    assert r.status_code == 404 and r.json()["detail"][0]["loc"] == ["path", "number"]
    assert "numbered 1..16, got 17" in r.json()["detail"][0]["msg"]
    abb = ok(client.post("/controllers", json={"name": "irb", "robot": "abb_irb120"}))
    r = client.get(f"/controllers/{abb['id']}/tools/40")  # an ABB table grows with an import
    assert r.status_code == 404 and "an import" in r.json()["detail"][0]["msg"]


def test_flange_pose_touch_up_and_both_inputs_refused(client):
    url = open_session(client, "tool.abc_world_6d", 1)
    s = ok(client.post(f"{url}/touch-up", json={"flange_pose": {"x": 500, "y": 0, "z": 400, "a": 0, "b": 180, "c": 0}}))
    assert s["steps"][0]["point"]["source"] == "flange_pose"
    d = _detail(client.post(f"{url}/touch-up", json={"joints_deg": [0, -90, 90, 0, 90, 0],
                                                      "flange_pose": {"x": 1}}))
    assert d["loc"] == ["body", "flange_pose"]


def test_no_500_with_a_stack_trace_on_garbage(client):
    for r in (client.post(f"{C}/sessions", content=b"\xff\xfe", headers={"content-type": "application/json"}),
              client.post(f"{C}/import", json={"format": "kuka", "text": "DECL E6POS nonsense = {X abc}"}),
              client.post(f"{C}/import", json={"format": "json", "text": "{"})):
        assert r.status_code == 422, r.text
        assert "Traceback" not in r.text
        json.loads(r.text)["detail"][0]["msg"]


def test_walk_refuses_a_step_beyond_the_menu(client):
    ok(client.put(f"{C}/tools/1", json={"pose": {"x": 0, "y": 0, "z": 150, "a": 0, "b": 0, "c": 0}}, headers={"If-Match": "*"}))
    url = open_session(client, "base.3point", 2, tool_no=1)
    walk(client, url)
    r = client.post(f"{url}/touch-up")
    assert r.status_code == 409 and "all 3 steps" in r.json()["detail"][0]["msg"]
    d = _detail(client.post(f"{url}/touch-up", json={"step": 3}))
    assert d["loc"] == ["body", "step"]


def test_slot_kind_must_fit_its_table(client):
    d = _detail(edit_slot(client, f"{C}/tools/1", {"kind": "fixed_tool"}))
    assert d["loc"] == ["body", "kind"] and "tool or workpiece" in d["msg"]
    assert ok(edit_slot(client, f"{C}/tools/1", {"kind": "workpiece"}))["kind"] == "workpiece"
