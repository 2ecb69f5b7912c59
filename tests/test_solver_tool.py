"""Tool menus (Start-up > Calibrate > Tool): XYZ 4-point, XYZ reference, ABC world, ABC 2-point,
numeric. Each test walks one menu: touch-ups in, TCP / orientation and report out."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solvers.dh import forward_kinematics, inverse_kinematics
from solvers.errors import CalibrationError, KinematicsError
from solvers.frames import Pose, angle_between_deg, matrix_from_kuka, translation
from solvers.tcp import (next_tcp_orientation, tcp_xyz_4point, tcp_xyz_reference, tool_abc_2point,
                         tool_abc_world, tool_numeric)

TIP = np.array([600.0, 80.0, 150.0])  # the fixed point in the cell (base, mm)
DOWN = Rotation.from_euler("x", 180, degrees=True)  # flange z pointing down


def rot(axis: str, deg: float) -> Rotation:
    return Rotation.from_euler(axis, deg, degrees=True)


def touch_ups(tcp_mm, rotations, point=TIP, noise_mm=0.0, rng=None) -> np.ndarray:
    """Flange poses that put the TCP on ``point``: p_k = s + e_k - R_k t (e_k: touch noise)."""
    R = np.stack([r.as_matrix() for r in rotations])
    T = np.tile(np.eye(4), (len(R), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = point - R @ np.asarray(tcp_mm, dtype=float)
    if noise_mm:
        T[:, :3, 3] += rng.normal(0.0, noise_mm, (len(R), 3))
    return T


def cone(n: int, tilt_deg: float = 35.0, twist_deg: float = 30.0, start_deg: float = 0.0) -> list:
    """n orientations tilted ``tilt_deg`` from straight down around a cone, with some twist."""
    out = []
    for k in range(n):
        az = np.radians(start_deg + 360.0 * k / n)
        tilt = Rotation.from_rotvec(np.radians(tilt_deg) * np.array([np.cos(az), np.sin(az), 0.0]))
        out.append(tilt * DOWN * rot("z", twist_deg * np.sin(3 * az)))
    return out


def random_tcp(rng) -> np.ndarray:
    return np.array([rng.uniform(-60, 60), rng.uniform(-60, 60), rng.uniform(80, 300)])


# --------------------------------------------------------------------------- XYZ 4-point


def test_xyz_4point_recovers_tcp_taught_on_each_robot(robot, rng):
    """Tool > XYZ 4-point on a real arm: jog the new tool's tip onto one point from tilted
    orientations (inverse kinematics), touch up each; the TCP comes back exactly."""
    t = random_tcp(rng)
    tool = translation(t)
    lim = robot.limits_deg()
    for _attempt in range(20):
        q0 = rng.uniform(0.25 * lim[:, 0], 0.25 * lim[:, 1])
        q0[1:3] += rng.uniform(-20, 20, 2)
        T0 = forward_kinematics(robot, q0, tool)
        poses = []
        for k in range(6):
            az = 2 * np.pi * k / 6
            tilt = Rotation.from_rotvec(np.radians(30.0) * np.array([np.cos(az), np.sin(az), 0]))
            goal = T0.copy()
            goal[:3, :3] = tilt.as_matrix() @ T0[:3, :3]
            try:
                q = inverse_kinematics(robot, goal, q0, tool=tool)
            except KinematicsError:
                continue
            poses.append(forward_kinematics(robot, q))
        if len(poses) >= 4:
            break
    assert len(poses) >= 4, f"{robot.name}: no reachable touch-ups"
    res = tcp_xyz_4point(np.stack(poses))
    assert res.method == "tool.xyz_4point"
    assert res.frame[:3, 3] == pytest.approx(t, abs=1e-4)
    assert np.allclose(res.frame[:3, :3], np.eye(3))
    assert res.report.extras["point_mm"] == pytest.approx(T0[:3, 3], abs=1e-4)
    assert res.report.max_error_mm < 1e-4


def test_xyz_4point_exact_on_random_tcps(rng):
    for _ in range(20):
        t = random_tcp(rng)
        res = tcp_xyz_4point(touch_ups(t, cone(4, tilt_deg=rng.uniform(25, 45))))
        assert res.frame[:3, 3] == pytest.approx(t, abs=1e-8)
        assert res.report.extras["point_mm"] == pytest.approx(TIP, abs=1e-8)
        assert res.report.rms_error_mm < 1e-8
        assert res.report.bad_point is None


def test_xyz_4point_noisy_tcp_within_stated_95_bound_most_of_the_time(rng):
    """Touch noise 0.05 mm: the TCP error stays inside position_bound95_mm in >= 90% of runs."""
    t = np.array([12.0, -30.0, 210.0])
    inside, trials = 0, 300
    for _ in range(trials):
        res = tcp_xyz_4point(touch_ups(t, cone(8), noise_mm=0.05, rng=rng))
        inside += np.linalg.norm(res.frame[:3, 3] - t) <= res.report.position_bound95_mm
        assert res.report.sigma_mm == pytest.approx(0.05, rel=0.6)
    assert inside / trials >= 0.90


def test_xyz_4point_estimate_is_unbiased_and_covariance_matches_scatter(rng):
    t = np.array([0.0, 25.0, 180.0])
    rots = cone(6)
    est = np.array([tcp_xyz_4point(touch_ups(t, rots, noise_mm=0.05, rng=rng)).frame[:3, 3]
                    for _ in range(400)])
    err = est - t
    assert np.all(np.abs(err.mean(axis=0)) < 4 * err.std(axis=0) / np.sqrt(len(err)))
    # the report's covariance at the true sigma is the Cramér–Rao bound; scatter matches it
    cov_true = tcp_xyz_4point(touch_ups(t, rots)).report.covariance * (0.05 / 0.01) ** 2
    assert np.trace(np.cov(err.T)) == pytest.approx(np.trace(cov_true), rel=0.2)


def test_xyz_4point_covariance_is_the_inverse_fisher_information_block():
    """Cov(t) = sigma²/N (I - R̄ᵀR̄)^-1 equals the t block of sigma² (Σ [R_k, -I]ᵀ[R_k, -I])^-1."""
    rots = cone(5, tilt_deg=25)
    res = tcp_xyz_4point(touch_ups([4, 4, 140], rots))
    R = np.stack([r.as_matrix() for r in rots])
    A = np.concatenate([R, -np.broadcast_to(np.eye(3), R.shape)], axis=2)
    F = np.einsum("kai,kaj->ij", A, A) / res.report.sigma_mm**2
    assert np.allclose(res.report.covariance, np.linalg.inv(F)[:3, :3], rtol=1e-9, atol=1e-15)
    assert np.allclose(res.report.extras["point_covariance_mm2"], np.linalg.inv(F)[3:, 3:],
                       rtol=1e-9, atol=1e-15)


def test_xyz_4point_refuses_one_orientation_four_times():
    T = touch_ups([0, 0, 150], [DOWN] * 4)
    with pytest.raises(CalibrationError) as e:
        tcp_xyz_4point(T)
    assert e.value.loc == ("flange_poses",)
    assert "orientation" in e.value.reason and "0.0 deg" in e.value.reason


def test_xyz_4point_orientations_within_a_degree_refused_with_spread():
    T = touch_ups([0, 0, 150], [DOWN * rot("x", a) for a in (0, 0.5, 1.0, 1.5)])
    with pytest.raises(CalibrationError, match=r"within 1\.5 deg"):
        tcp_xyz_4point(T)


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_xyz_4point_rotations_about_one_axis_name_the_unobservable_direction(axis):
    """Rotating only about flange z (A6) leaves the TCP's z unknown: the menu says so."""
    T = touch_ups([5, -5, 150], [DOWN * rot(axis, a) for a in (0, 60, 120, 170)])
    with pytest.raises(CalibrationError) as e:
        tcp_xyz_4point(T)
    assert e.value.loc == ("flange_poses",)
    assert f"along the flange {axis} axis cannot be determined" in e.value.reason
    assert "rotate about one axis" in e.value.reason
    assert "missing" in e.value.reason and "spread 170.0 deg" in e.value.reason


