"""Hidden physics: gravity torques by hand and by energy, each imperfection in its documented sense."""

from __future__ import annotations

import numpy as np
import pytest

from solvers.dh import DHJoint, RobotModel, forward_kinematics
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.gravity import gravity_torques, link_masses, potential_energy_j
from solvers.physics import (Imperfections, thermal_shift_mm, true_flange_poses, true_tcp_poses,
                             true_tcp_positions)
from solvers.recording import motion_signs
from solvers.robots import ROBOTS

TOOL = Pose(z=150.0).as_matrix()


def q_random(robot: RobotModel, rng, n: int = 8) -> np.ndarray:
    return rng.uniform(-80, 80, (n, robot.dof))


def test_gravity_two_link_horizontal_arm_by_hand():
    """tau_1 = g (m1 l/2 + m2 3l/2 + m_p 2l), tau_2 = g (m2 l/2 + m_p l), pulling the arm down."""
    arm = RobotModel("two links", "standard", (DHJoint(1000, 0, 0), DHJoint(1000, 0, 0)),
                     base_pose=Pose(c=90))  # joint axes along -y of base, arm along +x
    m1, m2 = link_masses(arm).mass_kg
    tau = gravity_torques(arm, [0, 0], payload_mass_kg=2.0)
    assert tau == pytest.approx([-9.81 * (m1 * 0.5 + m2 * 1.5 + 2 * 2.0), -9.81 * (m2 * 0.5 + 2 * 1.0)])
    # arm pointing straight up: no torque; turned by +90 deg about -y the arm points up
    assert gravity_torques(arm, [90, 0], 2.0) == pytest.approx([0, 0], abs=1e-9)


def test_gravity_torque_is_minus_gradient_of_potential_energy(robot, rng):
    """tau = -dV/dq (q in rad), every arm incl. FANUC's coupled J2/J3 and TM5's modified DH."""
    q = q_random(robot, rng, 4)
    pay = (3.0, (10.0, -5.0, 80.0))
    tau = gravity_torques(robot, q, *pay)
    h = 1e-6
    for i in range(robot.dof):
        dq = np.zeros(robot.dof)
        dq[i] = np.degrees(h)
        fd = -(potential_energy_j(robot, q + dq, *pay) - potential_energy_j(robot, q - dq, *pay)) / (2 * h)
        assert tau[:, i] == pytest.approx(fd, abs=1e-6)


def test_ur_mass_tables_are_the_published_ones():
    assert link_masses(ROBOTS["ur10"]).mass_kg == (7.1, 12.7, 4.27, 2.0, 2.0, 0.365)
    assert link_masses(ROBOTS["ur5e"]).mass_kg == (3.761, 8.058, 2.846, 1.37, 1.3, 0.365)
    assert "estimate" in link_masses(ROBOTS["kuka_kr6_r900_sixx"]).source


def test_no_imperfections_is_the_rigid_model(robot, rng):
    q = q_random(robot, rng)
    T = true_flange_poses(robot, q, np.arange(8.0), Imperfections())
    np.testing.assert_allclose(T, forward_kinematics(robot, q), atol=1e-9)


@pytest.mark.parametrize("key", ["ur10", "kuka_kr6_r900_sixx"])
def test_joint_offset_turns_the_dh_angle(key, rng):
    """offset_deg is true minus recorded, in the sense of the DH angle theta."""
    robot = ROBOTS[key]
    q = q_random(robot, rng)
    T = true_flange_poses(robot, q, np.zeros(8), Imperfections(joint_offset_deg=(0, 0.2, 0, -0.1, 0, 0)))
    j = robot.joints
    truth = robot.with_joint(1, offset_deg=j[1].offset_deg + 0.2).with_joint(3, offset_deg=j[3].offset_deg - 0.1)
    np.testing.assert_allclose(T, forward_kinematics(truth, q), atol=1e-9)
    if key == "ur10":  # direction +1: the joint stands at q + offset
        np.testing.assert_allclose(T, forward_kinematics(robot, q + [0, 0.2, 0, -0.1, 0, 0]), atol=1e-9)


def test_dh_delta_is_true_minus_nominal(rng):
    robot = ROBOTS["abb_irb120"]
    q = q_random(robot, rng)
    imp = Imperfections(dh_delta={("a_mm", 2): 0.3, ("d_mm", 4): -0.2, ("alpha_deg", 3): 0.01})
    truth = robot.with_joint(1, a_mm=270.3).with_joint(3, d_mm=301.8).with_joint(2, alpha_deg=-89.99)
    np.testing.assert_allclose(true_flange_poses(robot, q, np.zeros(8), imp),
                               forward_kinematics(truth, q), atol=1e-9)


def test_compliance_yields_along_gravity_torque(rng):
    robot = ROBOTS["ur10"]
    q = q_random(robot, rng)
    c = np.array([0, 0.002, 0.001, 0, 0, 0])
    T = true_flange_poses(robot, q, np.zeros(8), Imperfections(compliance_deg_per_Nm=tuple(c)),
                          payload_mass_kg=5.0, payload_com_mm=(0, 0, 50))
    tau = gravity_torques(robot, q, 5.0, (0, 0, 50))
    np.testing.assert_allclose(T, forward_kinematics(robot, q + c * tau), atol=1e-9)
    # yielding lowers the TCP (gravity does positive work)
    dz = T[:, 2, 3] - forward_kinematics(robot, q)[:, 2, 3]
    assert np.all(dz <= 1e-9) and dz.min() < -0.1


