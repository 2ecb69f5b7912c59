"""Tool > Light barrier through HTTP: the measuring cycle on the emulated robot and sensor, or a
posted beam recording; then compute and save like any other menu."""

from __future__ import annotations

import json

import numpy as np
import pytest

from api_helpers import C, CELL, TRUE_TCP_MM, ok, open_session, pose_matrix
from server.cli.main import main
from solvers.dh import forward_kinematics
from solvers.robots import ROBOTS

NOMINAL = {"x": 0.0, "y": 0.0, "z": 180.0}  # the drawing's length of the pointer


def test_light_barrier_cycle_finds_tcp_and_axis(client):
    url = open_session(client, "tool.light_barrier", 6, nominal_tool=NOMINAL)
    run = ok(client.post(f"{url}/run-cycle"))
    assert run["triggers"] >= 9 and run["passes"] == 9
    edges = {st["point"]["edge"] for st in run["session"]["steps"]}
    assert edges == {"enter", "leave", "tip"}
    report = ok(client.post(f"{url}/compute"))
    assert report["max_error_mm"] < 1e-3
    assert report["extras"]["runout_deg"] == pytest.approx(
        np.degrees(np.arccos(CELL.T_flange_tool[2, 2])), abs=1e-3)
    slot = ok(client.post(f"{url}/save"))
    T = pose_matrix(slot["pose"])
    assert T[:3, 3] == pytest.approx(TRUE_TCP_MM, abs=1e-3)
    assert float(T[:3, 2] @ CELL.T_flange_tool[:3, 2]) == pytest.approx(1.0, abs=1e-9)


def test_light_barrier_needs_a_nominal_tool(client):
    url = open_session(client, "tool.light_barrier", 6)
    r = client.post(f"{url}/run-cycle")
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "params", "nominal_tool"]


def beam_recording(client) -> dict:
    """A real controller's cycle: the triggers of the emulated run, written as robot-recording/1
    (joints by IK of each trigger's flange pose)."""
    first = open_session(client, "tool.light_barrier", 6, nominal_tool=NOMINAL)
    steps = ok(client.post(f"{first}/run-cycle"))["session"]["steps"]
    robot = ROBOTS["kuka_kr6_r900_sixx"]
    samples = []
    from emulator import solve_ik
    q = np.array(ok(client.get(f"{C}/robot"))["joints_deg"])
    for k, st in enumerate(steps):
        T = pose_matrix(st["point"]["flange_pose"])
        q = solve_ik(robot, T, q, tool=None)
        samples.append({"t_s": float(k), "joints_deg": q.tolist(), "beam": st["point"]["beam_id"],
                        "edge": st["point"]["edge"], "tcp_velocity_mm_s": st["point"]["velocity_mm_s"]})
    cell = ok(client.get(f"{C}/cell"))
    joints = [{"a_mm": j.a_mm, "alpha_deg": j.alpha_deg, "d_mm": j.d_mm, "offset_deg": j.offset_deg,
               "direction": j.direction} for j in robot.joints]
    assert forward_kinematics(robot, samples[0]["joints_deg"]) == pytest.approx(
        pose_matrix(steps[0]["point"]["flange_pose"]), abs=1e-6)
    return {"format": "robot-recording/1", "kind": "beam",
            "robot": {"model": robot.name, "dh_convention": "standard", "joints": joints},
            "tool": {"x": 0, "y": 0, "z": 180, "a": 0, "b": 0, "c": 0},
            "sensor": {"beams": cell["beams"], "tool_diameter_mm": cell["tool_diameter_mm"]},
            "samples": samples}


def test_light_barrier_from_a_posted_beam_recording(client):
    doc = beam_recording(client)
    url = open_session(client, "tool.light_barrier", 7)
    s = ok(client.post(f"{url}/beam-recording", json=doc))
    assert len(s["steps"]) == len(doc["samples"])
    report = ok(client.post(f"{url}/compute"))
    assert pose_matrix(report["frame"])[:3, 3] == pytest.approx(TRUE_TCP_MM, abs=1e-3)
    assert "diameter_mismatch" not in {w["code"] for w in report["warnings"]}
    assert report["sigma_source"] == "residual" and report["dof"] == len(doc["samples"]) - 5
    assert report["extras"]["paper_runout_deg"] == report["extras"]["runout_deg"]


def test_light_barrier_wrong_diameter_is_flagged_on_the_api(client):
    """The recording says 6.2 mm for the 6.0 mm shaft: compute names tool_diameter_mm."""
    doc = beam_recording(client)
    doc["sensor"]["tool_diameter_mm"] = 6.2
    url = open_session(client, "tool.light_barrier", 7)
    ok(client.post(f"{url}/beam-recording", json=doc))
    report = ok(client.post(f"{url}/compute"))
    (w,) = [w for w in report["warnings"] if w["code"] == "diameter_mismatch"]
    assert w["loc"] == ["tool_diameter_mm"] and "6.000 mm shaft" in w["message"]
    assert report["extras"]["diameter_measured_mm"] == pytest.approx(6.0, abs=1e-3)


def test_light_barrier_wrong_diameter_is_flagged_on_the_cli(client, tmp_path, capsys):
    """pendant calibrate tool.light_barrier with the triggers as flange poses and 6.2 mm."""
    steps = ok(client.post(f"{open_session(client, 'tool.light_barrier', 6, nominal_tool=NOMINAL)}"
                           "/run-cycle"))["session"]["steps"]
    cell = ok(client.get(f"{C}/cell"))
    points = [{"flange_pose": st["point"]["flange_pose"], "beam": st["point"]["beam_id"],
               "edge": st["point"]["edge"], "velocity_mm_s": st["point"]["velocity_mm_s"]}
              for st in steps]
    f = tmp_path / "beam.json"
    for diameter, flagged in ((cell["tool_diameter_mm"], False), (6.2, True)):
        f.write_text(json.dumps({"points": points, "inputs": {"beams": cell["beams"],
                                                              "tool_diameter_mm": diameter}}))
        assert main(["calibrate", "tool.light_barrier", str(f), "--json"]) == 0
        report = json.loads(capsys.readouterr().out)
        assert ("diameter_mismatch" in {w["code"] for w in report["warnings"]}) == flagged


def test_light_barrier_refuses_a_touch_recording(client):
    url = open_session(client, "tool.light_barrier", 7)
    doc = {"format": "robot-recording/1", "kind": "beam", "robot": {"model": "x", "dh_convention": "standard",
           "joints": [{"a_mm": 0, "alpha_deg": 0, "d_mm": 0, "offset_deg": 0}]}, "samples": []}
    r = client.post(f"{url}/beam-recording", json=doc)
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"][0] == "body"
