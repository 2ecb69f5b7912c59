"""Base > 3-point / Indirect / Numeric: recover known base frames touched by every arm."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from solvers import dh
from solvers.base import (base_3point, base_indirect, base_numeric, fit_rigid, fitzpatrick_tre_mm,
                          frame_from_three_points, point_jacobian, pose_difference, register_points)
from solvers.errors import CalibrationError, KinematicsError
from solvers.frames import Pose, angle_between_deg, apply

TOOL_TCP_MM = np.array([0.0, 0.0, 120.0])  # the calibrated pointer on the flange
TOOL = np.eye(4)
TOOL[:3, 3] = TOOL_TCP_MM


# ---------------------------------------------------------------- helpers (also used by the
# fixed-tool and workpiece tests)

def random_q(robot, rng, margin=0.5):
    lim = robot.limits_deg() * margin
    return rng.uniform(lim[:, 0], lim[:, 1])


def random_rotation(rng, max_deg=180.0):
    """A random rotation of at most ``max_deg`` (uniform axis)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return Rotation.from_rotvec(np.radians(rng.uniform(0, max_deg)) * axis).as_matrix()


def reach(robot, rng, make_goals, tool=None, position_only=False, tries=40):
    """Joint values reaching every goal of ``make_goals(T_start)`` from one random start.

    ``T_start`` is FK of a random pose (with ``tool``); goals are 4x4 targets for the same
    ``tool``. Retries from another start when a goal is out of reach. Returns
    (T_start, goals, q_list).
    """
    for _ in range(tries):
        q0 = random_q(robot, rng)
        T0 = dh.forward_kinematics(robot, q0, tool)
        goals = make_goals(T0)
        try:
            qs = [dh.inverse_kinematics(robot, G, q0, tool=tool, position_only=position_only) for G in goals]
        except KinematicsError:
            continue
        return T0, goals, qs
    raise AssertionError(f"{robot.name}: no reachable layout in {tries} tries")


def touched_points(robot, rng, local_mm, frame_rot=None):
    """A random true frame in reach of ``robot`` and its points ``local_mm`` touched with the
    calibrated pointer: returns (T_world_frame, measured points from FK of the IK solutions)."""
    R = random_rotation(rng) if frame_rot is None else frame_rot
    truth = {}

    def goals(T0):
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = T0[:3, 3] - R @ local_mm.mean(axis=0)  # centre the points on the start TCP
        truth["T"] = T
        out = []
        for p in apply(T, local_mm):
            G = T0.copy()
            G[:3, 3] = p
            out.append(G)
        return out

    _, _, qs = reach(robot, rng, goals, tool=TOOL, position_only=True)
    measured = np.array([dh.tcp_of(dh.forward_kinematics(robot, q), TOOL_TCP_MM) for q in qs])
    return truth["T"], measured


def frame_errors(T_true, T):
    """(position error mm, angle error deg)."""
    return float(np.linalg.norm(T[:3, 3] - T_true[:3, 3])), float(angle_between_deg(T_true[:3, :3], T[:3, :3]))


RECT = np.array([[0, 0, 0], [150, 0, 0], [150, 100, 0], [0, 100, 0], [75, 50, 0.0]])
SPREAD8 = np.array([[0, 0, 0], [200, 0, 0], [200, 150, 0], [0, 150, 0],
                    [100, 75, 60], [40, 120, 30], [170, 30, 20], [100, 0, 80.0]])
THREE = np.array([[0, 0, 0], [180, 0, 0], [60, 140, 0.0]])


# ---------------------------------------------------------------- base.3point

def test_base_3point_touch_origin_x_and_xy_then_frame(robot, rng):
    """Base > 3-point: touch origin, +X, XY with a calibrated pointer; the frame comes back."""
    T_true, P = touched_points(robot, rng, THREE)
    res = base_3point(*P)
    dp, da = frame_errors(T_true, res.frame)
    assert res.method == "base.3point"
    assert dp < 1e-3 and da < 1e-3
    assert res.report.max_error_mm == 0.0
    assert res.report.parameter_names == ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")