def test_xyz_4point_small_tilt_warns_and_names_the_weak_direction():
    rots = [DOWN * rot("z", a) * rot("x", b) for a, b in ((0, 0), (90, 3), (180, 0), (270, -3))]
    res = tcp_xyz_4point(touch_ups([0, 0, 150], rots))
    codes = {w.code: w for w in res.report.warnings}
    assert "weak_observability" in codes
    assert "flange z axis" in codes["weak_observability"].message
    assert res.frame[:3, 3] == pytest.approx([0, 0, 150], abs=1e-6)


def test_xyz_4point_names_the_one_bad_touch_up_among_eight(rng):
    """One touch-up 3 mm off: it is named, with the TCP fitted without it beside."""
    t = np.array([-8.0, 14.0, 175.0])
    T = touch_ups(t, cone(8), noise_mm=0.05, rng=rng)
    T[5, :3, 3] += 3.0 * np.array([0.6, 0.0, 0.8])
    res = tcp_xyz_4point(T)
    bad = res.report.bad_point
    assert bad is not None and bad.index == 5
    assert bad.residual_mm > 2.0
    assert bad.refit_frame[:3, 3] == pytest.approx(t, abs=0.2)
    assert bad.refit_rms_mm < 0.15
    finding = [w for w in res.report.warnings if w.code == "bad_point"][0]
    assert finding.loc == ("flange_poses", 5) and "point 6" in finding.message


