"""Fixed tool > 5D / 6D: touch an external TCP with a calibrated pointer, then align the flange."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solvers import dh
from solvers.errors import CalibrationError, KinematicsError
from solvers.fixed_tool import R_FLANGE_FIXEDTOOL, fixed_tool_5d, fixed_tool_6d, axis_frame_5d
from solvers.frames import Pose, angle_between_deg, axis_angle_deg
from test_solver_base import TOOL, TOOL_TCP_MM, random_q

RX180 = Rotation.from_euler("x", 180, degrees=True).as_matrix()


def fixed_tool_scene(robot, rng, tries=40):
    """A fixed tool in reach (axis within 40 deg of up, any twist) and the robot's two poses:
    (T_world_fixedtool, touch flange pose, align flange pose), both from FK of IK solutions."""
    for _ in range(tries):
        q0 = random_q(robot, rng)
        r = dh.forward_kinematics(robot, q0, TOOL)[:3, 3]  # the pointer tip at the start is r
        axis = np.r_[rng.normal(size=2), 0.0]
        tilt = Rotation.from_rotvec(np.radians(rng.uniform(0, 40)) * axis / np.linalg.norm(axis))
        R_E = (tilt * Rotation.from_euler("z", rng.uniform(-180, 180), degrees=True)).as_matrix()
        T_E = np.eye(4)
        T_E[:3, :3], T_E[:3, 3] = R_E, r
        G = np.eye(4)
        G[:3, :3] = R_E @ R_FLANGE_FIXEDTOOL  # the lecture's alignment, flange 150 mm above the tip
        G[:3, 3] = r + 150.0 * R_E[:, 2]
        try:
            q2 = dh.inverse_kinematics(robot, G, q0)
        except KinematicsError:
            continue
        return T_E, dh.forward_kinematics(robot, q0), dh.forward_kinematics(robot, q2)
    raise AssertionError(f"{robot.name}: no reachable fixed tool in {tries} tries")


def test_fixed_tool_6d_touch_then_align_then_frame(robot, rng):
    """Fixed tool > 6D: touch the external TCP with the pointer, align all flange axes, save."""
    T_E, T1, T2 = fixed_tool_scene(robot, rng)
    res = fixed_tool_6d(T1, TOOL_TCP_MM, T2)
    assert res.method == "fixed_tool.6d"
    assert np.linalg.norm(res.frame[:3, 3] - T_E[:3, 3]) < 1e-6
    assert angle_between_deg(res.frame[:3, :3], T_E[:3, :3]) < 1e-4
    assert res.report.residuals_mm.tolist() == [0.0]
    assert res.report.extras["align_distance_mm"] == pytest.approx(150.0, abs=1e-4)


def test_fixed_tool_5d_touch_then_align_axis_then_frame(robot, rng):
    """Fixed tool > 5D: only the tool axis is taken; X is world X projected across it."""
    T_E, T1, T2 = fixed_tool_scene(robot, rng)
    res = fixed_tool_5d(T1, TOOL_TCP_MM, T2)
    assert res.method == "fixed_tool.5d"
    assert np.linalg.norm(res.frame[:3, 3] - T_E[:3, 3]) < 1e-6
    assert axis_angle_deg(res.frame[:3, 2], T_E[:3, 2]) < 1e-4
    assert np.allclose(res.frame[:3, :3], axis_frame_5d(T_E[:3, 2]), atol=1e-9)
    # X lies in the plane of world X and the axis, on world X's side
    x, z = res.frame[:3, 0], res.frame[:3, 2]
    assert abs(np.cross(z, [1, 0, 0]) @ x) < 1e-9 and x[0] > 0


def test_fixed_tool_5d_ignores_flange_spin_about_the_axis(rng):
    """5D: spinning the aligned flange about its Z changes the 6D frame but not the 5D one."""
    T1 = Pose(600, 0, 400, 0, 180, 0).as_matrix()
    T2 = Pose(650, 20, 350, 10, 160, 5).as_matrix()
    spun = T2 @ np.block([[Rotation.from_euler("z", 37, degrees=True).as_matrix(), np.zeros((3, 1))],
                          [np.zeros((1, 3)), np.ones((1, 1))]])
    a5, b5 = fixed_tool_5d(T1, TOOL_TCP_MM, T2), fixed_tool_5d(T1, TOOL_TCP_MM, spun)
    a6, b6 = fixed_tool_6d(T1, TOOL_TCP_MM, T2), fixed_tool_6d(T1, TOOL_TCP_MM, spun)
    assert np.allclose(a5.frame, b5.frame, atol=1e-12)
    assert angle_between_deg(a6.frame[:3, :3], b6.frame[:3, :3]) == pytest.approx(37.0)
    assert b5.report.extras["twist_discarded_deg"] == pytest.approx(
        angle_between_deg(b5.frame[:3, :3], b6.frame[:3, :3]))


def test_fixed_tool_alignment_is_rx180_of_the_lecture():
    """-Z_E along +Z_F, X_E along X_F, Y_E along -Y_F: F_Q_E = Rx(180)."""
    T2 = Pose(0, 0, 0, 30, 20, 10).as_matrix()
    R = fixed_tool_6d(np.eye(4), [0, 0, 100], T2).frame[:3, :3]
    F = T2[:3, :3]
    assert np.allclose(R[:, 0], F[:, 0]) and np.allclose(R[:, 1], -F[:, 1]) and np.allclose(R[:, 2], -F[:, 2])
    assert np.allclose(R_FLANGE_FIXEDTOOL, RX180)


def test_5d_frame_straight_down_keeps_world_x():
    assert np.allclose(axis_frame_5d([0, 0, -1]), np.diag([1, -1, -1.0]))
    assert np.allclose(axis_frame_5d([0, 0, 5]), np.eye(3))


@pytest.mark.parametrize("z", [[0, 0, -1], [0, 0, 1], [0, 1, 0], [0.3, -0.5, -0.8]])
def test_5d_frame_moves_smoothly_as_the_axis_tilts(z):
    """A 0.01 deg change of the axis turns X by about as much, never by 180 deg (a fixed
    nozzle pointing straight down used to flip its X between readings)."""
    z = np.asarray(z, float) / np.linalg.norm(z)
    for axis in ([1, 0, 0], [0, 1, 0], [0, 0, 1]):
        if np.linalg.norm(np.cross(z, axis)) < 1e-9:
            continue
        z2 = Rotation.from_rotvec(np.radians(0.01) * np.cross(z, axis) / np.linalg.norm(np.cross(z, axis))).apply(z)
        assert angle_between_deg(axis_frame_5d(z), axis_frame_5d(z2)) < 0.05


@pytest.mark.parametrize("fn", [fixed_tool_5d, fixed_tool_6d])
def test_fixed_tool_alignment_done_the_other_way_round_is_flagged(robot, rng, fn):
    """Flange +Z along the fixed tool's +Z (not -Z) at the alignment, flange 150 mm above the
    tip: the axis comes out 180 deg off, and the touch-ups tell: the flange stood behind the
    fixed TCP at the touch and at the alignment. The right alignment raises nothing."""
    T_E, _, T2 = fixed_tool_scene(robot, rng)
    T1 = np.eye(4)  # the pointer onto the fixed TCP from its working side, tilted up to 40 deg
    v = np.r_[rng.normal(size=2), 0.0]
    tilt = Rotation.from_rotvec(np.radians(rng.uniform(0, 40)) * v / np.linalg.norm(v))
    T1[:3, :3] = T_E[:3, :3] @ RX180 @ tilt.as_matrix()
    T1[:3, 3] = T_E[:3, 3] - T1[:3, :3] @ TOOL_TCP_MM
    right = fn(T1, TOOL_TCP_MM, T2)
    assert "alignment_flipped" not in {w.code for w in right.report.warnings}
    assert np.nanmin(right.report.extras["flange_elevation_deg"]) > 0
    flipped_pose = T2.copy()
    flipped_pose[:3, :3] = T_E[:3, :3]  # flange z = +Z_E
    flipped = fn(T1, TOOL_TCP_MM, flipped_pose)
    assert axis_angle_deg(flipped.frame[:3, 2], T_E[:3, 2]) == pytest.approx(180.0, abs=1e-4)
    (w,) = [f for f in flipped.report.warnings if f.code == "alignment_flipped"]
    assert w.loc == ("align_flange_pose",) and "flange -Z along the fixed tool's +Z" in w.message
    assert np.nanmax(flipped.report.extras["flange_elevation_deg"]) < -30


def test_fixed_tool_alignment_from_the_side_cannot_tell():
    """Touch and alignment from the side (flange level with the fixed TCP): no verdict; the
    menu's prompt says which way to align."""
    r = np.array([800.0, 0.0, 300.0])
    side = Rotation.from_euler("y", -90, degrees=True).as_matrix()  # flange z along world -X
    T1 = np.eye(4)
    T1[:3, :3], T1[:3, 3] = side, r - side @ TOOL_TCP_MM
    for z_flange in (1.0, -1.0):
        T2 = np.eye(4)
        T2[:3, :3] = np.diag([1.0, z_flange, z_flange])  # flange z up or down
        T2[:3, 3] = r + [150.0, 0, 0]
        rep = fixed_tool_5d(T1, TOOL_TCP_MM, T2).report
        assert "alignment_flipped" not in {w.code for w in rep.warnings}
        assert np.abs(rep.extras["flange_elevation_deg"]).max() < 1e-6


