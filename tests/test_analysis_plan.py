"""``pendant plan``: D-optimal poses within the limits, in the box, above the floor, better
than random poses of the same pool; the API, the CLI, and a recording started from a plan."""

from __future__ import annotations

import json

import numpy as np
import pytest
from api_helpers import analyze, ok

from server.cli.main import main
from solvers.analysis.plan import (Workspace, _criterion, design_matrices, parse_effects,
                                   plan_poses, tracker_pool)
from solvers.dh import forward_kinematics
from solvers.errors import CalibrationError
from solvers.robots import ROBOTS

UR10 = ROBOTS["ur10"]
EFFECTS = parse_effects(["joint_compliance:2,joint_compliance:3,link_length:2,joint_offset:3"], 6)
PAYLOAD = (5.0, (0.0, 0.0, 50.0))


@pytest.fixture(scope="module")
def plan():
    return plan_poses(UR10, EFFECTS, 20, payload=PAYLOAD, seed=2, n_pool=600)


def test_plan_poses_are_reachable_in_the_box_and_above_the_floor(plan) -> None:
    q = np.array(plan["joints_deg"])
    lim = UR10.limits_deg()
    assert q.shape == (20, 6) and np.all(q >= lim[:, 0]) and np.all(q <= lim[:, 1])
    p = forward_kinematics(UR10, q)[:, :3, 3]
    ws = Workspace.default(UR10)
    assert np.all(p >= ws.lo) and np.all(p <= ws.hi) and np.all(p[:, 2] > ws.floor_mm)
    np.testing.assert_allclose(p, plan["tcp_mm"], atol=1e-3)
    # joint 1's zero moves every point rigidly: the tracker frame absorbs it
    assert "joint_offset_j1" not in plan["parameters"]
    assert set(plan["parameters"]) >= {"joint_compliance_j2", "joint_compliance_j3"}


def test_planned_poses_beat_random_poses_of_the_same_pool(plan) -> None:
    """Higher D_s criterion and lower predicted standard deviations than every one of 10
    random draws of 20 poses from the same pool."""
    pool = tracker_pool(UR10, np.eye(4), Workspace.default(UR10), 600, np.random.default_rng(2))
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = pool[rng.choice(len(pool), 20, replace=False)]
        B, E, keys, m, _ = design_matrices(UR10, q, np.eye(4), "tracker", PAYLOAD, EFFECTS)
        E = E[:, [keys.index(k) for k in plan["parameters"]]]
        X = np.hstack([B, E])
        assert _criterion(X.T @ X, B.T @ B) < plan["criterion"]
        from solvers.analysis.plan import parameter_std
        std = parameter_std(B, E, plan["noise_mm"])
        planned = np.array([plan["predicted_std"][k] for k in plan["parameters"]])
        assert np.exp(np.mean(np.log(planned))) < np.exp(np.mean(np.log(std)))


def test_touch_plan_touches_one_point() -> None:
    plan = plan_poses(UR10, EFFECTS, 12, instrument="touch", payload=PAYLOAD, seed=1, n_pool=300)
    p = forward_kinematics(UR10, np.array(plan["joints_deg"]))[:, :3, 3]
    ws = Workspace.default(UR10)
    np.testing.assert_allclose(p, np.tile(0.5 * (ws.lo + ws.hi), (12, 1)), atol=1e-3)


@pytest.mark.parametrize("call, loc", [
    (lambda: parse_effects(["backlash:2"], 6), ("effects", "backlash:2")),
    (lambda: parse_effects(["joint_offset:9"], 6), ("effects", "joint_offset:9")),
    (lambda: Workspace.parse("1,2,3", UR10), ("workspace",)),
    (lambda: plan_poses(UR10, EFFECTS, 3), ("n",)),
    (lambda: plan_poses(UR10, EFFECTS, 10, instrument="camera"), ("instrument",)),
    (lambda: plan_poses(UR10, EFFECTS, 10, workspace=Workspace.parse(
        "5000,5000,0,5100,5100,100", UR10)), ("workspace",)),
])
def test_bad_input_names_the_field(call, loc) -> None:
    with pytest.raises(CalibrationError) as err:
        call()
    assert err.value.loc == loc


def test_api_plan_then_record_then_analyse(client) -> None:  # noqa: F811
    plan = ok(client.post("/plan", json={"robot": "ur10", "effects": ["joint_compliance:2"],
                                         "n": 24, "payload_kg": 5.0, "seed": 1}))
    assert plan["format"] == "pose-plan/1" and len(plan["joints_deg"]) == 24
    physics = {"compliance_deg_per_Nm": [0, 1e-3, 0, 0, 0, 0], "noise_mm": 0.02, "rigid": False}
    rec = ok(client.post("/plan/recording", json={"robot": "ur10", "joints_deg": plan["joints_deg"],
                                                   "physics": physics, "payload_kg": 5.0}))
    rep = analyze(client, rec["id"])  # the analysis is a job: queued, run, its report read
    assert rep["findings"][0]["effect"] == "joint_compliance" and rep["findings"][0]["joint"] == 2
    bad = {"robot": "ur10", "joints_deg": plan["joints_deg"], "physics": {"noise_mm": "lots"}}
    r = client.post("/plan/recording", json=bad)
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "physics", "noise_mm"]
    r = client.post("/plan", json={"robot": "ur10", "effects": ["thermal_drift"]})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "effects", "thermal_drift"]
    r = client.post("/plan", json={"robot": "r2d2", "effects": ["joint_offset"]})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "robot"]


def test_cli_plan_writes_a_plan_and_a_recording(tmp_path, capsys) -> None:
    out, rec = tmp_path / "plan.json", tmp_path / "rec.json"
    assert main(["plan", "ur10", "--effects", "joint_compliance:2", "--n", "20", "--payload", "5",
                 "-o", str(out), "--record", str(rec), "--effect", "compliance:2=0.001"]) == 0
    assert len(json.loads(out.read_text())["joints_deg"]) == 20
    assert json.loads(rec.read_text())["format"] == "robot-recording/1"
    capsys.readouterr()
    assert main(["analyze", str(rec), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert (rep["findings"][0]["effect"], rep["findings"][0]["joint"]) == ("joint_compliance", 2)
