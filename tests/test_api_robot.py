"""Robot menu: joints, jogs in every coordinate system, approach, controllers with other arms."""

from __future__ import annotations

import numpy as np
import pytest

from api_helpers import C, CELL, edit_slot, ok, pose_array
from solvers.robots import ROBOTS


def test_demo_controller_and_openapi_tags(client):
    ctl = ok(client.get("/controllers"))
    assert [(c["name"], c["robot"]) for c in ctl] == [("cell-1", "kuka_kr6_r900_sixx")]
    tags = {t for path in client.get("/openapi.json").json()["paths"].values() for op in path.values()
            for t in op.get("tags", [])}
    assert {"Robot", "Tool", "Base", "Fixed tool", "Workpiece", "Sessions", "Export"} <= tags
    assert client.get("/").status_code == 200


def test_joint_jog_and_set_joints(client):
    s = ok(client.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A1", "increment": 5}))
    assert s["joints_deg"][0] == pytest.approx(5.0)
    s = ok(client.put(f"{C}/robot/joints", json={"joints_deg": [10, -80, 100, 5, 60, 30]}))
    assert s["joints_deg"] == pytest.approx([10, -80, 100, 5, 60, 30])


@pytest.mark.parametrize("mode,axis,expect", [("world", "Z", [0, 0, 5.0]), ("world", "X", [5.0, 0, 0])])
def test_world_jog_moves_the_flange_along_world_axes(client, mode, axis, expect):
    from api_helpers import angle_deg, pose_matrix
    before = pose_matrix(ok(client.get(f"{C}/robot"))["tcp_pose"])
    after = pose_matrix(ok(client.post(f"{C}/robot/jog", json={"mode": mode, "axis": axis, "increment": 5}))["tcp_pose"])
    assert after[:3, 3] - before[:3, 3] == pytest.approx(expect, abs=1e-4)
    assert angle_deg(after[:3, :3], before[:3, :3]) < 1e-5


def test_tool_jog_moves_along_the_active_tool_axis(client):
    ok(edit_slot(client, f"{C}/tools/2", {"name": "long", "pose": {"z": 200, "b": 30}}))
    ok(client.put(f"{C}/robot/active", json={"tool_no": 2}))
    s0 = ok(client.get(f"{C}/robot"))
    s1 = ok(client.post(f"{C}/robot/jog", json={"mode": "tool", "axis": "Z", "increment": 4}))
    from api_helpers import pose_matrix
    T0 = pose_matrix(s0["tcp_pose"])
    d = pose_array(s1["tcp_pose"])[:3] - T0[:3, 3]
    assert d == pytest.approx(4.0 * T0[:3, 2], abs=1e-4)
    s2 = ok(client.post(f"{C}/robot/jog", json={"mode": "tool", "axis": "A", "increment": 10}))
    assert pose_array(s2["tcp_pose"])[:3] == pytest.approx(pose_array(s1["tcp_pose"])[:3], abs=1e-4)


def test_approach_puts_the_true_tip_on_the_target(client):
    from solvers.dh import forward_kinematics
    s = ok(client.post(f"{C}/robot/approach", json={"target": "reference_tip", "tilt_deg": 30, "around_deg": 45,
                                                    "noise_mm": 0}))  # the ideal aim
    T = forward_kinematics(ROBOTS["kuka_kr6_r900_sixx"], s["joints_deg"], CELL.T_flange_tool)
    assert T[:3, 3] == pytest.approx(CELL.reference_tip_mm, abs=1e-6)
    assert np.degrees(np.arccos(-T[2, 2])) == pytest.approx(30.0, abs=1e-6)


def test_cell_shows_what_a_person_knows_not_the_truth(client):
    cell = ok(client.get(f"{C}/cell"))
    assert "reference_tip" in cell["targets"] and cell["base_points_mm"]["x"] == [200.0, 0.0, 0.0]
    assert "T_flange_tool" not in str(cell)


def test_other_library_arm_and_custom_dh(client):
    c = ok(client.post("/controllers", json={"name": "abb", "robot": "abb_irb120"}))
    assert c["robot_name"] == "ABB IRB 120"
    from api_helpers import calibrate
    report, slot = calibrate(client, "tool.xyz_4point", 1, controller=f"/controllers/{c['id']}")
    assert report["max_error_mm"] < 1e-3
    kr = ROBOTS["kuka_kr6_r900_sixx"]
    joints = [{"a_mm": j.a_mm, "alpha_deg": j.alpha_deg, "d_mm": j.d_mm, "offset_deg": j.offset_deg,
               "direction": j.direction, "q_min_deg": j.q_min_deg, "q_max_deg": j.q_max_deg} for j in kr.joints]
    custom = ok(client.post("/controllers", json={"name": "custom", "robot": None, "custom_robot": {
        "name": "my arm", "dh_convention": "standard", "joints": joints, "reach_mm": 901}}))
    assert custom["robot"] is None and custom["robot_name"] == "my arm" and custom["dof"] == 6
    r = client.post("/controllers", json={"name": "custom", "robot": "ur5e"})
    assert r.status_code == 409
    r = client.post("/controllers", json={"name": "x", "robot": "r2d2"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "robot"]
    assert client.delete(f"/controllers/{custom['id']}").status_code == 204


def test_placeholder_page_without_web_dir(tmp_path):
    from fastapi.testclient import TestClient

    from api_helpers import app_settings

    from server.api.app import create_app
    app = create_app(app_settings(f"sqlite:///{tmp_path / 'p.db'}", web_dir=tmp_path / "no-web"))
    with TestClient(app) as c:
        r = c.get("/")
        assert r.status_code == 200 and "/docs" in r.text
