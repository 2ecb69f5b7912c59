"""Workpiece > Direct / Indirect: a robot-held workpiece brushed on a calibrated fixed TCP."""

from __future__ import annotations

import numpy as np
import pytest

from solvers import dh
from solvers.errors import CalibrationError, KinematicsError
from solvers.frames import angle_between_deg, apply, invert
from solvers.robots import ROBOTS
from solvers.workpiece import contact_points_flange, workpiece_direct, workpiece_indirect
from test_solver_base import SPREAD8, THREE, frame_errors, random_q, random_rotation

FOUR = np.array([[0, 0, 0], [200, 0, 0], [0, 150, 0], [0, 0, 80.0]])  # not coplanar
RECT4 = np.array([[0, 0, 0], [200, 0, 0], [200, 150, 0], [0, 150, 0.0]])  # coplanar


def random_workpiece(rng):
    """T_flange_workpiece: any rotation, origin 80..150 mm in front of the flange."""
    T = np.eye(4)
    T[:3, :3] = random_rotation(rng)
    T[:3, 3] = [rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(80, 150)]
    return T


def brush_scene(robot, rng, known_mm, tilt_deg=15.0, tries=40):
    """Bring each known workpiece point onto one fixed TCP, tilting the flange up to
    ``tilt_deg`` between touches: (T_flange_workpiece, r, flange poses from FK of IK)."""
    T_fw = random_workpiece(rng)
    c = apply(T_fw, known_mm)
    for _ in range(tries):
        q0 = random_q(robot, rng)
        T0 = dh.forward_kinematics(robot, q0)
        r = apply(T0, c[0])
        goals = []
        for k, ck in enumerate(c):
            G = np.eye(4)
            G[:3, :3] = T0[:3, :3] @ (np.eye(3) if k == 0 else random_rotation(rng, tilt_deg))
            G[:3, 3] = r - G[:3, :3] @ ck
            goals.append(G)
        try:
            qs = [dh.inverse_kinematics(robot, G, q0) for G in goals]
        except KinematicsError:
            continue
        return T_fw, r, np.array([dh.forward_kinematics(robot, q) for q in qs])
    raise AssertionError(f"{robot.name}: no reachable workpiece layout in {tries} tries")


# ---------------------------------------------------------------- workpiece.direct

def test_workpiece_direct_brush_origin_x_and_xy_then_frame(robot, rng):
    """Workpiece > Direct: origin, +X point, XY point on the fixed TCP (tilting between them)."""
    T_fw, r, poses = brush_scene(robot, rng, THREE)
    res = workpiece_direct(r, poses)
    assert res.method == "workpiece.direct"
    dp, da = frame_errors(T_fw, res.frame)
    assert dp < 1e-4 and da < 1e-4
    assert res.report.max_error_mm == 0.0
    assert np.allclose(res.report.extras["contact_points_mm"], apply(T_fw, THREE), atol=1e-4)


def test_workpiece_direct_constant_orientation_equals_lecture_vectors(rng):
    """With the orientation held, the result is the lecture's t, u = r - f2 - R t, v, w = u × v."""
    T_fw = random_workpiece(rng)
    R = random_rotation(rng)
    r = np.array([700.0, -50.0, 250.0])
    f = np.array([r - R @ ck for ck in apply(T_fw, THREE)])
    poses = np.stack([np.eye(4)] * 3)
    poses[:, :3, :3], poses[:, :3, 3] = R, f
    t = R.T @ (r - f[0])  # F_t_W
    u = r - f[1] - R @ t
    v = r - f[2] - R @ t
    x = u / np.linalg.norm(u)
    w = np.cross(u, v)
    z = w / np.linalg.norm(w)
    y = np.cross(z, x)
    R_FW = R.T @ np.column_stack([x, y, z])  # F_Q_W = [R_Q_F]^-1 R_Q_W
    res = workpiece_direct(r, poses)
    assert np.allclose(res.frame[:3, :3], R_FW, atol=1e-12)
    assert np.allclose(res.frame[:3, 3], t, atol=1e-9)
    assert np.allclose(res.frame, T_fw, atol=1e-9)