def test_xyz_4point_and_reference_warn_when_all_touch_ups_scatter(rng):
    T = touch_ups([0, 0, 150], cone(6), noise_mm=1.5, rng=rng)
    assert any(w.code == "large_residual" for w in tcp_xyz_4point(T).report.warnings)
    assert any(w.code == "large_residual" for w in tcp_xyz_reference(TIP, T).report.warnings)


def test_xyz_4point_clean_noisy_data_has_no_bad_point(rng):
    hits = sum(tcp_xyz_4point(touch_ups([0, 0, 200], cone(8), noise_mm=0.05, rng=rng))
               .report.bad_point is not None for _ in range(50))
    assert hits <= 2


def test_xyz_4point_nan_named_by_index():
    T = touch_ups([0, 0, 150], cone(4))
    T[2, 1, 3] = np.nan
    with pytest.raises(CalibrationError) as e:
        tcp_xyz_4point(T)
    assert e.value.loc == ("flange_poses", 2, 1, 3)
    assert "finite" in e.value.reason


def test_xyz_4point_needs_four_touch_ups():
    with pytest.raises(CalibrationError, match="at least 4") as e:
        tcp_xyz_4point(touch_ups([0, 0, 150], cone(3)))
    assert e.value.loc == ("flange_poses",)


def test_xyz_4point_rejects_a_non_rigid_pose_by_index():
    T = touch_ups([0, 0, 150], cone(5))
    T[3, :3, :3] *= 1.01
    with pytest.raises(CalibrationError, match="rotation") as e:
        tcp_xyz_4point(T)
    assert e.value.loc == ("flange_poses", 3)
    with pytest.raises(CalibrationError, match="shape"):
        tcp_xyz_4point(np.zeros((4, 3, 4)))


def test_xyz_4point_rejects_a_mirrored_pose_and_a_bad_last_row():
    T = touch_ups([0, 0, 150], cone(5))
    T[1, :3, 0] *= -1  # orthonormal but a reflection
    with pytest.raises(CalibrationError, match="proper rotation") as e:
        tcp_xyz_4point(T)
    assert e.value.loc == ("flange_poses", 1)
    T = touch_ups([0, 0, 150], cone(5))
    T[4, 3, 0] = 0.5
    with pytest.raises(CalibrationError, match="last row") as e:
        tcp_xyz_4point(T)
    assert e.value.loc == ("flange_poses", 4)


def test_xyz_4point_report_fields():
    res = tcp_xyz_4point(touch_ups([0, 10, 150], cone(6)))
    rep = res.report
    assert rep.parameter_names == ("x_mm", "y_mm", "z_mm") and rep.covariance.shape == (3, 3)
    assert rep.sigma_mm == pytest.approx(0.01)  # noise-free: the floor
    assert rep.position_bound95_mm > 0 and rep.residuals_mm.shape == (6,)
    assert rep.extras["spread_deg"] > 30 and min(rep.extras["tilt_deg"]) > 10
    assert rep.warnings == ()


