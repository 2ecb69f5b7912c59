"""Robot kinematics: both DH conventions, Jacobian and inverse kinematics on every arm."""

from __future__ import annotations

import numpy as np
import pytest

from solvers import dh
from solvers.errors import KinematicsError
from solvers.frames import Pose, matrix_from_kuka
from solvers.robots import ROBOTS


def random_q(robot, rng, n=None, margin=0.8):
    lim = robot.limits_deg() * margin
    lim = np.clip(lim, -170, 170)
    size = (robot.dof,) if n is None else (n, robot.dof)
    return rng.uniform(lim[:, 0], lim[:, 1], size=size)


def test_batch_equals_single(robot, rng):
    q = random_q(robot, rng, 5)
    T = dh.forward_kinematics(robot, q)
    for k in range(5):
        assert np.allclose(T[k], dh.forward_kinematics(robot, q[k]))


def test_standard_and_modified_tables_describe_the_same_arm():
    """The UR5e written in modified DH (Craig) gives the same flange poses as the standard table."""
    std = ROBOTS["ur5e"]
    p = std.params()
    # Standard row i (a_i, alpha_i) becomes modified row i+1's (a_{i}, alpha_{i}); the final
    # standard (a_6, alpha_6) moves into the flange pose.
    a = np.r_[0, p["a_mm"][:-1]]
    alpha = np.r_[0, p["alpha_deg"][:-1]]
    joints = tuple(dh.DHJoint(a_mm=a[i], alpha_deg=alpha[i], d_mm=p["d_mm"][i], offset_deg=0)
                   for i in range(6))
    mod = dh.RobotModel(name="UR5e modified", dh_convention="modified", joints=joints,
                        flange_pose=Pose(x=p["a_mm"][-1], c=p["alpha_deg"][-1]))
    q = np.random.default_rng(1).uniform(-180, 180, (20, 6))
    assert np.allclose(dh.forward_kinematics(std, q), dh.forward_kinematics(mod, q), atol=1e-9)


def test_jacobian_matches_finite_differences(robot, rng):
    q = random_q(robot, rng)
    tool = matrix_from_kuka([10, -20, 150, 0, 30, 0])
    J = dh.geometric_jacobian(robot, q, tool)
    h = 1e-6
    T0 = dh.forward_kinematics(robot, q, tool)
    for j in range(robot.dof):
        dq = np.zeros(robot.dof)
        dq[j] = h
        T1 = dh.forward_kinematics(robot, q + dq, tool)
        v = (T1[:3, 3] - T0[:3, 3]) / np.radians(h)
        dR = T1[:3, :3] @ T0[:3, :3].T
        w = np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]]) / 2 / np.radians(h)
        assert np.allclose(J[:3, j], v, atol=1e-3), f"joint {j + 1} linear"
        assert np.allclose(J[3:, j], w, atol=1e-6), f"joint {j + 1} angular"


def test_inverse_kinematics_reaches_a_reachable_pose(robot, rng):
    q_true = random_q(robot, rng, margin=0.5)
    goal = dh.forward_kinematics(robot, q_true)
    q_start = q_true + rng.normal(0, 5, robot.dof)
    q = dh.inverse_kinematics(robot, goal, q_start)
    assert np.allclose(dh.forward_kinematics(robot, q), goal, atol=1e-6)


def test_inverse_kinematics_refuses_out_of_reach(robot):
    goal = np.eye(4)
    goal[:3, 3] = [5000, 0, 0]
    with pytest.raises(KinematicsError) as e:
        dh.inverse_kinematics(robot, goal, np.zeros(robot.dof) + 1)
    assert "not reachable" in e.value.reason


def test_joint_limit_names_joint_value_and_limit():
    kuka = ROBOTS["kuka_kr6_r900_sixx"]
    with pytest.raises(KinematicsError) as e:
        dh.check_joint_limits(kuka, [0, 60, 0, 0, 0, 0])
    assert e.value.loc == ("joints_deg", 1)
    assert "A2 (joint 2) at 60.000 deg" in e.value.reason and "[-190, 45]" in e.value.reason


def test_wrong_joint_count_is_named():
    with pytest.raises(KinematicsError.__mro__[1]) as e:
        dh.forward_kinematics(ROBOTS["ur5e"], [0, 0, 0])
    assert e.value.loc == ("joints_deg",)