def test_fixed_tool_extra_touches_average_and_report_scatter(rng):
    """Extra touches from other orientations: r is their mean, their scatter the residual."""
    r = np.array([800.0, 100.0, 200.0])
    poses = []
    for k in range(4):
        R = Rotation.from_euler("ZYX", [90 * k, 160 + 5 * k, 10], degrees=True).as_matrix()
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, r - R @ TOOL_TCP_MM + rng.normal(0, 0.05, 3)
        poses.append(T)
    res = fixed_tool_6d(poses[0], TOOL_TCP_MM, Pose(800, 100, 400, 0, 180, 0).as_matrix(),
                        extra_touch_poses=np.array(poses[1:]))
    rep = res.report
    assert len(rep.residuals_mm) == 4
    assert np.linalg.norm(res.frame[:3, 3] - r) < 0.15
    assert rep.sigma_mm < 0.15 and rep.position_bound95_mm < 0.3
    assert rep.warnings == ()


def test_fixed_tool_extra_touches_expose_a_wrong_pointer_tcp():
    """A pointer TCP 2 mm off: touches from four sides disagree, the report says so."""
    r = np.array([800.0, 100.0, 200.0])
    poses = []
    for k in range(4):
        R = Rotation.from_euler("ZYX", [90 * k, 150, 0], degrees=True).as_matrix()
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, r - R @ TOOL_TCP_MM
        poses.append(T)
    res = fixed_tool_5d(poses[0], TOOL_TCP_MM + [2, 0, 0], np.eye(4), extra_touch_poses=np.array(poses[1:]))
    assert [w.code for w in res.report.warnings] == ["touch_spread"]
    assert res.report.max_error_mm > 0.5


