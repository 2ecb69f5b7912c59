"""Simulated recordings: valid documents for every kind and arm, exact without imperfections,
and each imperfection where the physics module says it is."""

from __future__ import annotations

import numpy as np
import pytest

from server.formats.recording import parse_recording
from solvers.dh import forward_kinematics
from solvers.errors import CalibrationError
from solvers.frames import Pose, apply
from solvers.gravity import gravity_torques
from solvers.physics import Imperfections, true_tcp_poses
from solvers.recording import RecordingData, last_motion_sign
from solvers.robots import ROBOTS
from solvers.simulate import DEFAULT_INSTRUMENT, simulate_recording

N = {"touch": 6, "tracker": 12, "beam": 20}
INST = DEFAULT_INSTRUMENT.as_matrix()


def sim(kind: str, robot="ur10", imp: Imperfections | None = None, n: int | None = None, **kw) -> RecordingData:
    return parse_recording(simulate_recording(kind, robot, imp, n or N[kind], seed=7, **kw))


def beam_conditions(rec: RecordingData, T: np.ndarray) -> np.ndarray:
    """Each trigger's condition (0 exactly at the trigger) for TCP poses T (N, 4, 4)."""
    r = rec.tool_diameter_mm / 2
    out = []
    for k in range(rec.n_samples):
        point, u = rec.beams[str(rec.beam_ids[k])]
        v = rec.tcp_velocity_mm_s[k]
        p, w = T[k, :3, 3], T[k, :3, 2]
        if rec.edges[k] == "tip":
            nv = v - (v @ u) * u
            out.append((p - point) @ nv / np.linalg.norm(nv))
            continue
        n = np.cross(w, u)
        n = n / np.linalg.norm(n) * np.sign(np.cross(w, u) @ v)
        out.append((p - point) @ n + (r if rec.edges[k] == "enter" else -r))
    return np.array(out)


@pytest.mark.parametrize("kind", ["touch", "tracker", "beam"])
def test_every_kind_and_arm_gives_a_valid_exact_recording(kind, robot):
    """Both DH conventions (TM5 is modified), KUKA's counted-against joints, FANUC's coupling."""
    rec = sim(kind, robot)
    assert rec.kind == kind and rec.n_samples == N[kind] and rec.robot.dh_convention == robot.dh_convention
    assert rec.robot.coupling is None  # FANUC's J2/J3 written decoupled
    T = forward_kinematics(rec.robot, rec.joints_deg, rec.tool)
    if kind == "tracker":
        np.testing.assert_allclose(rec.measured_mm, apply(INST, T[:, :3, 3]), atol=1e-8)
    elif kind == "touch":
        assert np.ptp(T[:, :3, 3], axis=0).max() < 1e-6
        tilts = np.degrees(np.arccos(-T[:, 2, 2]))
        assert tilts.min() > 19 and tilts.max() < 51
    else:
        assert np.abs(beam_conditions(rec, T)).max() < 1e-6
        assert set(rec.edges) == {"enter", "leave", "tip"}


def test_coupled_fanuc_file_joints_are_decoupled():
    rec = sim("tracker", "fanuc_lrmate200id")
    fanuc = ROBOTS["fanuc_lrmate200id"]
    q_ctrl = np.linalg.solve(fanuc.coupling_matrix(), rec.joints_deg.T).T
    np.testing.assert_allclose(forward_kinematics(rec.robot, rec.joints_deg),
                               forward_kinematics(fanuc, q_ctrl), atol=1e-9)


def test_tracker_joint_offset_is_fk_at_q_plus_offset():
    rec = sim("tracker", imp=Imperfections(joint_offset_deg=(0, 0.05, 0, 0, 0, 0)))
    T = forward_kinematics(rec.robot, rec.joints_deg + [0, 0.05, 0, 0, 0, 0], rec.tool)
    np.testing.assert_allclose(rec.measured_mm, apply(INST, T[:, :3, 3]), atol=1e-8)


def test_tracker_link_length_and_compliance_and_backlash():
    imp = Imperfections(dh_delta={("a_mm", 2): 0.3}, compliance_deg_per_Nm=(0, 0.001, 0.002, 0, 0, 0),
                        backlash_deg=(0.02, 0.03, 0, 0, 0, 0))
    rec = sim("tracker", imp=imp, payload=(4.0, (0, 0, 60)))
    assert rec.payload_mass_kg == 4.0
    q = rec.joints_deg
    q_true = (q - last_motion_sign(rec) * np.array(imp.backlash_deg) / 2
              + np.array(imp.compliance_deg_per_Nm) * gravity_torques(rec.robot, q, 4.0, (0, 0, 60)))
    truth = rec.robot.with_joint(1, a_mm=rec.robot.joints[1].a_mm + 0.3)
    T = forward_kinematics(truth, q_true, rec.tool)
    np.testing.assert_allclose(rec.measured_mm, apply(INST, T[:, :3, 3]), atol=1e-8)


def test_tracker_thermal_drift_and_noise():
    rec = sim("tracker", imp=Imperfections(thermal_drift_mm=0.5), n=20)
    T = forward_kinematics(rec.robot, rec.joints_deg, rec.tool)
    drift = np.outer(rec.t_s / rec.t_s[-1], [0, 0, 0.5])
    np.testing.assert_allclose(rec.measured_mm, apply(INST, T[:, :3, 3] + drift), atol=1e-8)
    noisy = sim("tracker", imp=Imperfections(noise_mm=0.02), n=200)
    r = noisy.measured_mm - apply(INST, forward_kinematics(noisy.robot, noisy.joints_deg, noisy.tool)[:, :3, 3])
    assert 0.016 < r.std() < 0.024