def test_base_3point_xy_point_anywhere_on_plus_y_side(rng):
    """P3 need not be on the Y axis, and a P3 on the -X side still gives +Y towards P3."""
    for p3 in ([300, 50, 0], [-80, 200, 0], [10, 400, 0]):
        T = base_3point([0, 0, 0], [250, 0, 0], p3).frame
        assert np.allclose(T[:3, :3], np.eye(3), atol=1e-12)


def test_base_3point_noisy_touches_within_stated_sensitivity(rng):
    """Noisy touch-ups (0.05 mm) stay inside the predicted 95% bounds; the predicted angle
    sigma matches a Monte Carlo of 2000 trials within 10%."""
    R = random_rotation(rng)
    T_true = np.eye(4)
    T_true[:3, :3], T_true[:3, 3] = R, [700, 100, 300]
    P = apply(T_true, THREE)
    rep = base_3point(*P, touch_sigma_mm=0.05).report
    d = np.array([pose_difference(T_true, frame_from_three_points(*(P + rng.normal(0, 0.05, P.shape))))
                  for _ in range(2000)])
    assert np.allclose(d.std(axis=0), np.sqrt(np.diag(rep.covariance)), rtol=0.1)
    inside = np.linalg.norm(d[:, 3:], axis=1) <= rep.angle_bound95_deg
    assert 0.93 <= inside.mean() <= 0.97  # the bound is a 95 % bound, not a loose one
    assert rep.sigma_source == "assumed" and rep.dof is None
    assert rep.extras["x_lever_mm"] == pytest.approx(180.0)
    assert rep.extras["xy_lever_mm"] == pytest.approx(140.0)


def test_base_3point_short_lever_warns():
    rep = base_3point([0, 0, 0], [40, 0, 0], [0, 300, 0]).report
    assert [w.code for w in rep.warnings] == ["short_lever", "assumed_sigma"]
    assert rep.warnings[0].loc == ("x_point_mm",)


def test_base_3point_refuses_points_too_close():
    with pytest.raises(CalibrationError) as e:
        base_3point([100, 0, 0], [104, 3, 0], [100, 200, 0])
    assert e.value.loc == ("x_point_mm",)
    assert "5.00 mm from the origin" in e.value.reason
    with pytest.raises(CalibrationError) as e:
        base_3point([100, 0, 0], [300, 0, 0], [302, 1, 0])
    assert e.value.loc == ("xy_point_mm",) and "from the X point" in e.value.reason


def test_base_3point_refuses_collinear_points():
    with pytest.raises(CalibrationError) as e:
        base_3point([0, 0, 0], [200, 0, 0], [500, 4, 3])
    assert e.value.loc == ("xy_point_mm",)
    assert "5.00 mm from the X line" in e.value.reason and "0.57 deg" in e.value.reason


@pytest.mark.parametrize("args, loc", [
    (([0, np.nan, 0], [200, 0, 0], [0, 200, 0]), ("origin_mm", 1)),
    (([0, 0, 0], [200, 0], [0, 200, 0]), ("x_point_mm",)),
    (([0, 0, 0], [200, 0, 0], [[0, 200, 0]]), ("xy_point_mm",)),
    (([0, 0, 0], [200, 0, 0], [0, np.inf, 0]), ("xy_point_mm", 1)),
])
def test_base_3point_refuses_nan_and_wrong_shapes(args, loc):
    with pytest.raises(CalibrationError) as e:
        base_3point(*args)
    assert e.value.loc == loc


def test_base_3point_refuses_negative_touch_sigma():
    with pytest.raises(CalibrationError) as e:
        base_3point([0, 0, 0], [200, 0, 0], [0, 200, 0], touch_sigma_mm=-1)
    assert e.value.loc == ("touch_sigma_mm",)


# ---------------------------------------------------------------- base.indirect

def test_base_indirect_touch_known_points_then_frame(robot, rng):
    """Base > Indirect: touch 5 points known in the base (coplanar); the frame comes back."""
    T_true, M = touched_points(robot, rng, RECT)
    res = base_indirect(M, RECT)
    dp, da = frame_errors(T_true, res.frame)
    assert res.method == "base.indirect"
    assert dp < 1e-3 and da < 1e-3
    assert res.report.max_error_mm < 1e-3
    assert res.report.bad_point is None