def test_xyz_4point_flags_a_repeated_touch_up():
    rots = cone(4)
    T = touch_ups([0, 0, 150], rots + [rots[1]])
    res = tcp_xyz_4point(T)
    dup = [w for w in res.report.warnings if w.code == "duplicate_touch_up"]
    assert dup and dup[0].loc == ("flange_poses", 4)


def test_next_orientation_guides_towards_the_missing_rotation():
    """After rotating only about A6 the pendant suggests a tilt; touching up there solves it."""
    t = np.array([3.0, -4.0, 160.0])
    rots = [DOWN * rot("z", a) for a in (0, 90, 180)]
    R_next = next_tcp_orientation(touch_ups(t, rots))
    nearest = min(angle_between_deg(R_next, r.as_matrix()) for r in rots)
    assert nearest == pytest.approx(45, abs=1)  # a 45 deg tilt of one of the touch-ups
    res = tcp_xyz_4point(touch_ups(t, rots + [Rotation.from_matrix(R_next)]))
    assert res.frame[:3, 3] == pytest.approx(t, abs=1e-8)
    assert "tilt" in res.report.guidance
    assert res.report.next_orientation.shape == (3, 3)


def test_next_orientation_beats_random_tilts(rng):
    """The suggested touch-up shrinks trace Cov(t) at least as much as 20 random 30-45 deg tilts."""
    t = np.array([0.0, 0.0, 150.0])
    rots = cone(4, tilt_deg=20)
    R_next = Rotation.from_matrix(next_tcp_orientation(touch_ups(t, rots)))
    best = np.trace(tcp_xyz_4point(touch_ups(t, rots + [R_next])).report.covariance)
    for _ in range(20):
        axis = rng.normal(size=3)
        tilt = Rotation.from_rotvec(np.radians(rng.uniform(30, 45)) * axis / np.linalg.norm(axis))
        other = np.trace(tcp_xyz_4point(touch_ups(t, rots + [rots[0] * tilt])).report.covariance)
        assert best <= other * 1.05


def test_next_orientation_from_a_single_touch_up_is_a_tilt():
    R_next = next_tcp_orientation(touch_ups([0, 0, 150], [DOWN]))
    assert angle_between_deg(R_next, DOWN.as_matrix()) == pytest.approx(45, abs=1e-6)


def test_next_orientation_rejects_nan():
    T = touch_ups([0, 0, 150], cone(2))
    T[1, 0, 0] = np.inf
    with pytest.raises(CalibrationError) as e:
        next_tcp_orientation(T)
    assert e.value.loc == ("flange_poses", 1, 0, 0)


# --------------------------------------------------------------------------- XYZ reference


def test_xyz_reference_recovers_tcp_from_one_touch_up(rng):
    for _ in range(10):
        t = random_tcp(rng)
        res = tcp_xyz_reference(TIP, touch_ups(t, cone(1, tilt_deg=rng.uniform(0, 40))))
        assert res.method == "tool.xyz_reference"
        assert res.frame[:3, 3] == pytest.approx(t, abs=1e-9)
        assert res.report.extras["point_mm"] == pytest.approx(TIP)
        assert any(w.code == "single_touch" for w in res.report.warnings)


def test_xyz_reference_noisy_within_bound_and_names_a_bad_touch(rng):
    t = np.array([20.0, 0.0, 120.0])
    inside = 0
    for _ in range(200):
        res = tcp_xyz_reference(TIP, touch_ups(t, cone(6), noise_mm=0.05, rng=rng))
        inside += np.linalg.norm(res.frame[:3, 3] - t) <= res.report.position_bound95_mm
    assert inside >= 180
    T = touch_ups(t, cone(6), noise_mm=0.05, rng=rng)
    T[2, :3, 3] += [0, 3.0, 0]
    res = tcp_xyz_reference(TIP, T)
    assert res.report.bad_point is not None and res.report.bad_point.index == 2
    assert res.report.bad_point.refit_frame[:3, 3] == pytest.approx(t, abs=0.2)