def test_workpiece_direct_noisy_within_stated_sensitivity(rng):
    T_fw = random_workpiece(rng)
    R = random_rotation(rng)
    r = np.array([700.0, -50.0, 250.0])
    poses = np.stack([np.eye(4)] * 3)
    poses[:, :3, :3] = R
    poses[:, :3, 3] = [r - R @ ck for ck in apply(T_fw, THREE)]
    rep0 = workpiece_direct(r, poses, touch_sigma_mm=0.05).report
    angles = []
    for _ in range(300):
        noisy = poses.copy()
        noisy[:, :3, 3] += rng.normal(0, 0.05, (3, 3))
        angles.append(angle_between_deg(T_fw[:3, :3], workpiece_direct(r, noisy).frame[:3, :3]))
    assert np.mean(np.array(angles) <= rep0.angle_bound95_deg) > 0.93
    assert rep0.angle_bound95_deg < 0.15


def test_workpiece_direct_refuses_points_too_close():
    T = np.stack([np.eye(4)] * 3)
    T[:, :3, 3] = [[500, 0, 400], [500, 0, 400], [500, -150, 400]]
    with pytest.raises(CalibrationError) as e:
        workpiece_direct([500, 0, 300], T)
    assert e.value.loc == ("flange_poses", 1) and "0.00 mm from the origin" in e.value.reason


def test_workpiece_direct_refuses_collinear_points():
    T = np.stack([np.eye(4)] * 3)
    T[:, :3, 3] = [[500, 0, 400], [300, 0, 400], [100, -2, 400]]
    with pytest.raises(CalibrationError) as e:
        workpiece_direct([500, 0, 300], T)
    assert e.value.loc == ("flange_poses", 2) and "from the X line" in e.value.reason


@pytest.mark.parametrize("r, n, patch, loc, words", [
    ([500, 0, np.nan], 3, None, ("fixed_tcp_mm", 2), "finite"),
    ([500, 0], 3, None, ("fixed_tcp_mm",), "shape"),
    ([500, 0, 300], 2, None, ("flange_poses",), "at least 3"),
    ([500, 0, 300], 4, None, ("flange_poses",), "exactly 3"),
    ([500, 0, 300], 3, "mirror", ("flange_poses", 1), "proper rotation"),
    ([500, 0, 300], 3, "nan", ("flange_poses", 2, 0, 3), "finite"),
])
def test_workpiece_direct_refuses_bad_input(r, n, patch, loc, words):
    T = np.stack([np.eye(4)] * n)
    T[:, :3, 3] = [[500, 0, 400], [300, 0, 400], [500, -150, 400], [400, 0, 400]][:n]
    if patch == "mirror":
        T[1, 2, 2] = -1
    if patch == "nan":
        T[2, 0, 3] = np.nan
    with pytest.raises(CalibrationError) as e:
        workpiece_direct(r, T)
    assert e.value.loc == loc and words in e.value.reason


# ---------------------------------------------------------------- workpiece.indirect

def test_workpiece_indirect_bring_known_points_to_fixed_tcp_then_frame(robot, rng):
    """Workpiece > Indirect: 8 known points, each on the fixed TCP, tilting between them."""
    T_fw, r, poses = brush_scene(robot, rng, SPREAD8)
    res = workpiece_indirect(r, poses, SPREAD8)
    assert res.method == "workpiece.indirect"
    dp, da = frame_errors(T_fw, res.frame)
    assert dp < 1e-4 and da < 1e-4
    assert res.report.max_error_mm < 1e-4 and res.report.bad_point is None


def test_workpiece_indirect_lecture_4point_matrix_equals_least_squares(rng):
    """Exact data: F_T_W = F_P [W_P]^-1 (lecture, 4 non-coplanar points) = the LSQ fit."""
    T_fw = random_workpiece(rng)
    R = random_rotation(rng)
    r = np.array([650.0, 120.0, 300.0])
    poses = np.stack([np.eye(4)] * 4)
    poses[:, :3, :3] = R  # the lecture holds the orientation
    poses[:, :3, 3] = [r - R @ ck for ck in apply(T_fw, FOUR)]
    F_P = np.vstack([(R.T @ (r - poses[:, :3, 3]).T), np.ones(4)])  # F_p_i = [R_Q_F]^-1 (t - f_i)
    W_P = np.vstack([FOUR.T, np.ones(4)])
    T_lecture = F_P @ np.linalg.inv(W_P)
    res = workpiece_indirect(r, poses, FOUR)
    assert np.allclose(T_lecture, res.frame, atol=1e-9)
    assert np.allclose(res.frame, T_fw, atol=1e-9)


def test_workpiece_indirect_coplanar_points_singular_for_lecture_fine_for_lsq(rng):
    """Four coplanar points: W_P has rank 3 (the lecture's inverse fails), the LSQ does not."""
    W_P = np.vstack([RECT4.T, np.ones(4)])
    assert np.linalg.matrix_rank(W_P) == 3
    T_fw, r, poses = brush_scene(ROBOTS["ur5e"], rng, RECT4)
    res = workpiece_indirect(r, poses, RECT4)
    assert np.allclose(res.frame, T_fw, atol=1e-4)