def test_touch_real_tcp_is_on_the_point_the_recorded_one_is_not():
    imp = Imperfections(joint_offset_deg=(0, 0.05, -0.03, 0, 0.02, 0), backlash_deg=(0.02,) * 6,
                        thermal_drift_mm=0.2)
    doc = simulate_recording("touch", "kuka_kr6_r900_sixx", imp, 8, seed=3, payload=(2.0, (0, 0, 50)))
    rec = parse_recording(doc)
    true = true_tcp_poses(rec.robot, rec.joints_deg, rec.t_s, imp, rec.tool, rec.start_joints_deg,
                          rec.payload_mass_kg, rec.payload_com_mm)[:, :3, 3]
    assert np.ptp(true, axis=0).max() < 1e-6
    nominal = forward_kinematics(rec.robot, rec.joints_deg, rec.tool)[:, :3, 3]
    assert np.ptp(nominal, axis=0).max() > 0.1  # the rigid model sees the imperfections
    noisy = sim("touch", imp=Imperfections(noise_mm=0.1), n=8)
    spread = forward_kinematics(noisy.robot, noisy.joints_deg, noisy.tool)[:, :3, 3]
    assert 0.02 < np.ptp(spread, axis=0).max() < 1.0


def test_beam_latency_records_the_pose_later_along_the_motion():
    rec = sim("beam", imp=Imperfections(trigger_latency_ms=50.0), speed_mm_s=20.0)
    T = forward_kinematics(rec.robot, rec.joints_deg, rec.tool)
    cond = beam_conditions(rec, T)
    assert np.abs(cond).min() > 0.5  # 20 mm/s x 50 ms = 1 mm late, along the motion
    T[:, :3, 3] -= rec.tcp_velocity_mm_s * 0.05
    assert np.abs(beam_conditions(rec, T)).max() < 1e-6


def test_beam_triggers_happen_on_the_true_robot():
    imp = Imperfections(joint_offset_deg=(0.02, -0.03, 0.01, 0, 0.05, 0), backlash_deg=(0.01,) * 6,
                        trigger_latency_ms=20.0, thermal_drift_mm=0.1)
    rec = sim("beam", "abb_irb120", imp, heights=3, both_directions=False)
    true = true_tcp_poses(rec.robot, rec.joints_deg, rec.t_s, imp, rec.tool, rec.start_joints_deg,
                          tcp_velocity_mm_s=rec.tcp_velocity_mm_s)
    miss = np.abs(beam_conditions(rec, true))
    assert np.median(miss) < 1e-9 and miss.max() < 1e-5  # (a backlash flank flip at a trigger)
    nominal = beam_conditions(rec, forward_kinematics(rec.robot, rec.joints_deg, rec.tool))
    assert np.abs(nominal).max() > 0.05
    # one direction only: all passes move the same way
    passes = rec.tcp_velocity_mm_s[rec.edges != "tip"]
    assert np.allclose(passes, passes[0])


def test_custom_tool_instrument_and_sensor():
    tool = Pose(2.0, -1.0, 180.0, 0, 3, 0)
    inst = Pose(1000, 0, 0, 90, 0, 0)
    rec = sim("tracker", tool_mm=tool, instrument_pose=inst)
    np.testing.assert_allclose(rec.tool, tool.as_matrix(), atol=1e-9)
    T = forward_kinematics(rec.robot, rec.joints_deg, rec.tool)
    np.testing.assert_allclose(rec.measured_mm, apply(inst.as_matrix(), T[:, :3, 3]), atol=1e-8)
    base = sim("beam", "ur5e")
    sensor = {"beams": [{"id": "b1", "point_mm": list(base.beams["bx"][0]), "direction": [1, 1, 0]},
                        {"id": "b2", "point_mm": list(base.beams["bx"][0]), "direction": [1, -1, 0]}],
              "tool_diameter_mm": 4.0}
    rec = sim("beam", "ur5e", sensor=sensor)
    assert set(rec.beam_ids) == {"b1", "b2"} and rec.tool_diameter_mm == 4.0
    assert np.abs(beam_conditions(rec, forward_kinematics(rec.robot, rec.joints_deg, rec.tool))).max() < 1e-6


@pytest.mark.parametrize("kwargs, loc", [
    (dict(kind="dance"), ("kind",)),
    (dict(robot="ur99"), ("robot",)),
    (dict(kind="beam", heights=5), ("heights",)),
    (dict(imperfections=Imperfections(joint_offset_deg=(1, 2))), ("joint_offset_deg",)),
    (dict(payload=(-1.0, (0, 0, 0))), ("payload", "mass_kg")),
])
def test_bad_arguments_are_refused_by_name(kwargs, loc):
    args = dict(kind="tracker", robot="ur10", imperfections=None, n_samples=5) | kwargs
    with pytest.raises(CalibrationError) as info:
        simulate_recording(**args)
    assert info.value.loc == loc


def test_same_seed_same_recording():
    a = simulate_recording("touch", "ur5e", Imperfections(noise_mm=0.05), 5, seed=11)
    b = simulate_recording("touch", "ur5e", Imperfections(noise_mm=0.05), 5, seed=11)
    assert a == b


def test_touch_point_can_be_chosen():
    rec = sim("touch", touch_point_mm=(700, -200, 100))
    tcp = forward_kinematics(rec.robot, rec.joints_deg, rec.tool)[:, :3, 3]
    np.testing.assert_allclose(tcp, np.tile([700, -200, 100], (len(tcp), 1)), atol=1e-6)