def test_xyz_reference_errors_name_the_field():
    T = touch_ups([0, 0, 100], cone(2))
    with pytest.raises(CalibrationError) as e:
        tcp_xyz_reference([1.0, np.nan, 2.0], T)
    assert e.value.loc == ("reference_point_mm", 1)
    with pytest.raises(CalibrationError, match="at least 1"):
        tcp_xyz_reference(TIP, np.zeros((0, 4, 4)))
    with pytest.raises(CalibrationError, match="reference point") as e:
        tcp_xyz_reference(TIP + [9000.0, 0, 0], T)
    assert e.value.loc == ("flange_poses",)


# --------------------------------------------------------------------------- ABC World


def _random_tool_rotation(rng) -> np.ndarray:
    return Rotation.from_rotvec(np.radians(rng.uniform(0, 60)) * Rotation.random(
        random_state=int(rng.integers(1 << 30))).apply([0, 0, 1])).as_matrix()


def test_abc_world_6d_recovers_tool_orientation(rng):
    """Tool axis jogged to point down (world -Z), tool +X along world +X: the ABC come back."""
    R_world_tool = np.diag([1.0, -1.0, -1.0])
    for _ in range(10):
        R_ft = _random_tool_rotation(rng)
        t = random_tcp(rng)
        T_wf = np.eye(4)
        T_wf[:3, :3] = R_world_tool @ R_ft.T
        T_wf[:3, 3] = [500, 100, 300]
        res = tool_abc_world(T_wf, t, "6d")
        assert res.method == "tool.abc_world_6d"
        assert np.allclose(res.frame[:3, :3], R_ft, atol=1e-12)
        assert res.frame[:3, 3] == pytest.approx(t)


def test_abc_world_5d_recovers_axis_with_least_twist(rng):
    for _ in range(10):
        R_ft = _random_tool_rotation(rng)
        twist = rot("z", rng.uniform(-180, 180)).as_matrix()  # 5D cannot see a twist about -Z
        T_wf = np.eye(4)
        T_wf[:3, :3] = twist @ np.diag([1.0, -1.0, -1.0]) @ R_ft.T
        res = tool_abc_world(Pose.from_matrix(T_wf), [0, 0, 150], "5d")
        z = res.frame[:3, 2]
        assert z == pytest.approx(R_ft[:, 2], abs=1e-9)
        # least twist: the rotation angle equals the tilt of the axis from flange z
        tilt = np.degrees(np.arccos(np.clip(z[2], -1, 1)))
        assert angle_between_deg(np.eye(3), res.frame[:3, :3]) == pytest.approx(tilt, abs=1e-6)
        assert res.report.extras["axis_tilt_deg"] == pytest.approx(tilt)


def test_abc_world_straight_tool_gives_identity_and_reversed_axis_warns():
    res = tool_abc_world(matrix_from_kuka([500, 0, 400, 0, 180, 0]), [0, 0, 150], "5d")
    assert np.allclose(res.frame[:3, :3], np.eye(3))
    res = tool_abc_world(matrix_from_kuka([500, 0, 400, 0, 0, 0]), [0, 0, 150], "5d")
    assert res.frame[:3, 2] == pytest.approx([0, 0, -1])
    assert any(w.code == "axis_points_back" for w in res.report.warnings)


def test_abc_world_errors_name_the_field():
    T = matrix_from_kuka([500, 0, 400, 0, 180, 0])
    with pytest.raises(CalibrationError) as e:
        tool_abc_world(T, [0, 0, 150], "7d")
    assert e.value.loc == ("mode",)
    with pytest.raises(CalibrationError) as e:
        tool_abc_world(T, [0, 0, 9000], "6d")
    assert e.value.loc == ("tcp_mm", 2)
    bad = T.copy()
    bad[0, 3] = np.nan
    with pytest.raises(CalibrationError) as e:
        tool_abc_world(bad, [0, 0, 150], "6d")
    assert e.value.loc == ("flange_pose", 0, 3)
    bad = T.copy()
    bad[:3, 0] *= -1
    with pytest.raises(CalibrationError, match="rotation") as e:
        tool_abc_world(bad, [0, 0, 150], "6d")
    assert e.value.loc == ("flange_pose",)
    bad = T.copy()
    bad[3, 0] = 1.0
    with pytest.raises(CalibrationError, match="last row"):
        tool_abc_world(bad, [0, 0, 150], "5d")