def test_backlash_link_lags_the_motor_by_half_the_lost_motion(rng):
    robot = ROBOTS["ur5e"]
    q = q_random(robot, rng)
    start = np.zeros(6)
    b = np.array([0.05, 0.1, 0, 0, 0, 0.02])
    T = true_flange_poses(robot, q, np.zeros(8), Imperfections(backlash_deg=tuple(b)), start_joints_deg=start)
    s = motion_signs(q, start)
    np.testing.assert_allclose(T, forward_kinematics(robot, q - s * b / 2), atol=1e-9)
    # approached from + and from -: the joint stands b apart
    up = true_flange_poses(robot, [q[0]], [0], Imperfections(backlash_deg=tuple(b)), q[0] - 1)
    down = true_flange_poses(robot, [q[0]], [0], Imperfections(backlash_deg=tuple(b)), q[0] + 1)
    np.testing.assert_allclose(down, forward_kinematics(robot, q[0] + b / 2)[None], atol=1e-9)
    np.testing.assert_allclose(up, forward_kinematics(robot, q[0] - b / 2)[None], atol=1e-9)


def test_thermal_drift_moves_the_base_linearly_in_time(rng):
    robot = ROBOTS["tm5_900"]
    q = q_random(robot, rng)
    t = np.linspace(100, 800, 8)
    imp = Imperfections(thermal_drift_mm=0.4)
    d = true_flange_poses(robot, q, t, imp)[:, :3, 3] - forward_kinematics(robot, q)[:, :3, 3]
    np.testing.assert_allclose(d, np.outer((t - 100) / 700, [0, 0, 0.4]), atol=1e-9)
    assert thermal_shift_mm([0, 5, 10], Imperfections(thermal_drift_mm=1, thermal_direction=(2, 0, 0)),
                            (0, 20))[:, 0] == pytest.approx([0, 0.25, 0.5])


def test_latency_moves_the_pose_back_along_the_velocity(rng):
    robot = ROBOTS["ur10"]
    q = q_random(robot, rng, 3)
    v = np.array([[10.0, 0, 0], [0, -20, 0], [5, 5, 5]])
    T = true_flange_poses(robot, q, np.zeros(3), Imperfections(trigger_latency_ms=40), tcp_velocity_mm_s=v)
    np.testing.assert_allclose(T[:, :3, 3], forward_kinematics(robot, q)[:, :3, 3] - 0.04 * v, atol=1e-9)
    np.testing.assert_allclose(T[:, :3, :3], forward_kinematics(robot, q)[:, :3, :3], atol=1e-12)


def test_tool_deflection_pushes_the_tcp_down_across_the_tool_axis(rng):
    robot = ROBOTS["ur10"]
    q = q_random(robot, rng)
    imp = Imperfections(tool_deflection_mm_per_N=0.002)
    T = true_tcp_poses(robot, q, np.zeros(8), imp, TOOL, payload_mass_kg=4.0)
    nominal = forward_kinematics(robot, q, TOOL)
    d = T[:, :3, 3] - nominal[:, :3, 3]
    w = nominal[:, :3, 2]
    F = np.array([0, 0, -9.81 * 4.0])
    np.testing.assert_allclose(d, 0.002 * (F - (w @ F)[:, None] * w), atol=1e-9)
    assert np.allclose(np.einsum("ij,ij->i", d, w), 0) and np.all(d[:, 2] <= 1e-12)
    # no payload, no deflection
    np.testing.assert_allclose(true_tcp_positions(robot, q, np.zeros(8), imp, TOOL), nominal[:, :3, 3])


def test_cyclic_error_is_a_sine_of_the_joint_angle(rng):
    robot = ROBOTS["ur5e"]
    q = q_random(robot, rng)
    T = true_flange_poses(robot, q, np.zeros(8), Imperfections(cyclic_error={3: (0.02, 4.0)}))
    dq = np.zeros_like(q)
    dq[:, 2] = 0.02 * np.sin(np.radians(4 * q[:, 2]))
    np.testing.assert_allclose(T, forward_kinematics(robot, q + dq), atol=1e-9)


@pytest.mark.parametrize("imp, loc", [
    (Imperfections(joint_offset_deg=(0, 1)), ("joint_offset_deg",)),
    (Imperfections(backlash_deg=(-1, 0, 0, 0, 0, 0)), ("backlash_deg",)),
    (Imperfections(dh_delta={("a_mm", 7): 1.0}), ("dh_delta", "a_mm:7")),
    (Imperfections(dh_delta={("theta", 1): 1.0}), ("dh_delta", "theta:1")),
    (Imperfections(cyclic_error={0: (1, 1)}), ("cyclic_error", 0)),
    (Imperfections(noise_mm=-1), ("noise_mm",)),
    (Imperfections(thermal_drift_mm=float("nan")), ("thermal_drift_mm",)),
])
def test_bad_imperfections_are_refused_by_name(imp, loc):
    with pytest.raises(CalibrationError) as info:
        true_flange_poses(ROBOTS["ur10"], np.zeros((1, 6)), [0.0], imp)
    assert info.value.loc == loc


def test_imperfections_from_json_style_dict():
    imp = Imperfections.from_dict({"joint_offset_deg": [0, 0.1, 0, 0, 0, 0], "dh_delta": {"d_mm:4": -0.2},
                                   "backlash_deg": [0.01] * 6, "thermal_drift_mm": 0.3})
    assert imp.joint_offset_deg == (0, 0.1, 0, 0, 0, 0) and dict(imp.dh_delta) == {("d_mm", 4): -0.2}
    assert imp.check(6) is imp and not imp.is_rigid()
    with pytest.raises(CalibrationError) as info:
        Imperfections.from_dict({"gremlins": 1})
    assert info.value.loc == ("gremlins",)
    with pytest.raises(CalibrationError) as info:
        Imperfections.from_dict({"dh_delta": {"a_mm": 1}})
    assert info.value.loc == ("dh_delta", "a_mm")
