"""Analysis building blocks: the twist columns, the rigid baselines of each kind, the held-out
RMS, identifiability, and the errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from server.formats.recording import parse_recording
from solvers.analysis import analyze, render_text
from solvers.analysis.baseline import fit_baseline, rms_mm
from solvers.analysis.kinematics import sensitivities
from solvers.dh import forward_kinematics
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.physics import Imperfections
from solvers.robots import ROBOTS
from solvers.simulate import simulate_recording

TOOL = Pose(x=5.0, y=-3.0, z=140.0, a=10.0, b=5.0).as_matrix()


@pytest.mark.parametrize("key", ["kuka_kr6_r900_sixx", "tm5_900", "ur10"])
def test_twist_columns_match_finite_differences(key: str, rng) -> None:
    """Each DH parameter's twist column equals the FK change it causes (both conventions)."""
    robot = ROBOTS[key]
    q = rng.uniform(-60, 60, (4, robot.dof))
    s = sensitivities(robot, q, TOOL)
    h = 1e-6
    for j in range(robot.dof):
        for name, field, scale in (("theta", "offset_deg", np.degrees(h)), ("a", "a_mm", h),
                                   ("d", "d_mm", h), ("alpha", "alpha_deg", np.degrees(h))):
            jnt = robot.joints[j]
            up = robot.with_joint(j, **{field: getattr(jnt, field) + scale})
            dn = robot.with_joint(j, **{field: getattr(jnt, field) - scale})
            Tu, Td = forward_kinematics(up, q, TOOL), forward_kinematics(dn, q, TOOL)
            dc = (Tu[:, :3, 3] - Td[:, :3, 3]) / (2 * h)
            dw = Rotation.from_matrix(Tu[:, :3, :3] @ np.swapaxes(Td[:, :3, :3], 1, 2)).as_rotvec() / (2 * h)
            col = getattr(s, name)[:, :, j]
            assert np.allclose(col[:, :3], dc, atol=1e-4), (key, name, j)
            assert np.allclose(col[:, 3:], dw, atol=1e-7), (key, name, j)


@pytest.mark.parametrize("kind, n", [("tracker", 30), ("touch", 12), ("beam", 48)])
def test_rigid_recording_baseline_recovers_the_truth(kind: str, n: int) -> None:
    doc = simulate_recording(kind, "tm5_900", Imperfections(noise_mm=0.005), n, seed=4,
                             tool_mm=Pose(x=1.0, y=-2.0, z=150.0))
    rec = parse_recording(doc)
    base = fit_baseline(rec)
    p = base.parameters
    assert (p["tcp_x_mm"], p["tcp_y_mm"]) == (pytest.approx(1.0, abs=0.05), pytest.approx(-2.0, abs=0.05))
    if kind != "beam":
        assert p["tcp_z_mm"] == pytest.approx(150.0, abs=0.05)
    if kind == "tracker":
        assert (p["instrument_x_mm"], p["instrument_a_deg"]) == (pytest.approx(2500.0, abs=0.5),
                                                                 pytest.approx(160.0, abs=0.01))
    if kind == "beam":
        assert p["runout_deg"] < 0.05
    assert rms_mm(base.g, base.m) < 0.03
    rep = analyze(rec)
    assert rep["verdict"] == "no_missing_physics" and rep["findings"] == []
    assert rep["baseline"]["heldout_rms_mm"] >= rep["baseline"]["rms_mm"]
    assert "none" in render_text(rep)


def test_absorbed_effects_are_reported_not_identifiable_with_what_would_reveal_them() -> None:
    doc = simulate_recording("tracker", "ur10", Imperfections(noise_mm=0.01), 30, seed=2,
                             tool_mm=Pose(x=30.0, z=150.0))
    rep = analyze(parse_recording(doc))
    ni = {(e["effect"], e["joint"], e.get("dh_parameter")) for e in rep["not_identifiable"]}
    # J1's zero and d1 move every pose rigidly: the instrument frame absorbs them
    assert ("joint_offset", 1, None) in ni and ("link_length", 1, "d") in ni
    # the last joint's zero turns the TCP about its own axis: absorbed by the TCP
    assert ("joint_offset", 6, None) in ni
    reason = next(e["reason"] for e in rep["not_identifiable"] if e["effect"] == "joint_offset" and e["joint"] == 6)
    assert "absorbed by the TCP:" in reason
    reason = next(e["reason"] for e in rep["not_identifiable"] if e["effect"] == "joint_offset" and e["joint"] == 1)
    assert "absorbed by the instrument frame:" in reason