# --------------------------------------------------------------------------- ABC 2-point


def two_point_poses(R_ft, t, lever_mm=80.0, side_mm=40.0, rng=None):
    """Touch-ups of the reference point: TCP, a point on the axis behind it, a +X plane point."""
    z, x = R_ft[:, 2], R_ft[:, 0]
    points = [t, t - lever_mm * z, t + side_mm * x - 30.0 * z]
    rots = [DOWN * rot("z", 10), DOWN * rot("x", 20), DOWN * rot("y", -25)]
    R = np.stack([r.as_matrix() for r in rots])
    T = np.tile(np.eye(4), (3, 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = [TIP - R[k] @ points[k] for k in range(3)]
    return T


def test_abc_2point_recovers_tool_orientation(rng):
    for _ in range(10):
        R_ft = _random_tool_rotation(rng)
        t = random_tcp(rng)
        res = tool_abc_2point(t, two_point_poses(R_ft, t))
        assert res.method == "tool.abc_2point"
        assert np.allclose(res.frame[:3, :3], R_ft, atol=1e-9)
        assert res.frame[:3, 3] == pytest.approx(t)
        assert res.report.extras["lever_mm"] == pytest.approx(80.0)
        assert 0 < res.report.angle_bound95_deg < 1.0


def test_abc_2point_bound_covers_touch_noise(rng):
    R_ft, t = _random_tool_rotation(rng), np.array([0, 0, 150.0])
    T0 = two_point_poses(R_ft, t)
    bound = tool_abc_2point(t, T0).report.angle_bound95_deg
    errs = []
    for _ in range(300):
        T = T0.copy()
        T[:, :3, 3] += rng.normal(0, 0.05, (3, 3))
        errs.append(angle_between_deg(tool_abc_2point(t, T).frame[:3, :3], R_ft))
    assert np.mean(np.array(errs) <= bound) >= 0.9


def test_abc_2point_errors_name_the_touch_up():
    t = np.array([0, 0, 150.0])
    with pytest.raises(CalibrationError, match="from the TCP") as e:
        tool_abc_2point(t, two_point_poses(np.eye(3), t, lever_mm=2.0))
    assert e.value.loc == ("flange_poses", 1)
    T = two_point_poses(np.eye(3), t)
    T[2] = T[1]  # plane point on the axis
    with pytest.raises(CalibrationError, match="on the tool axis") as e:
        tool_abc_2point(t, T)
    assert e.value.loc == ("flange_poses", 2)
    with pytest.raises(CalibrationError, match="exactly 3") as e:
        tool_abc_2point(t, np.concatenate([T, T[:1]]))
    assert e.value.loc == ("flange_poses",)
    with pytest.raises(CalibrationError) as e:
        tool_abc_2point([0, np.nan, 0], T)
    assert e.value.loc == ("tcp_mm", 1)


def test_abc_2point_axis_point_in_front_warns():
    t = np.array([0, 0, 150.0])
    res = tool_abc_2point(t, two_point_poses(np.eye(3), t, lever_mm=-60.0))
    assert any(w.code == "axis_points_back" for w in res.report.warnings)


# --------------------------------------------------------------------------- numeric


def test_numeric_returns_the_typed_pose():
    p = Pose(1.5, -2.0, 180.0, 0.0, 30.0, 0.0)
    res = tool_numeric(p)
    assert res.method == "tool.numeric"
    assert np.allclose(res.frame, p.as_matrix())
    assert np.allclose(tool_numeric([1.5, -2.0, 180.0, 0.0, 30.0, 0.0]).frame, p.as_matrix())


@pytest.mark.parametrize("pose, field", [
    (Pose(0, float("nan"), 100), "y"),
    (Pose(6000, 0, 100), "x"),
    (Pose(0, 0, -5000), "z"),
    (Pose(0, 0, 100, 400, 0, 0), "a"),
    (Pose(0, 0, 100, 0, 0, float("inf")), "c"),
])
def test_numeric_errors_name_the_value(pose, field):
    with pytest.raises(CalibrationError) as e:
        tool_numeric(pose)
    assert e.value.loc == ("pose", field)
