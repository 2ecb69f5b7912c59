"""Base calibration (KUKA BASE 3-point / indirect / numeric) and the geometry it shares.

Two pieces of math live here once and are imported by ``fixed_tool`` and ``workpiece``:

- :func:`frame_from_three_points` and :func:`three_point_report`: a frame from an origin, a
  point on +X and a point in the XY plane, and how touch noise moves it (``base.3point``,
  ``workpiece.direct``).
- :func:`fit_rigid` and :func:`register_points`: the best-fit rigid transform between two point
  sets with residuals, covariance, Fitzpatrick's target registration error and the bad point
  (``base.indirect``, ``workpiece.indirect``).

Pose parameters of every covariance here are ``x_mm, y_mm, z_mm`` (the frame origin in the
parent frame) and ``rx_deg, ry_deg, rz_deg``: a small rotation about the solved frame's own
x, y, z axes, ``R = R_hat @ Exp(d_theta)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.report import (CalibrationResult, Finding, QualityReport, bounds95,
                            leave_one_out_bad_point, residual_sigma, sigma_dof)
from solvers.validate import FloatArray, as_array, as_points, as_transforms

POSE_PARAMETERS = ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")
MIN_DISTANCE_MM = 10.0  # touch-ups closer than this cannot define a direction
SHORT_LEVER_MM = 100.0  # below this a 3-point frame's angles get noisy: say so
LARGE_RESIDUAL_MM = 1.0  # a rigid fit this bad usually means wrong units or point order
TOUCH_SIGMA_MM = 0.05  # default touch-up noise (1 sigma per coordinate) for 3-point sensitivity
SIGMA_FLOOR_MM = 0.01  # rigid fits never claim a scatter below this (robot repeatability)

Loc = tuple[str | int, ...]
_POINT_NAMES = ("origin", "X point", "XY point")
BASE_3POINT_LOCS: tuple[Loc, Loc, Loc] = (("origin_mm",), ("x_point_mm",), ("xy_point_mm",))


# --------------------------------------------------------------------------------------------
# Frame from three points (base.3point, workpiece.direct)
# --------------------------------------------------------------------------------------------

def frame_from_three_points(origin_mm: FloatArray, x_point_mm: FloatArray,
                            xy_point_mm: FloatArray, locs: Sequence[Loc] = BASE_3POINT_LOCS,
                            min_distance_mm: float = MIN_DISTANCE_MM) -> FloatArray:
    """4x4 frame with origin P1, +X through P2 and P3 on the +Y side of its XY plane.

    ``x = unit(P2 - P1)``, ``z = unit(x × (P3 - P1))``, ``y = z × x``, ``T = [x y z | P1]``
    (the lecture's ``w = u × v``, ``z = w/|w|``, ``y = z × x`` [1]_). P3 need not lie on the Y
    axis; its component along y is ``|x × (P3 - P1)| > 0`` by construction.

    Parameters
    ----------
    origin_mm, x_point_mm, xy_point_mm : ndarray, shape (3,)
        P1, P2, P3 in the parent frame (mm).
    locs : three loc tuples
        How the three points are named in errors (API field paths).
    min_distance_mm : float
        Smallest allowed distance between two points and of P3 from the X line.

    Returns
    -------
    ndarray, shape (4, 4)
        ``T_parent_frame``.

    Raises
    ------
    CalibrationError
        A point is not 3 finite numbers; two points are closer than ``min_distance_mm`` (names
        which two and the distance); P3 lies within ``min_distance_mm`` of the X line
        (collinear; gives the distance and the angle).

    References
    ----------
    .. [1] A. D. Udai, "Fixed tool calibration: external TCP and workpiece calibration",
       NPTEL Industrial Robotics, week 7, lecture 31 (workpiece direct method).

    Examples
    --------
    >>> T = frame_from_three_points([100, 0, 0], [300, 0, 0], [150, 80, 0])
    >>> T.round(6).tolist()[:3]
    [[1.0, 0.0, 0.0, 100.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]
    >>> frame_from_three_points([0, 0, 0], [200, 0, 0], [400, 3, 0])
    Traceback (most recent call last):
    ...
    solvers.errors.CalibrationError: xy_point_mm: lies 3.00 mm from the X line through the \
origin and the X point (0.43 deg off it): touch a point at least 10 mm off that line
    """
    P = [as_array(p, loc, (3,)) for p, loc in zip((origin_mm, x_point_mm, xy_point_mm), locs)]
    for i, j in ((0, 1), (0, 2), (1, 2)):
        d = float(np.linalg.norm(P[j] - P[i]))
        if d < min_distance_mm:
            raise CalibrationError(tuple(locs[j]), f"the {_POINT_NAMES[j]} is {d:.2f} mm from "
                                   f"the {_POINT_NAMES[i]}: touch points at least "
                                   f"{min_distance_mm:g} mm apart")
    u = P[1] - P[0]
    x = u / np.linalg.norm(u)
    v = P[2] - P[0]
    w = np.cross(x, v)
    off_line = float(np.linalg.norm(w))
    if off_line < min_distance_mm:
        along = abs(float(v @ x))
        angle = float(np.degrees(np.arctan2(off_line, along)))
        raise CalibrationError(tuple(locs[2]), f"lies {off_line:.2f} mm from the X line through "
                               f"the origin and the X point ({angle:.2f} deg off it): touch a "
                               f"point at least {min_distance_mm:g} mm off that line")
    z = w / off_line
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = P[0]
    return T


def pose_difference(T_ref: FloatArray, T: FloatArray) -> FloatArray:
    """6-vector ``[t - t_ref (mm), rotvec(R_ref^T R) (deg)]``: T relative to T_ref in the
    parameters of :data:`POSE_PARAMETERS` (rotation about T_ref's own axes)."""
    drot = Rotation.from_matrix(T_ref[:3, :3].T @ T[:3, :3]).as_rotvec(degrees=True)
    return np.concatenate([T[:3, 3] - T_ref[:3, 3], drot])


def perturbed(T: FloatArray, d: FloatArray) -> FloatArray:
    """T moved by the pose parameters ``d`` (:data:`POSE_PARAMETERS`): origin + ``d[:3]``
    (parent frame, mm), rotation about T's own axes by the rotation vector ``d[3:]`` (deg).
    The inverse of :func:`pose_difference`; the step of the numeric Jacobians that carry a
    frame's covariance through a solver.

    Examples
    --------
    >>> d = np.array([1.0, -2.0, 0.5, 0.3, -0.2, 0.1])
    >>> np.allclose(pose_difference(np.eye(4), perturbed(np.eye(4), d)), d)
    True
    """
    Tp = np.array(T, dtype=float, copy=True)
    Tp[:3, 3] += d[:3]
    Tp[:3, :3] = Tp[:3, :3] @ Rotation.from_rotvec(d[3:], degrees=True).as_matrix()
    return Tp


def three_point_report(points_mm: FloatArray, locs: Sequence[Loc], touch_sigma_mm: float,
                       frame: FloatArray | None = None) -> QualityReport:
    """Report of a 3-point frame: no residual (3 points fix 6 parameters exactly, the residual
    is zero by construction), so the sensitivity to touch noise instead.

    Covariance ``C = s^2 J J^T`` where J (6x9) is the derivative of the pose parameters
    (:data:`POSE_PARAMETERS`) with respect to the 9 touched coordinates (central differences)
    and s = ``touch_sigma_mm`` per coordinate. Roughly ``sigma(rz) = sigma(ry) = sqrt(2) s / L``
    with L = |P2 - P1| and ``sigma(rx) ~ s sqrt(1 + ...) / d`` with d the distance of P3
    from the X line: the lever arms, reported in ``extras``. The bounds therefore rest on the
    assumed s (``sigma_source="assumed"``, chi-square quantiles, an ``assumed_sigma`` info
    finding): they hold when the touch-ups really scatter by s.

    Examples
    --------
    >>> P = np.array([[0, 0, 0], [200, 0, 0], [0, 200, 0.0]])
    >>> rep = three_point_report(P, [("p", k) for k in range(3)], 0.05)
    >>> np.round(rep.extras["angle_sigma_deg"], 4).tolist()  # about x, y, z of the frame
    [0.0203, 0.0203, 0.0203]
    """
    P = np.asarray(points_mm, dtype=float)
    T0 = frame_from_three_points(*P, locs=locs) if frame is None else frame
    h = 1e-3
    J = np.zeros((6, 9))
    for k in range(9):
        dP = np.zeros(9)
        dP[k] = h
        Tp = frame_from_three_points(*(P + dP.reshape(3, 3)), locs=locs, min_distance_mm=0.0)
        Tm = frame_from_three_points(*(P - dP.reshape(3, 3)), locs=locs, min_distance_mm=0.0)
        J[:, k] = (pose_difference(T0, Tp) - pose_difference(T0, Tm)) / (2 * h)
    cov = touch_sigma_mm**2 * (J @ J.T)
    x_lever = float(np.linalg.norm(P[1] - P[0]))
    xy_lever = float(np.linalg.norm(np.cross(T0[:3, 0], P[2] - P[0])))
    warnings: list[Finding] = []
    if x_lever < SHORT_LEVER_MM:
        warnings.append(Finding("short_lever", f"the X point is only {x_lever:.0f} mm from the "
                                f"origin: {SHORT_LEVER_MM:g} mm or more keeps the frame's angles "
                                f"steadier", tuple(locs[1])))
    if xy_lever < SHORT_LEVER_MM:
        warnings.append(Finding("short_lever", f"the XY point is only {xy_lever:.0f} mm off the X "
                                f"line: {SHORT_LEVER_MM:g} mm or more keeps the tilt about X "
                                f"steadier", tuple(locs[2])))
    warnings.append(Finding("assumed_sigma", f"three points leave no residual to measure the "
                            f"touch scatter: the bounds assume {touch_sigma_mm:g} mm per "
                            f"coordinate (touch_sigma_mm)", (), "info"))
    angle_sigma = np.sqrt(np.diag(cov)[3:])
    return QualityReport(
        residuals_mm=np.zeros(3),
        parameter_names=POSE_PARAMETERS,
        covariance=cov,
        sigma_mm=float(touch_sigma_mm),
        **bounds95(cov, None, position=slice(0, 3), angle=slice(3, 6)),
        warnings=tuple(warnings),
        extras={"touch_sigma_mm": float(touch_sigma_mm), "angle_sigma_deg": angle_sigma,
                "x_lever_mm": x_lever, "xy_lever_mm": xy_lever,
                "note": "3 points fix the frame exactly: residuals are zero by construction; "
                        "the covariance and the 95% bounds rest on the assumed touch noise "
                        f"touch_sigma_mm = {touch_sigma_mm:g} mm (chi-square quantiles), not on "
                        "a measured scatter"},
    )


def base_3point(origin_mm: FloatArray, x_point_mm: FloatArray, xy_point_mm: FloatArray, *,
                touch_sigma_mm: float = TOUCH_SIGMA_MM,
                min_distance_mm: float = MIN_DISTANCE_MM) -> CalibrationResult:
    """Base > 3-point: a base frame from its origin, a point on +X and a point in the XY plane.

    The three points are touched with a calibrated TCP, so they are known in world (robot
    base) coordinates. ``x = unit(P2 - P1)``, ``z = unit(x × (P3 - P1))``, ``y = z × x``,
    origin P1 [1]_; P3 lies on the +Y side.

    Parameters
    ----------
    origin_mm, x_point_mm, xy_point_mm : array_like, shape (3,)
        P1, P2, P3 in world, mm.
    touch_sigma_mm : float, keyword-only
        Touch-up noise (1 sigma per coordinate, mm) for the sensitivity in the report.
    min_distance_mm : float, keyword-only
        Smallest distance between points and of P3 from the X line.

    Returns
    -------
    CalibrationResult
        ``method="base.3point"``, ``frame = T_world_base``. The report's residuals are zero by
        construction; its covariance, bounds and ``extras["angle_sigma_deg"]`` give the error
        expected from ``touch_sigma_mm`` through the lever arms (``extras["x_lever_mm"]``,
        ``extras["xy_lever_mm"]``).

    Raises
    ------
    CalibrationError
        Not finite / wrong shape; two points closer than ``min_distance_mm``; the three points
        collinear (P3 within ``min_distance_mm`` of the X line).

    References
    ----------
    .. [1] A. D. Udai, "Fixed tool calibration: external TCP and workpiece calibration",
       NPTEL Industrial Robotics, week 7, lecture 31; KUKA System Software 8, "Base
       calibration: 3-point method".

    Examples
    --------
    >>> res = base_3point([500, 0, 200], [700, 0, 200], [500, 300, 200])
    >>> res.frame[:3, 3].tolist(), res.report.max_error_mm
    ([500.0, 0.0, 200.0], 0.0)
    >>> round(float(res.report.extras["angle_sigma_deg"][2]), 4)  # about z, 200 mm lever
    0.0203
    """
    if not (np.isfinite(touch_sigma_mm) and touch_sigma_mm >= 0):
        raise CalibrationError(("touch_sigma_mm",), f"must be a number >= 0, got {touch_sigma_mm}")
    locs = BASE_3POINT_LOCS
    T = frame_from_three_points(origin_mm, x_point_mm, xy_point_mm, locs, min_distance_mm)
    points = (origin_mm, x_point_mm, xy_point_mm)
    P = np.array([as_array(p, loc, (3,)) for p, loc in zip(points, locs)])
    return CalibrationResult("base.3point", T, three_point_report(P, locs, touch_sigma_mm, frame=T))


# --------------------------------------------------------------------------------------------
# Best-fit rigid transform (base.indirect, workpiece.indirect)
# --------------------------------------------------------------------------------------------

def check_layout(points_mm: FloatArray, loc: Loc, min_spread_mm: float = MIN_DISTANCE_MM) -> None:
    """Raise unless the points span at least a plane: a rigid fit needs two directions.

    Coplanar points are fine for a rigid fit (the normal follows from the in-plane axes);
    collinear points leave the rotation about their line free and are singular. The test is
    the RMS distance of the points from their best-fit line, ``sqrt((s2² + s3²) / N)`` from
    the singular values of the centred points.

    Examples
    --------
    >>> check_layout(np.array([[0, 0, 0], [100, 0, 0], [200, 0.5, 0], [300, 0, 0]]), ("known_mm",))
    Traceback (most recent call last):
    ...
    solvers.errors.CalibrationError: known_mm: all 4 points lie on one line (RMS 0.21 mm off it): \
a rigid fit needs points spread in two directions (coplanar is fine), at least 10 mm off that line
    """
    P = np.asarray(points_mm, dtype=float)
    s = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)
    n = len(P)
    if s[0] / np.sqrt(n) < min_spread_mm:
        raise CalibrationError(tuple(loc), f"all {n} points lie within {s[0] / np.sqrt(n):.2f} mm "
                               f"RMS of their centroid: spread them at least {min_spread_mm:g} mm "
                               f"apart")
    off_line = float(np.sqrt((s[1] ** 2 + s[2] ** 2) / n))
    if off_line < min_spread_mm:
        raise CalibrationError(tuple(loc), f"all {n} points lie on one line (RMS {off_line:.2f} mm "
                               f"off it): a rigid fit needs points spread in two directions "
                               f"(coplanar is fine), at least {min_spread_mm:g} mm off that line")


def fit_rigid(known_mm: FloatArray, measured_mm: FloatArray) -> FloatArray:
    """Best-fit rigid transform T minimising ``sum_i |R k_i + t - m_i|²``.

    The rotation of the centred point sets by ``Rotation.align_vectors`` (Kabsch; the
    closed-form least-squares solution of Arun et al. [1]_, Horn [2]_ and Umeyama [3]_ without
    scale), then ``t = m_bar - R k_bar``. The caller checks the layout (:func:`check_layout`).

    Parameters
    ----------
    known_mm, measured_mm : ndarray, shape (N, 3)
        The same N >= 3 points in the frame being calibrated and in the parent frame.

    Returns
    -------
    ndarray, shape (4, 4)
        ``T_parent_frame``, mapping known coordinates onto measured ones.

    References
    ----------
    .. [1] K. S. Arun, T. S. Huang, S. D. Blostein, "Least-squares fitting of two 3-D point
       sets", IEEE Trans. PAMI 9(5), 1987.
    .. [2] B. K. P. Horn, "Closed-form solution of absolute orientation using unit
       quaternions", J. Opt. Soc. Am. A 4(4), 1987.
    .. [3] S. Umeyama, "Least-squares estimation of transformation parameters between two
       point patterns", IEEE Trans. PAMI 13(4), 1991.

    Examples
    --------
    >>> K = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [0, 0, 100.0]])
    >>> M = K @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]]).T + [10, 20, 30]
    >>> fit_rigid(K, M).round(6).tolist()[0]
    [0.0, -1.0, 0.0, 10.0]
    """
    K = np.asarray(known_mm, dtype=float)
    M = np.asarray(measured_mm, dtype=float)
    k_bar, m_bar = K.mean(axis=0), M.mean(axis=0)
    rot, _ = Rotation.align_vectors(M - m_bar, K - k_bar)
    T = np.eye(4)
    T[:3, :3] = rot.as_matrix()
    T[:3, 3] = m_bar - T[:3, :3] @ k_bar
    return T


def _skew(v: FloatArray) -> FloatArray:
    """Cross-product matrices [v]x of (..., 3) vectors."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape + (3,))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def point_jacobian(frame: FloatArray, points_mm: FloatArray) -> FloatArray:
    """d(T p)/d(params) of points p (frame coordinates), shape (N, 3, 6), params in mm and rad.

    With ``R = R_hat Exp(d_theta)``: ``d(R p + t) = d_t - R_hat [p]x d_theta``.
    """
    P = np.atleast_2d(np.asarray(points_mm, dtype=float))
    J = np.zeros((len(P), 3, 6))
    J[:, :, :3] = np.eye(3)
    J[:, :, 3:] = -frame[:3, :3] @ _skew(P)
    return J


def rigid_fit_covariance(frame: FloatArray, known_mm: FloatArray, sigma_mm: float) -> FloatArray:
    """Covariance (6x6, mm and deg) of the pose parameters of a rigid fit.

    ``C = sigma² (J^T J)^-1`` with J stacked from :func:`point_jacobian` at the known points,
    isotropic noise ``sigma_mm`` per coordinate of every measured point.
    """
    J = point_jacobian(frame, known_mm).reshape(-1, 6)
    cov_rad = sigma_mm**2 * np.linalg.inv(J.T @ J)
    scale = np.array([1, 1, 1, *(3 * [180.0 / np.pi])])
    return cov_rad * np.outer(scale, scale)


def fitzpatrick_tre_mm(known_mm: FloatArray, fle_mm: float, target_mm: FloatArray) -> FloatArray:
    """Expected target registration error (RMS, mm) at targets, Fitzpatrick's formula [1]_.

    ``TRE²(r) = (FLE² / N) (1 + 1/3 sum_k d_k² / f_k²)``, k over the principal axes of the N
    fiducials; d_k is the target's distance from axis k and f_k the fiducials' RMS distance
    from it. FLE is the RMS 3-D localisation error of one point (``sqrt(3) sigma``).

    References
    ----------
    .. [1] J. M. Fitzpatrick, J. B. West, C. R. Maurer, "Predicting error in rigid-body
       point-based registration", IEEE Trans. Med. Imaging 17(5), 1998.

    Examples
    --------
    >>> K = np.array([[100, 0, 0], [-100, 0, 0], [0, 100, 0], [0, -100, 0.0]])
    >>> round(float(fitzpatrick_tre_mm(K, 0.1, [0, 0, 0])), 4)  # at the centroid: FLE/sqrt(N)
    0.05
    """
    K = np.asarray(known_mm, dtype=float)
    c = K.mean(axis=0)
    X = K - c
    _, V = np.linalg.eigh(X.T @ X)  # principal axes (columns)
    r = np.atleast_2d(np.asarray(target_mm, dtype=float)) - c
    ratio = np.zeros(len(r))
    for k in range(3):
        a = V[:, k]
        f2 = np.mean(np.sum((X - np.outer(X @ a, a)) ** 2, axis=1))
        d2 = np.sum((r - np.outer(r @ a, a)) ** 2, axis=1)
        ratio += d2 / f2
    tre = np.sqrt(fle_mm**2 / len(K) * (1 + ratio / 3))
    return tre if np.ndim(target_mm) > 1 else tre[0]


def register_points(measured_mm: object, known_mm: object, *, measured_loc: str = "measured_mm",
                    known_loc: str = "known_mm", target_mm: object = None,
                    sigma_floor_mm: float = SIGMA_FLOOR_MM,
                    min_spread_mm: float = MIN_DISTANCE_MM) -> tuple[FloatArray, QualityReport]:
    """Best-fit rigid ``T`` with ``measured ≈ T known`` and its full quality report.

    Residual ``e_i = T k_i - m_i``; ``sigma = sqrt(sum |e_i|² / (3N - 6))`` (at least
    ``sigma_floor_mm``); covariance of the 6 pose parameters from :func:`rigid_fit_covariance`;
    95% bounds with the F quantiles of ``3N - 6`` degrees of freedom (chi-square, and
    ``sigma_source="assumed"``, when the floor is used; :func:`~solvers.report.bounds95`); TRE by :func:`fitzpatrick_tre_mm` with ``FLE = sqrt(3) sigma``; the bad point by
    leave-one-out when N >= 5.

    Parameters
    ----------
    measured_mm : array_like, shape (N, 3)
        Points in the parent frame (mm), N >= 4.
    known_mm : array_like, shape (N, 3)
        The same points in the frame being calibrated (mm).
    target_mm : array_like, shape (3,), optional
        A point of interest in known coordinates: ``report.tre_mm`` is the TRE there. Default:
        the TRE at the known point farthest from the centroid (the worst over the taught
        region); ``extras`` always holds ``tre_centroid_mm`` and ``tre_farthest_mm``.

    Returns
    -------
    (ndarray (4, 4), QualityReport)

    Raises
    ------
    CalibrationError
        Wrong shape, NaN, fewer than 4 points, different counts, or a singular layout
        (coincident or collinear points) of either set.
    """
    K = as_points(known_mm, known_loc, min_count=4)
    M = as_points(measured_mm, measured_loc, min_count=4)
    if len(K) != len(M):
        raise CalibrationError((known_loc,), f"has {len(K)} points but {measured_loc} has "
                               f"{len(M)}: give one known point per touch-up")
    r_target = None if target_mm is None else as_array(target_mm, "target_mm", (3,))
    check_layout(K, (known_loc,), min_spread_mm)
    check_layout(M, (measured_loc,), min_spread_mm)
    n = len(K)
    T = fit_rigid(K, M)
    E = (K @ T[:3, :3].T + T[:3, 3]) - M
    residuals = np.linalg.norm(E, axis=1)
    sigma = residual_sigma(E, 6, floor=sigma_floor_mm)
    cov = rigid_fit_covariance(T, K, sigma)
    fle = float(np.sqrt(3.0) * sigma)
    c = K.mean(axis=0)
    far = int(np.argmax(np.linalg.norm(K - c, axis=1)))
    tre_centroid = float(fitzpatrick_tre_mm(K, fle, c))
    tre_far = float(fitzpatrick_tre_mm(K, fle, K[far]))
    tre = tre_far if r_target is None else float(fitzpatrick_tre_mm(K, fle, r_target))

    def fit(idx: Sequence[int]):
        idx = list(idx)
        check_layout(K[idx], (known_loc,), min_spread_mm)
        Ts = fit_rigid(K[idx], M[idx])
        return Ts, lambda i: float(np.linalg.norm(Ts[:3, :3] @ K[i] + Ts[:3, 3] - M[i]))

    bad = leave_one_out_bad_point(n, fit, n_parameters=2, min_points=5)
    warnings: list[Finding] = []
    guidance = None
    if bad is not None:
        warnings.append(Finding("bad_point", bad.message(), (measured_loc, bad.index)))
        guidance = f"re-teach point {bad.index + 1}"
    if bad is None and residuals.max() > LARGE_RESIDUAL_MM:
        worst = int(np.argmax(residuals))
        warnings.append(Finding("large_residual", f"point {worst + 1} is {residuals.max():.2f} mm "
                                f"off the best fit: check the units and the order of {known_loc}",
                                (measured_loc, worst)))
    if n == 4:
        warnings.append(Finding("few_points", "4 points leave 6 redundant numbers: the scatter "
                                "and the bounds are rough; the bad point check needs 5 or more",
                                (), "info"))
    report = QualityReport(
        residuals_mm=residuals,
        parameter_names=POSE_PARAMETERS,
        covariance=cov,
        sigma_mm=sigma,
        **bounds95(cov, sigma_dof(sigma, 3 * n - 6, sigma_floor_mm), position=slice(0, 3),
                   angle=slice(3, 6)),
        tre_mm=tre,
        bad_point=bad,
        warnings=tuple(warnings),
        guidance=guidance,
        extras={"residual_vectors_mm": E, "fle_mm": fle, "tre_centroid_mm": tre_centroid,
                "tre_farthest_mm": tre_far, "tre_farthest_point": far,
                "tre_target_mm": None if r_target is None else tre},
    )
    return T, report


def base_indirect(measured_mm: object, known_mm: object, *, target_mm: object = None,
                  sigma_floor_mm: float = SIGMA_FLOOR_MM) -> CalibrationResult:
    """Base > Indirect: a base frame from N >= 4 points known in it and touched in world.

    Best-fit rigid transform ``T_world_base = argmin sum_i |T k_i - m_i|²`` (Kabsch via
    ``Rotation.align_vectors`` [1]_ [2]_ [3]_): k_i known in the base being calibrated (e.g.
    from a drawing), m_i the same point touched with a calibrated TCP in world. Residuals per
    point; ``sigma = sqrt(SSR / (3N - 6))``; covariance of the 6 pose parameters; TRE [4]_.

    Parameters
    ----------
    measured_mm : array_like, shape (N, 3)
        Touched points in world (robot base), mm.
    known_mm : array_like, shape (N, 3)
        The same points in the base frame being calibrated, mm. Coplanar is fine.
    target_mm : array_like, shape (3,), optional, keyword-only
        A point in base coordinates where the expected error matters: ``report.tre_mm``.
        Default: the TRE at the known point farthest from the centroid.
    sigma_floor_mm : float, keyword-only
        The scatter never drops below this in the covariance and TRE.

    Returns
    -------
    CalibrationResult
        ``method="base.indirect"``, ``frame = T_world_base``; ``report.tre_mm``,
        ``extras["tre_centroid_mm"]``, ``extras["tre_farthest_mm"]``, ``report.bad_point``
        (N >= 5).

    Raises
    ------
    CalibrationError
        Wrong shapes, NaN, N < 4, different counts, coincident or collinear points.

    References
    ----------
    .. [1] K. S. Arun, T. S. Huang, S. D. Blostein, IEEE Trans. PAMI 9(5), 1987.
    .. [2] B. K. P. Horn, J. Opt. Soc. Am. A 4(4), 1987.
    .. [3] S. Umeyama, IEEE Trans. PAMI 13(4), 1991.
    .. [4] J. M. Fitzpatrick, J. B. West, C. R. Maurer, IEEE Trans. Med. Imaging 17(5), 1998.

    Examples
    --------
    >>> known = [[0, 0, 0], [400, 0, 0], [400, 300, 0], [0, 300, 0]]
    >>> measured = np.array(known) + [800, -150, 20]
    >>> res = base_indirect(measured, known)
    >>> res.frame[:3, 3].round(6).tolist(), round(res.report.max_error_mm, 6)
    ([800.0, -150.0, 20.0], 0.0)
    """
    T, report = register_points(measured_mm, known_mm, measured_loc="measured_mm",
                                known_loc="known_mm", target_mm=target_mm,
                                sigma_floor_mm=sigma_floor_mm)
    return CalibrationResult("base.indirect", T, report)


def base_numeric(pose: Pose | Sequence[float]) -> CalibrationResult:
    """Base > Numeric input: the base frame typed in as KUKA X, Y, Z, A, B, C (mm, deg).

    ``T_world_base`` with ``R = Rz(A) @ Ry(B) @ Rx(C)`` (intrinsic Z, Y', X''), from CAD data.

    Raises
    ------
    CalibrationError
        A value that is not a finite number (loc ``("pose", i)``).

    Examples
    --------
    >>> res = base_numeric(Pose(1000, 0, 0, 90, 0, 0))
    >>> res.frame[:3, 0].round(6).tolist(), res.method
    ([0.0, 1.0, 0.0], 'base.numeric')
    """
    v = as_array(pose.as_array() if isinstance(pose, Pose) else pose, "pose", (6,))
    p = Pose.from_array(v)
    return CalibrationResult("base.numeric", p.as_matrix(),
                             QualityReport(residuals_mm=np.zeros(0), extras={"pose": p}))


def as_transform(value: object, loc: str) -> FloatArray:
    """One checked rigid 4x4 transform (a ``Pose`` is accepted and converted)."""
    if isinstance(value, Pose):
        return Pose.from_array(as_array(value.as_array(), loc, (6,))).as_matrix()
    T = as_array(value, loc, (4, 4))
    try:
        as_transforms(T[None], loc)
    except CalibrationError as exc:
        raise CalibrationError((loc,), exc.reason) from None
    return T


__all__ = ["base_3point", "base_indirect", "base_numeric", "frame_from_three_points",
           "three_point_report", "fit_rigid", "register_points", "check_layout",
           "rigid_fit_covariance", "fitzpatrick_tre_mm", "point_jacobian", "pose_difference",
           "as_transform", "POSE_PARAMETERS"]