def test_fixed_tool_bare_flange_is_noted():
    res = fixed_tool_6d(np.eye(4), [0, 0, 0], np.eye(4))
    assert [w.code for w in res.report.warnings] == ["tcp_at_flange"]


def test_fixed_tool_accepts_pose():
    a = fixed_tool_6d(Pose(500, 0, 300, 0, 180, 0), TOOL_TCP_MM, Pose(500, 0, 400))
    b = fixed_tool_6d(Pose(500, 0, 300, 0, 180, 0).as_matrix(), TOOL_TCP_MM, Pose(500, 0, 400).as_matrix())
    assert np.allclose(a.frame, b.frame)


MIRROR = np.diag([1, 1, -1, 1.0])
NAN_POSE = np.eye(4)
NAN_POSE[1, 3] = np.nan


@pytest.mark.parametrize("fn", [fixed_tool_5d, fixed_tool_6d])
@pytest.mark.parametrize("args, kwargs, loc", [
    ((NAN_POSE, TOOL_TCP_MM, np.eye(4)), {}, ("touch_flange_pose", 1, 3)),
    ((np.eye(4), [0, np.nan, 100], np.eye(4)), {}, ("tool_tcp_mm", 1)),
    ((np.eye(4), [0, 100], np.eye(4)), {}, ("tool_tcp_mm",)),
    ((np.eye(4), TOOL_TCP_MM, MIRROR), {}, ("align_flange_pose",)),
    ((np.eye(4), TOOL_TCP_MM, np.eye(3)), {}, ("align_flange_pose",)),
    ((np.eye(4), TOOL_TCP_MM, np.eye(4)), {"extra_touch_poses": [MIRROR]}, ("extra_touch_poses", 0)),
    ((Pose(0, 0, 0, np.nan, 0, 0), TOOL_TCP_MM, np.eye(4)), {}, ("touch_flange_pose", 3)),
])
def test_fixed_tool_refuses_bad_input(fn, args, kwargs, loc):
    with pytest.raises(CalibrationError) as e:
        fn(*args, **kwargs)
    assert e.value.loc == loc