def noisy_brushes(rng):  # noqa: ANN001, ANN201
    """The 8 SPREAD8 points of a random workpiece brushed on a fixed TCP r from orientations
    tilted up to 20 deg, with 0.05 mm touch noise: (T_flange_workpiece, r, poses)."""
    T_fw = random_workpiece(rng)
    r = np.array([650.0, 120.0, 300.0])
    poses = []
    for ck in apply(T_fw, SPREAD8):
        T = np.eye(4)
        T[:3, :3] = random_rotation(rng, 20)
        T[:3, 3] = r - T[:3, :3] @ ck + rng.normal(0, 0.05, 3)
        poses.append(T)
    return T_fw, r, poses


def test_workpiece_indirect_noisy_within_bounds(rng):
    T_fw, r, poses = noisy_brushes(rng)
    res = workpiece_indirect(r, np.array(poses), SPREAD8, target_mm=[100, 75, 0])
    rep = res.report
    dp, da = frame_errors(T_fw, res.frame)  # the frame does not depend on target_mm
    assert dp < 2 * rep.position_bound95_mm and da < 2 * rep.angle_bound95_deg
    assert rep.tre_mm == rep.extras["tre_target_mm"] < rep.extras["tre_farthest_mm"]
    assert 0.02 < rep.sigma_mm < 0.09


def test_workpiece_indirect_names_a_3mm_bad_point_among_8(rng):
    """One of 8 touches is 3 mm off the fixed TCP: the report names that pose."""
    T_fw, r, poses = noisy_brushes(rng)
    poses[2][:3, 3] += [0.0, 3.0, 0.0]
    rep = workpiece_indirect(r, np.array(poses), SPREAD8).report
    assert rep.bad_point is not None and rep.bad_point.index == 2
    assert [w.loc for w in rep.warnings if w.code == "bad_point"] == [("flange_poses", 2)]
    dp, da = frame_errors(T_fw, rep.bad_point.refit_frame)
    assert dp < 0.2 and da < 0.1


def test_workpiece_indirect_refuses_collinear_known_points():
    line = np.array([[0, 0, 0], [100, 0, 0], [200, 0, 0], [300, 0, 0.0]])
    poses = np.stack([np.eye(4)] * 4)
    poses[:, :3, 3] = [500, 0, 400] - RECT4
    with pytest.raises(CalibrationError) as e:
        workpiece_indirect([500, 0, 300], poses, line)
    assert e.value.loc == ("known_mm",) and "one line" in e.value.reason


def test_workpiece_indirect_refuses_one_contact_point_four_times():
    poses = np.stack([np.eye(4)] * 4)
    poses[:, :3, 3] = [500, 0, 400]
    with pytest.raises(CalibrationError) as e:
        workpiece_indirect([500, 0, 300], poses, RECT4)
    assert e.value.loc == ("flange_poses",) and "centroid" in e.value.reason


@pytest.mark.parametrize("n_poses, known, loc, words", [
    (3, RECT4[:3], ("flange_poses",), "at least 4"),
    (4, SPREAD8[:5], ("known_mm",), "has 5 points but flange_poses has 4"),
    (4, np.where(np.arange(12).reshape(4, 3) == 4, np.nan, RECT4), ("known_mm", 1, 1), "finite"),
    (4, RECT4[:, :2], ("known_mm",), "shape"),
])
def test_workpiece_indirect_refuses_bad_input(n_poses, known, loc, words):
    poses = np.stack([np.eye(4)] * n_poses)
    poses[:, :3, 3] = ([500, 0, 400] - RECT4)[:n_poses]
    with pytest.raises(CalibrationError) as e:
        workpiece_indirect([500, 0, 300], poses, known)
    assert e.value.loc == loc and words in e.value.reason


def test_contact_points_are_the_touched_workpiece_points_in_flange(rng):
    T_fw = random_workpiece(rng)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = random_rotation(rng), [400, 200, 100]
    p_w = np.array([30.0, -20.0, 5.0])
    r = apply(T @ T_fw, p_w)  # that workpiece point sits on the fixed TCP
    assert np.allclose(contact_points_flange(r, T[None])[0], apply(T_fw, p_w))
    assert np.allclose(apply(invert(T_fw), contact_points_flange(r, T[None])[0]), p_w)