def test_effect_that_cannot_move_the_tcp_is_invisible_not_a_finding() -> None:
    """The TCP on joint 6's axis: its backlash or zero cannot move the measured point; no
    regressor made of fitting noise may become a finding."""
    doc = simulate_recording("tracker", "ur5e", Imperfections(noise_mm=0.05), 100, seed=8053,
                             payload=(2.0, [0, 0, 40]))
    rep = analyze(parse_recording(doc))
    assert rep["findings"] == [] and rep["verdict"] == "no_missing_physics"
    invisible = {(e["effect"], e["joint"]) for e in rep["not_identifiable"] if "invisible" in e["reason"]}
    assert ("backlash", 6) in invisible and ("joint_offset", 6) in invisible


def test_static_time_effect_with_one_time_is_not_offered() -> None:
    """All samples at one time: a thermal drift cannot be seen (a static growth looks like
    link lengths); the analysis does not offer it."""
    doc = simulate_recording("tracker", "ur5e", Imperfections(noise_mm=0.01), 20, seed=3)
    for s in doc["samples"]:
        s["t_s"] = 0.0
    rep = analyze(parse_recording(doc))
    assert rep["verdict"] == "no_missing_physics"


def test_too_few_samples_raise_naming_the_field() -> None:
    from dataclasses import replace
    doc = simulate_recording("tracker", "ur10", Imperfections(noise_mm=0.01), 5, seed=1)
    rec = parse_recording(doc)
    short = replace(rec, t_s=rec.t_s[:3], joints_deg=rec.joints_deg[:3],
                    measured_mm=rec.measured_mm[:3])
    with pytest.raises(CalibrationError) as err:
        analyze(short)
    assert err.value.loc == ("samples",) and "at least 4" in err.value.reason


def test_a_four_point_touch_recording_is_analysed() -> None:
    """A 4-point tool session's recording (docs/api.md's example) is analysed, not refused:
    leave-one-out still leaves 9 rows for the 6 baseline parameters."""
    doc = simulate_recording("touch", "kuka_kr6_r900_sixx", Imperfections(noise_mm=0.05), 4, seed=1)
    rep = analyze(parse_recording(doc))
    assert rep["n_samples"] == 4 and rep["verdict"] == "no_missing_physics"
    assert rep["baseline"]["heldout_rms_mm"] >= rep["baseline"]["rms_mm"] > 0


@pytest.mark.parametrize("kind, n", [("tracker", 20), ("touch", 12), ("beam", 36)])
def test_exact_data_one_effect_one_finding(kind: str, n: int) -> None:
    """Without noise the offset comes out exactly and rounding never becomes a finding."""
    imp = Imperfections(joint_offset_deg=(0, 0, 0.02, 0, 0, 0))
    rep = analyze(parse_recording(simulate_recording(kind, "kuka_kr6_r900_sixx", imp, n, seed=1)))
    assert [(f["effect"], f["joint"]) for f in rep["findings"]] == [("joint_offset", 3)]
    assert rep["findings"][0]["parameters"]["offset_deg"] == pytest.approx(0.02, abs=1e-8)
    assert rep["verdict"] == "explained" and rep["final"]["rms_mm"] < 1e-6


def test_tip_constraint_is_the_plane_through_the_beam_line() -> None:
    """A tip descent tilted towards the beam direction: a TCP anywhere on the beam line meets
    the tip condition, wherever the sensor block puts the beam's reference point."""
    from solvers.analysis.baseline import _beam_constraint

    b = np.array([[600.0, 0.0, 200.0]])
    v = np.array([[1.0, 0.0, 0.0]])
    w = np.array([[np.sin(np.radians(10.0)), 0.0, -np.cos(np.radians(10.0))]])  # tilted descent
    u = np.array([[0.0, 0.0, -1.0]])
    for along_mm in (0.0, 50.0, -120.0):
        c = b + along_mm * v
        g = _beam_constraint(c, u, b, v, w, np.array([2]), 3.0)
        assert abs(g[0]) < 1e-12, (along_mm, g)
    # and 1 mm off the line, across the beam in the descent's own plane, it is 1 mm off
    c = b + np.array([[0.0, 0.0, 1.0]])
    assert abs(_beam_constraint(c, u, b, v, w, np.array([2]), 3.0)[0]) == pytest.approx(1.0)