def test_base_indirect_noisy_within_bounds_and_tre_matches_monte_carlo(rng):
    """0.05 mm noise on 8 points: the covariance and Fitzpatrick's TRE match 1000 trials."""
    sigma = 0.05
    T_true = np.eye(4)
    T_true[:3, :3], T_true[:3, 3] = random_rotation(rng), [600, -200, 100]
    M0 = apply(T_true, SPREAD8)
    target = np.array([400.0, 300.0, 0.0])  # a point outside the taught region
    errs, tre_err, cent_err = [], [], []
    for _ in range(1000):
        T = fit_rigid(SPREAD8, M0 + rng.normal(0, sigma, M0.shape))
        errs.append(pose_difference(T_true, T))
        tre_err.append(np.linalg.norm(apply(T, target) - apply(T_true, target)))
        cent_err.append(np.linalg.norm(apply(T, SPREAD8.mean(0)) - apply(T_true, SPREAD8.mean(0))))
    res = base_indirect(M0 + rng.normal(0, sigma, M0.shape), SPREAD8, target_mm=target)
    rep = res.report
    assert rep.sigma_mm == pytest.approx(sigma, rel=0.4)
    # the covariance the report uses, rescaled to the true sigma, against the trials
    cov = rep.covariance * (sigma / rep.sigma_mm) ** 2
    assert np.allclose(np.std(errs, axis=0), np.sqrt(np.diag(cov)), rtol=0.1)
    scale = sigma / rep.sigma_mm
    assert rep.tre_mm * scale == pytest.approx(np.sqrt(np.mean(np.square(tre_err))), rel=0.1)
    assert rep.extras["tre_centroid_mm"] * scale == pytest.approx(np.sqrt(np.mean(np.square(cent_err))), rel=0.1)
    dp, da = frame_errors(T_true, res.frame)
    assert dp < 2 * rep.position_bound95_mm and da < 2 * rep.angle_bound95_deg


def test_base_indirect_fitzpatrick_tre_equals_covariance_propagation(rng):
    """TRE² from Fitzpatrick's formula = trace of the pose covariance carried to the target."""
    K = SPREAD8
    T = np.eye(4)
    T[:3, :3] = random_rotation(rng)
    sigma = 0.07
    J = point_jacobian(T, K).reshape(-1, 6)
    cov = sigma**2 * np.linalg.inv(J.T @ J)
    targets = rng.uniform(-500, 500, (6, 3))
    for r in targets:
        Jr = point_jacobian(T, r)[0]
        tre_cov = np.sqrt(np.trace(Jr @ cov @ Jr.T))
        assert fitzpatrick_tre_mm(K, np.sqrt(3) * sigma, r) == pytest.approx(tre_cov, rel=1e-9)


def test_base_indirect_names_a_3mm_bad_point_among_8(rng):
    """Base > Indirect: one of 8 touches is 3 mm off; the report names it and refits without it."""
    T_true = np.eye(4)
    T_true[:3, :3], T_true[:3, 3] = random_rotation(rng), [500, 300, 50]
    M = apply(T_true, SPREAD8) + rng.normal(0, 0.05, SPREAD8.shape)
    M[5] += 3.0 * np.array([0.6, -0.8, 0.0])
    rep = base_indirect(M, SPREAD8).report
    assert rep.bad_point is not None and rep.bad_point.index == 5
    assert rep.worst_point == 5
    assert rep.guidance == "re-teach point 6"
    assert [w.loc for w in rep.warnings if w.code == "bad_point"] == [("measured_mm", 5)]
    dp, da = frame_errors(T_true, rep.bad_point.refit_frame)
    assert dp < 0.2 and da < 0.05
    assert rep.bad_point.refit_rms_mm < 0.15


def test_base_indirect_no_bad_point_in_clean_noise(rng):
    T_true = np.eye(4)
    T_true[:3, 3] = [500, 300, 50]
    M = apply(T_true, SPREAD8) + rng.normal(0, 0.05, SPREAD8.shape)
    assert base_indirect(M, SPREAD8).report.bad_point is None


def test_base_indirect_target_default_is_farthest_point():
    K = SPREAD8
    rep = base_indirect(K + 10.0, K).report
    assert rep.tre_mm == rep.extras["tre_farthest_mm"] > rep.extras["tre_centroid_mm"]
    # exact data: the scatter floor (0.01 mm) gives FLE = sqrt(3) * 0.01 and TRE(centroid) = FLE/sqrt(N)
    assert rep.extras["tre_centroid_mm"] == pytest.approx(np.sqrt(3) * 0.01 / np.sqrt(8))


def test_base_indirect_refuses_collinear_points():
    line = np.array([[0, 0, 0], [100, 0, 0], [200, 0, 0], [300, 0.2, 0.1]])
    with pytest.raises(CalibrationError) as e:
        base_indirect(line + 5, line)
    assert e.value.loc == ("known_mm",) and "one line" in e.value.reason
    with pytest.raises(CalibrationError) as e:
        base_indirect(line, RECT[:4])
    assert e.value.loc == ("measured_mm",) and "one line" in e.value.reason


def test_base_indirect_refuses_coincident_points():
    K = np.zeros((4, 3)) + [10.0, 20.0, 30.0]
    with pytest.raises(CalibrationError) as e:
        base_indirect(RECT[:4], K)
    assert e.value.loc == ("known_mm",) and "centroid" in e.value.reason


@pytest.mark.parametrize("measured, known, loc, words", [
    (RECT[:3], RECT[:3], ("known_mm",), "at least 4"),
    (RECT[:4], RECT, ("known_mm",), "has 5 points"),
    (RECT[:, :2], RECT[:, :2], ("known_mm",), "shape"),
    (np.where(np.arange(15).reshape(5, 3) == 7, np.nan, RECT), RECT, ("measured_mm", 2, 1), "finite"),
])
def test_base_indirect_refuses_bad_input(measured, known, loc, words):
    with pytest.raises(CalibrationError) as e:
        base_indirect(measured, known)
    assert e.value.loc == loc and words in e.value.reason


def test_base_indirect_four_points_flags_few_points():
    rep = base_indirect(RECT[:4] + 1, RECT[:4]).report
    assert "few_points" in [w.code for w in rep.warnings]
    assert rep.bad_point is None


def test_register_points_coplanar_is_fine(rng):
    """Coplanar points (rank 2) fix the rotation; only collinear ones are singular."""
    T_true = np.eye(4)
    T_true[:3, :3] = random_rotation(rng)
    T, rep = register_points(apply(T_true, RECT), RECT)
    assert np.allclose(T, T_true, atol=1e-9)
    assert np.all(np.isfinite(rep.covariance))


# ---------------------------------------------------------------- base.numeric

def test_base_numeric_type_pose_then_frame():
    res = base_numeric(Pose(1200, -300, 0, 90, 0, 180))
    assert res.method == "base.numeric"
    assert Pose.from_matrix(res.frame) == Pose(1200, -300, 0, 90, 0, 180)
    assert res.report.max_error_mm == 0.0


def test_base_numeric_refuses_nan():
    with pytest.raises(CalibrationError) as e:
        base_numeric(Pose(0, 0, 0, float("nan"), 0, 0))
    assert e.value.loc == ("pose", 3)


@settings(max_examples=60, deadline=None)
@given(rotvec=st.lists(st.floats(-np.pi, np.pi), min_size=3, max_size=3),
       shift=st.lists(st.floats(-2000, 2000), min_size=3, max_size=3),
       coplanar=st.booleans())
def test_fit_rigid_recovers_any_rotation_including_half_turns(rotvec, shift, coplanar):
    """Every rotation (half turns too) and shift comes back, coplanar layouts included."""
    K = RECT if coplanar else SPREAD8
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Rotation.from_rotvec(rotvec).as_matrix(), shift
    assert np.allclose(fit_rigid(K, apply(T, K)), T, atol=1e-8)
