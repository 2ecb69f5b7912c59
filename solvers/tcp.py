"""Robot-held tool calibration: the TCP (XYZ menus) and the tool orientation (ABC menus).

Menus (KUKA *Start-up > Calibrate > Tool*; ABB *tooldata* definition alike):

- ``tool.xyz_4point``   :func:`tcp_xyz_4point` -- one fixed point touched from N >= 4 orientations.
- ``tool.xyz_reference`` :func:`tcp_xyz_reference` -- a point already known in base.
- ``tool.abc_world_5d`` / ``_6d`` :func:`tool_abc_world` -- tool aligned with world axes.
- ``tool.abc_2point``   :func:`tool_abc_2point` -- a point on the tool axis and one in its XZ plane.
- ``tool.numeric``      :func:`tool_numeric` -- typed-in values, checked.

Every result's ``frame`` is ``T_flange_tcp``: the TCP in the flange frame, whose z axis is the
tool axis (working direction). All rotations go through SciPy's ``Rotation``; flange poses
are 4x4 ``T_base_flange`` (base = world when the robot stands at the world origin).
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from scipy import stats
from scipy.spatial.transform import Rotation

from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.report import (CHI2_95, BadPoint, CalibrationResult, Finding, QualityReport, bound95,
                            leave_one_out_bad_point, residual_sigma)
from solvers.validate import FloatArray, as_array, as_transforms

#: Touch-up noise floor (mm): the sigma used when the residual is smaller or has no dof.
SIGMA_FLOOR_MM = 0.01
#: Nominal touch-up repeatability (mm) for the exactly-determined ABC 2-point bound.
NOMINAL_TOUCH_SIGMA_MM = 0.05
#: All orientations within this angle (deg) of each other: the 4-point menu refuses.
MIN_SPREAD_DEG = 2.0
#: Effective tilt perpendicular to a TCP direction below which that direction is unobservable.
DEGENERATE_TILT_DEG = 2.0
#: ... and below which it is weakly observable (warning).
WEAK_TILT_DEG = 10.0
#: Largest plausible TCP / tool translation (mm).
MAX_TCP_MM = 5000.0
#: Residual scatter (sigma, mm) above which the touch-ups are reported as inconsistent.
LARGE_SIGMA_MM = 0.5
#: Shortest usable lever (mm) between TCP and the ABC 2-point axis / plane points.
MIN_LEVER_MM = 5.0

#: 3 F(3, nu; 0.95): the 95% joint-confidence scale of 3 parameters when sigma is estimated
#: from nu residual degrees of freedom (it tends to chi2(3; 0.95) = 7.81 as nu grows).
_F95_3 = 3.0 * stats.f.ppf(0.95, 3, np.arange(1, 1001))

#: smallest eigenvalue of M = I - R̄ᵀR̄ that still determines the TCP: sin²(2 deg / 2)
_MIN_LAMBDA = math.sin(math.radians(DEGENERATE_TILT_DEG) / 2.0) ** 2

_AXES = np.eye(3)
_AXIS_NAMES = ("x", "y", "z")


def _candidate_tilts() -> tuple[FloatArray, FloatArray, FloatArray]:
    """Flange-frame rotations tried by :func:`next_tcp_orientation`: 26 axes x {45, 30} deg.

    Returns the rotations (C, 3, 3), their angles (deg) and axes (C, 3)."""
    g = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                  if (i, j, k) != (0, 0, 0)], dtype=float)
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    angles = np.radians([45.0, 30.0])
    rotvecs = (angles[:, None, None] * g[None]).reshape(-1, 3)
    return Rotation.from_rotvec(rotvecs).as_matrix(), np.repeat(np.degrees(angles), len(g)), \
        np.tile(g, (len(angles), 1))


_TILT_R, _TILT_DEG, _TILT_AXIS = _candidate_tilts()
_EYE3 = np.eye(3)
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])
_COS_10 = float(np.cos(np.radians(10.0)))
#: entries (00, 11, 22, 01, 02, 12) of a symmetric 3x3, as flat indices
_SYM6 = np.array([0, 4, 8, 1, 2, 5])


def _symmetric_weights() -> FloatArray:
    """W (9, 6C): ``vec(K) @ W`` = the six entries of ``K Q_c + (K Q_c)ᵀ`` for every candidate."""
    W = np.zeros((3, 3, 6, len(_TILT_R)))
    for s, (a, b) in enumerate([(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]):
        for m in range(3):
            W[a, m, s] += _TILT_R[:, m, b]  # (K Q)[a, b] = sum_m K[a, m] Q[m, b]
            W[b, m, s] += _TILT_R[:, m, a]  # (K Q)[b, a]
    return W.reshape(9, -1)


_SYMW = _symmetric_weights()
_TRACE_HALF_DEG = 1.0 + 2.0 * float(np.cos(np.radians(0.5)))  # trace(R_iᵀR_j) at 0.5 deg


# --------------------------------------------------------------------------- helpers


def _direction_words(v: FloatArray) -> str:
    """Plain words for a unit direction in flange coordinates ("the flange z axis")."""
    i = int(np.argmax(np.abs(v)))
    if abs(v[i]) >= _COS_10:
        return f"the flange {_AXIS_NAMES[i]} axis"
    return "the flange direction ({:.2f}, {:.2f}, {:.2f})".format(*v)


_TILT_WORDS = [f"tilt the flange {deg:.0f} deg about {_direction_words(u)} "
               "(report.next_orientation)" for deg, u in zip(_TILT_DEG, _TILT_AXIS)]


def _perpendicular_axes_words(v: FloatArray) -> str:
    """The two flange axes most perpendicular to v ("flange x or y")."""
    order = np.argsort(np.abs(v))
    return f"flange {_AXIS_NAMES[order[0]]} or {_AXIS_NAMES[order[1]]}"


def _as_flange_poses(value: object, min_count: int) -> FloatArray:
    """``as_transforms`` without its loop over poses: one vectorised check on the fast path,
    the per-pose search (same messages) only when something is wrong."""
    T = as_array(value, "flange_poses", (None, 4, 4))
    if len(T) < min_count:
        raise CalibrationError(("flange_poses",), f"needs at least {min_count} poses, got {len(T)}")
    R = T[:, :3, :3]
    if len(T) and (np.abs(R @ R.transpose(0, 2, 1) - _EYE3).max() <= 1e-6
                   and np.abs(T[:, 3] - _LAST_ROW).max() <= 1e-6
                   and np.linalg.det(R).min() > 0):
        return T
    return as_transforms(T, "flange_poses", min_count)


def _pivot_normal(X: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Reduced normal equations of R_k t + p_k = s with s eliminated.

    ``X`` (N, 3, 4) holds ``[R_k | p_k]`` (the top three rows of T_base_flange). Returns
    (R̄, p̄, M, rhs) with ``M = (1/N) Σ (R_k - R̄)ᵀ(R_k - R̄) = I - R̄ᵀR̄`` (flange frame)
    and ``M t = rhs = -(1/N) Σ (R_k - R̄)ᵀ (p_k - p̄)``: one 4x4 product of the centred
    ``[R_k - R̄ | p_k - p̄]``, which also avoids the cancellation of ``I - R̄ᵀR̄``.
    """
    n = len(X)
    Xbar = X.sum(axis=0) * (1.0 / n)
    D = (X - Xbar).reshape(3 * n, 4)
    C = (D.T @ D) * (1.0 / n)
    return Xbar[:, :3], Xbar[:, 3], C[:3, :3], -C[:3, 3]


def _pivot_fit(X: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Least-squares (t, s, eigenvalues, eigenvectors of M) from ``X = [R_k | p_k]`` (N, 3, 4);
    raises ValueError when singular."""
    Rbar, pbar, M, rhs = _pivot_normal(X)
    w, V = np.linalg.eigh(M)
    if w[0] < _MIN_LAMBDA:
        raise ValueError("orientations do not determine the TCP")
    t = V @ ((V.T @ rhs) / w)
    s = Rbar @ t + pbar
    return t, s, w, V


def _scale95(dof: int, sigma: float) -> float:
    """Squared 95% radius factor for 3 parameters: 3 F(3, dof) when sigma was estimated from
    dof residual degrees of freedom, chi2(3) when it is the floor (taken as known)."""
    if sigma <= SIGMA_FLOOR_MM or dof <= 0 or dof > len(_F95_3):
        return CHI2_95[3]
    return float(_F95_3[dof - 1])


def _bad_point_pivot(R: FloatArray, p: FloatArray) -> BadPoint | None:
    """Leave-one-out search for the one touch-up that disagrees (N >= 5).

    All N fits without one point are solved at once: with m = N - 1,
    ``R̄_k = (Σ R_i - R_k)/m``, ``p̄_k = (Σ p_i - p_k)/m``, ``M_k = I - R̄_kᵀR̄_k``,
    ``M_k t_k = -(Σ R_iᵀp_i - R_kᵀp_k)/m + R̄_kᵀ p̄_k``, ``s_k = R̄_k t_k + p̄_k``; then
    :func:`~solvers.report.leave_one_out_bad_point` judges each point by the fit without it
    (2 parameters per point: 6 scalars / 3). A fit without k whose geometry is degenerate
    is skipped.
    """
    n = len(R)
    m = n - 1.0
    Rb = (R.sum(axis=0) - R) / m
    pb = (p.sum(axis=0) - p) / m
    Rp = np.einsum("kji,kj->ki", R, p)
    Rbt = Rb.transpose(0, 2, 1)
    Mk = _EYE3 - Rbt @ Rb
    rhs = (Rp - Rp.sum(axis=0)) / m + (Rbt @ pb[:, :, None])[:, :, 0]
    ok = np.linalg.eigvalsh(Mk)[:, 0] >= _MIN_LAMBDA
    Mk[~ok] = _EYE3
    tk = np.linalg.solve(Mk, rhs[:, :, None])[:, :, 0]
    sk = (Rb @ tk[:, :, None])[:, :, 0] + pb
    E = np.einsum("iab,kb->kia", R, tk) + (p[None, :, :] - sk[:, None, :])
    err = np.sqrt((E * E).sum(axis=2)).tolist()  # err[k][i]: point i under the fit without k
    total = n * (n - 1) // 2

    def fit(idx):
        k = total - sum(idx)  # the one index left out
        if len(idx) != n - 1 or not ok[k]:
            raise ValueError("not a leave-one-out subset with a usable geometry")
        row = err[k]
        return _tcp_frame(tk[k]), row.__getitem__

    return leave_one_out_bad_point(n, fit, n_parameters=2, floor_mm=0.02, k_sigma=4.0,
                                   min_points=5)


def _tcp_frame(tcp_mm: FloatArray, R: FloatArray | None = None) -> FloatArray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = tcp_mm
    return T


def _best_tilt(R: FloatArray, Rbar: FloatArray,
               G: FloatArray | None = None) -> tuple[int, int, FloatArray, FloatArray]:
    """The tilt that most shrinks trace Cov(t) after one more touch-up.

    Candidates tilt the touch-up orientation nearest the mean, R_j, about flange axes:
    ``R_new = R_j Q_c``. With ``A = N R̄/(N+1)``, ``B = R_j/(N+1)`` the new mean is
    ``R̄' = A + B Q_c`` and ``M'_c = I - AᵀA - I/(N+1)² - (K Q_c + (K Q_c)ᵀ)``, ``K = AᵀB``,
    linear in K: its six distinct entries for all candidates are one product with a
    precomputed (9, 6C) matrix. ``trace(M'^-1)`` = (sum of the principal 2x2 minors) / det,
    with a 1e-9 ridge so that N < 3 (rank-deficient) stays comparable. Returns (candidate
    index, j, R_new, trace factors ``trace(M'^-1)/(N+1)``).
    """
    n = len(R)
    if G is None:
        Rf = R.reshape(n, 9)
        G = Rf @ Rf.T
    j = int(np.argmax(G.sum(axis=0)))  # max trace(R̄ᵀ R_j)
    A = Rbar * (n / (n + 1.0))
    const = (1.0 + 1e-9 - 1.0 / (n + 1.0) ** 2) * _EYE3 - A.T @ A
    K = (A.T @ R[j]) * (1.0 / (n + 1.0))
    a, b, c, d, e, f = (const.ravel()[_SYM6, None] - (K.ravel() @ _SYMW).reshape(6, -1))
    m0 = b * c - f * f
    dd, ee = d * d, e * e
    det = a * m0 - b * ee - c * dd + 2.0 * d * e * f
    tr = (m0 + a * (b + c) - dd - ee) / ((n + 1.0) * det)
    best = int(np.argmin(tr))
    return best, j, R[j] @ _TILT_R[best], tr


def _guidance_text(R: FloatArray, Rbar: FloatArray, sigma_mm: float | None,
                   G: FloatArray | None = None) -> tuple[str, FloatArray]:
    best, j, Rnew, tr = _best_tilt(R, Rbar, G)
    text = f"next touch-up: from the orientation of touch-up {j + 1}, {_TILT_WORDS[best]}"
    if sigma_mm is not None:
        text += (f"; expected TCP RMS error then {sigma_mm * math.sqrt(tr[best]):.3f} mm "
                 f"at sigma {sigma_mm:.3f} mm")
    return text, Rnew


# --------------------------------------------------------------------------- XYZ 4-point


def next_tcp_orientation(flange_poses: FloatArray) -> FloatArray:
    """Flange orientation for the next XYZ 4-point touch-up: the one that helps the TCP most.

    Candidates are the touch-up orientation nearest the mean, R_j, tilted by 30 or 45 deg
    about 26 flange-frame axes, ``R_new = R_j @ Rot(u, alpha)``. With one more touch-up the
    TCP covariance becomes ``sigma² / (N+1) · (I - R̄'ᵀR̄')^-1`` with
    ``R̄' = (N R̄ + R_new) / (N+1)``; the candidate with the smallest trace wins.

    Parameters
    ----------
    flange_poses : ndarray, shape (N, 4, 4), N >= 1
        T_base_flange at the touch-ups so far.

    Returns
    -------
    ndarray, shape (3, 3)
        Flange rotation in base (R_base_flange) to touch up next.

    Raises
    ------
    CalibrationError
        ``("flange_poses", ...)`` when a pose is not finite or not a rigid transform.

    References
    ----------
    .. [1] Z. Yaniv, "Which pivot calibration?", Proc. SPIE 9415, 2015.

    Examples
    --------
    >>> from solvers.frames import matrix_from_kuka
    >>> T = matrix_from_kuka([[500, 0, 300, 0, 180, 0], [500, 0, 300, 90, 180, 0]])
    >>> R = next_tcp_orientation(T)  # both poses rotate about flange z: tilt away from it
    >>> Rb = (T[0, :3, :3] + T[1, :3, :3] + R) / 3
    >>> bool(np.linalg.eigvalsh(np.eye(3) - Rb.T @ Rb).min() > 0.05)  # TCP now observable
    True
    """
    T = as_transforms(flange_poses, "flange_poses", min_count=1)
    R = T[:, :3, :3]
    return _best_tilt(R, R.mean(axis=0))[2]


def tcp_xyz_4point(flange_poses: FloatArray) -> CalibrationResult:
    """XYZ 4-point (N-point): TCP in the flange from N >= 4 touch-ups of one fixed point.

    For every touch-up k the TCP is on the same point s:
    ``R_k t + p_k = s``, i.e. the stacked linear system ``[R_k, -I] [t; s] = -p_k``,
    solved by least squares [1]_ (t: TCP in flange, s: touched point in base, mm).
    Eliminating s (``s = R̄ t + p̄``) leaves ``M t = -(1/N) Σ (R_k - R̄)ᵀ(p_k - p̄)`` with
    ``M = I - R̄ᵀR̄`` (flange frame, R̄ the element-wise mean rotation).

    Noise model: isotropic touch noise sigma on each p_k (equivalently on the contact).
    The estimate is then unbiased and efficient; its covariance is the inverse Fisher
    information ``sigma² (Σ [R_k, -I]ᵀ[R_k, -I])^-1``, whose t block is exactly
    ``Cov(t) = sigma²/N · M^-1`` (the Cramér–Rao bound). sigma is estimated from the
    residual with 6 parameters, floored at ``SIGMA_FLOOR_MM``. ``position_bound95_mm`` is
    the largest radius of the 95% confidence ellipsoid of t: ``sqrt(k lambda_max(Cov(t)))``
    with ``k = 3 F(3, 3N-6; 0.95)`` (sigma estimated; Student-type widening for small N) or
    ``k = chi2(3; 0.95)`` when the floor is used.

    Observability: an eigenvalue lambda of M with eigenvector v (flange frame) is
    ``sin²(theta/2)`` for two poses tilted by theta about an axis perpendicular to v, so
    ``theta = 2 asin(sqrt(lambda))`` is the *effective tilt* that measures t along v. Below
    2 deg the TCP along v is unobservable (error); below 10 deg weak (warning).

    Parameters
    ----------
    flange_poses : ndarray, shape (N, 4, 4), N >= 4
        T_base_flange at each touch-up (mm).

    Returns
    -------
    CalibrationResult
        ``method="tool.xyz_4point"``; ``frame`` = T_flange_tcp with identity rotation.
        ``report.residuals_mm[k] = |R_k t + p_k - s|``; ``covariance`` (3x3, mm²) of
        ``("x_mm", "y_mm", "z_mm")``; ``sigma_mm``; ``position_bound95_mm``; ``bad_point``
        (N >= 5); ``warnings``; ``guidance`` and ``next_orientation`` (next touch-up);
        ``extras``: ``point_mm`` (s in base), ``point_covariance_mm2``, ``spread_deg`` (largest
        angle between two touch-up orientations), ``tilt_deg`` (effective tilt along the
        eigenvectors of M, deg), ``eigenvectors_flange`` (columns, flange frame).

    Raises
    ------
    CalibrationError
        ``("flange_poses",)``: fewer than 4 poses; all orientations within 2 deg of each
        other ("orientations too alike", with the spread in deg); the orientations rotate
        about one axis so the TCP along it is unobservable (names that flange direction).
        ``("flange_poses", k, ...)``: pose k not finite / not rigid.

    References
    ----------
    .. [1] Z. Yaniv, "Which pivot calibration?", Proc. SPIE 9415, 2015.
    .. [2] KUKA System Software 8.x, Operating and Programming Instructions, "TCP
       calibration: XYZ 4-point method".

    Examples
    --------
    >>> from solvers.frames import matrix_from_kuka
    >>> R = matrix_from_kuka([[0, 0, 0, a, b, c] for a, b, c in
    ...     [(0, 180, 0), (0, 150, 0), (90, 150, 0), (180, 150, 0), (0, 180, 35)]])[:, :3, :3]
    >>> t, s = np.array([10.0, -5.0, 200.0]), np.array([600.0, 50.0, 100.0])
    >>> T = np.tile(np.eye(4), (5, 1, 1)); T[:, :3, :3] = R; T[:, :3, 3] = s - R @ t
    >>> res = tcp_xyz_4point(T)
    >>> np.round(res.frame[:3, 3], 6).tolist()
    [10.0, -5.0, 200.0]
    >>> res.report.max_error_mm < 1e-9
    True
    """
    T = _as_flange_poses(flange_poses, 4)
    R = T[:, :3, :3]
    p = T[:, :3, 3]
    n = len(T)

    # orientation spread: angle of R_iᵀR_j from its trace, all pairs at once
    Rf = R.reshape(n, 9)
    G = Rf @ Rf.T  # G_ij = trace(R_iᵀ R_j) = 1 + 2 cos(angle_ij)
    spread = math.degrees(math.acos(min(max((float(G.min()) - 1.0) / 2.0, -1.0), 1.0)))
    if spread < MIN_SPREAD_DEG:
        raise CalibrationError(("flange_poses",), (
            f"orientations too alike: all {n} touch-ups within {spread:.1f} deg of each other, "
            f"so the TCP cannot be told from the touched point; touch up from orientations "
            f"tilted 30-45 deg apart"))

    Rbar, pbar, M, rhs = _pivot_normal(T[:, :3, :])
    w, V = np.linalg.eigh(M)
    tilt0 = math.degrees(2.0 * math.asin(math.sqrt(min(max(float(w[0]), 0.0), 1.0))))
    if tilt0 < DEGENERATE_TILT_DEG:
        v = V[:, 0]
        text, _ = _guidance_text(R, Rbar, None, G)
        raise CalibrationError(("flange_poses",), (
            f"the TCP along {_direction_words(v)} cannot be determined: all orientations rotate "
            f"about one axis ({_direction_words(v)}; orientation spread {spread:.1f} deg, tilt "
            f"about perpendicular axes only {tilt0:.1f} deg); the rotation about "
            f"{_perpendicular_axes_words(v)} is missing -- {text}"))

    t = V @ ((V.T @ rhs) / w)
    s = Rbar @ t + pbar
    r = R @ t + (p - s)
    res = np.sqrt((r * r).sum(axis=1))
    sigma = residual_sigma(r, 6, SIGMA_FLOOR_MM)
    Minv = (V / w) @ V.T
    var = sigma * sigma / n
    cov = var * Minv
    cov_s = var * (_EYE3 + Rbar @ Minv @ Rbar.T)
    # bound95 from the eigenvalues in hand: the largest of Cov(t) is sigma²/(N w_min)
    b95 = math.sqrt(_scale95(3 * n - 6, sigma) * var / float(w[0]))

    findings: list[Finding] = []
    if tilt0 < WEAK_TILT_DEG:
        v = V[:, 0]
        along95 = float(np.sqrt(CHI2_95[1] * (v @ cov @ v)))
        findings.append(Finding("weak_observability", (
            f"the TCP along {_direction_words(v)} is weakly determined: the orientations tilt "
            f"only {tilt0:.1f} deg about axes perpendicular to it (rotation about "
            f"{_perpendicular_axes_words(v)} is missing); +-{along95:.3f} mm (95%) along it"),
            ("flange_poses",)))
    if np.count_nonzero(G > _TRACE_HALF_DEG) > n:  # some pair within 0.5 deg (rare path)
        for i, j in np.argwhere(np.triu(G > _TRACE_HALF_DEG, 1)):
            if np.linalg.norm(p[i] - p[j]) < 0.5:
                findings.append(Finding("duplicate_touch_up", (
                    f"touch-up {j + 1} repeats touch-up {i + 1} (same orientation and position): "
                    f"it adds no information; touch up from a new orientation"),
                    ("flange_poses", int(j))))
    if sigma > LARGE_SIGMA_MM:
        findings.append(Finding("large_residual", (
            f"the touch-ups disagree: residual scatter {sigma:.2f} mm per coordinate (RMS "
            f"distance {float(np.sqrt(res @ res / n)):.2f} mm); is the tool loose or the "
            f"reference tip moving?"), ("flange_poses",)))
    tcp_len = math.sqrt(float(t @ t))
    if tcp_len > MAX_TCP_MM:
        findings.append(Finding("implausible_tcp", f"TCP {tcp_len:.0f} mm from the flange: "
                                f"check the touch-ups", ("flange_poses",)))

    bad = _bad_point_pivot(R, p) if n >= 5 else None
    if bad is not None:
        findings.append(Finding("bad_point", bad.message() + (
            " (TCP without it: {:.3f}, {:.3f}, {:.3f} mm)".format(*bad.refit_frame[:3, 3])),
            ("flange_poses", bad.index)))

    text, Rnew = _guidance_text(R, Rbar, sigma, G)
    report = QualityReport(
        residuals_mm=res, parameter_names=("x_mm", "y_mm", "z_mm"), covariance=cov,
        sigma_mm=sigma, position_bound95_mm=b95, bad_point=bad,
        warnings=tuple(findings), guidance=text, next_orientation=Rnew,
        extras={"point_mm": s, "point_covariance_mm2": cov_s, "spread_deg": spread,
                "tilt_deg": [math.degrees(2.0 * math.asin(math.sqrt(min(max(x, 0.0), 1.0))))
                             for x in w.tolist()],
                "eigenvectors_flange": V})
    return CalibrationResult("tool.xyz_4point", _tcp_frame(t), report)


# --------------------------------------------------------------------------- XYZ reference


def tcp_xyz_reference(reference_point_mm: FloatArray,
                      flange_poses: FloatArray) -> CalibrationResult:
    """XYZ Reference: TCP from touching a point already known in base.

    The point s was measured before with a calibrated reference tool. Each touch-up k gives
    ``t_k = R_kᵀ (s - p_k)``; the TCP is their mean ``t = (1/N) Σ t_k`` (least squares of
    ``R_k t + p_k = s``). Residual ``|R_k t + p_k - s| = |t - t_k|``; sigma from their spread
    (3 parameters, floor ``SIGMA_FLOOR_MM``); ``Cov(t) = sigma²/N · I``;
    ``position_bound95_mm = sqrt(k sigma²/N)`` with ``k = 3 F(3, 3N-3; 0.95)`` (chi2(3) at
    the floor). The reference point's own error is not in the bound (it adds directly).

    Parameters
    ----------
    reference_point_mm : array_like, shape (3,)
        The reference point s in base (mm).
    flange_poses : ndarray, shape (N, 4, 4), N >= 1
        T_base_flange at each touch-up of s with the new tool.

    Returns
    -------
    CalibrationResult
        ``method="tool.xyz_reference"``; ``frame`` = T_flange_tcp, identity rotation;
        report with residuals_mm, covariance (3x3 of ``x_mm, y_mm, z_mm``), sigma_mm,
        position_bound95_mm, bad_point (N >= 4) and ``extras["point_mm"]`` = s.

    Raises
    ------
    CalibrationError
        ``("reference_point_mm", i)`` not finite / wrong shape; ``("flange_poses", ...)``
        no pose, a pose not finite or not rigid; ``("flange_poses",)`` TCP over 5000 mm.

    References
    ----------
    .. [1] KUKA System Software 8.x, Operating and Programming Instructions, "TCP
       calibration: XYZ Reference method".

    Examples
    --------
    >>> from solvers.frames import matrix_from_kuka
    >>> T = matrix_from_kuka([0, 0, 0, 30, 160, 10])
    >>> T[:3, 3] = np.array([700.0, 0, 50]) - T[:3, :3] @ [0, 0, 180.0]
    >>> res = tcp_xyz_reference([700, 0, 50], [T])
    >>> np.round(res.frame[:3, 3], 6).tolist()
    [0.0, 0.0, 180.0]
    """
    s = as_array(reference_point_mm, "reference_point_mm", (3,))
    T = as_transforms(flange_poses, "flange_poses", min_count=1)
    R = T[:, :3, :3]
    p = T[:, :3, 3]
    n = len(T)
    tk = np.einsum("kji,kj->ki", R, s - p)
    t = tk.mean(axis=0)
    d = tk - t
    res = np.linalg.norm(d, axis=1)
    sigma = residual_sigma(d, 3, SIGMA_FLOOR_MM)
    cov = (sigma**2 / n) * np.eye(3)
    b95 = math.sqrt(_scale95(3 * n - 3, sigma) * sigma**2 / n)
    findings: list[Finding] = []
    if np.linalg.norm(t) > MAX_TCP_MM:
        raise CalibrationError(("flange_poses",), (
            f"TCP {np.linalg.norm(t):.0f} mm from the flange (> {MAX_TCP_MM:.0f} mm): is the "
            f"reference point right?"))
    if sigma > LARGE_SIGMA_MM:
        findings.append(Finding("large_residual", (
            f"the touch-ups disagree: residual scatter {sigma:.2f} mm per coordinate; is the "
            f"reference point right and the tool tight?"), ("flange_poses",)))
    if n == 1:
        findings.append(Finding("single_touch", (
            f"one touch-up: the noise cannot be estimated; the bound assumes "
            f"{SIGMA_FLOOR_MM} mm -- touch up 3 or more times"), ("flange_poses",), "info"))
    bad = None
    if n >= 4:
        def fit(idx):
            ti = tk[np.asarray(idx)].mean(axis=0)
            err = np.linalg.norm(tk - ti, axis=1)
            return _tcp_frame(ti), lambda k: float(err[k])

        bad = leave_one_out_bad_point(n, fit, n_parameters=1, floor_mm=0.02, k_sigma=4.0,
                                      min_points=4)
        if bad is not None:
            findings.append(Finding("bad_point", bad.message(), ("flange_poses", bad.index)))
    report = QualityReport(
        residuals_mm=res, parameter_names=("x_mm", "y_mm", "z_mm"), covariance=cov,
        sigma_mm=sigma, position_bound95_mm=b95, bad_point=bad,
        warnings=tuple(findings), extras={"point_mm": s})
    return CalibrationResult("tool.xyz_reference", _tcp_frame(t), report)


# --------------------------------------------------------------------------- ABC menus


def _one_transform(value: object, loc: str) -> FloatArray:
    """A single rigid 4x4 (a ``Pose`` is accepted too), errors on ``(loc, ...)``."""
    if isinstance(value, Pose):
        value = value.as_matrix()
    T = as_array(value, loc, (4, 4))
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise CalibrationError((loc,), "rotation part is not a proper rotation matrix")
    if np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-6:
        raise CalibrationError((loc,), "last row must be [0, 0, 0, 1]")
    return T


def _tcp_vector(tcp_mm: object) -> FloatArray:
    t = as_array(tcp_mm, "tcp_mm", (3,))
    big = np.flatnonzero(np.abs(t) >= MAX_TCP_MM)
    if big.size:
        raise CalibrationError(("tcp_mm", int(big[0])), (
            f"{t[big[0]]:.1f} mm is not a plausible TCP (|value| < {MAX_TCP_MM:.0f} mm)"))
    return t


def _shortest_arc(a: FloatArray, b: FloatArray) -> FloatArray:
    """Rotation of least angle taking unit a onto unit b; for b = -a: 180 deg about x (or y)."""
    axis = np.cross(a, b)
    sn = np.linalg.norm(axis)
    c = float(np.clip(a @ b, -1.0, 1.0))
    if sn < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, _AXES[0])
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(a, _AXES[1])
        return Rotation.from_rotvec(np.pi * perp / np.linalg.norm(perp)).as_matrix()
    return Rotation.from_rotvec(axis / sn * np.arctan2(sn, c)).as_matrix()


def tool_abc_world(flange_pose: FloatArray | Pose, tcp_mm: FloatArray,
                   mode: Literal["5d", "6d"]) -> CalibrationResult:
    """ABC World: tool orientation from one pose aligned with the world axes.

    Alignment convention (our tool z axis is the working direction):

    - ``5d``: the operator jogs until the tool's working direction points straight down,
      tool +z = world -Z. So ``R_flange_tool e_z = a = R_wfᵀ (0, 0, -1)``. Only the axis is
      defined; the rotation chosen is the one with the least twist relative to the flange:
      the shortest-arc rotation taking flange z onto a (if a = -flange z exactly: 180 deg
      about flange x).
    - ``6d``: additionally tool +x = world +X, hence tool +y = world -Y:
      ``R_world_tool = diag(1, -1, -1)`` and ``R_flange_tool = R_wfᵀ diag(1, -1, -1)``.

    (KUKA's own pendant uses the tool X axis as working direction; this service's tool
    axis is z, see docs/conventions.md.) The accuracy is that of the manual alignment.

    Parameters
    ----------
    flange_pose : ndarray, shape (4, 4), or Pose
        T_world_flange with the tool aligned (T_base_flange when base = world).
    tcp_mm : array_like, shape (3,)
        The TCP in the flange frame (mm), from an XYZ menu.
    mode : {"5d", "6d"}

    Returns
    -------
    CalibrationResult
        ``method`` ``"tool.abc_world_5d"`` / ``"tool.abc_world_6d"``; ``frame`` =
        T_flange_tcp (rotation from the alignment, translation tcp_mm); empty residuals;
        ``extras["axis_tilt_deg"]`` angle between the tool axis and the flange z axis.

    Raises
    ------
    CalibrationError
        ``("flange_pose", ...)`` not finite / not rigid; ``("tcp_mm", i)`` not finite or
        |value| >= 5000 mm; ``("mode",)`` not "5d"/"6d".

    References
    ----------
    .. [1] KUKA System Software 8.x, Operating and Programming Instructions, "Defining the
       orientation: ABC World method".

    Examples
    --------
    >>> from solvers.frames import matrix_from_kuka
    >>> res = tool_abc_world(matrix_from_kuka([500, 0, 400, 0, 180, 0]), [0, 0, 150], "6d")
    >>> np.round(res.frame, 6).tolist()[2]
    [0.0, 0.0, 1.0, 150.0]
    """
    mode = mode.lower() if isinstance(mode, str) else mode
    if mode not in ("5d", "6d"):
        raise CalibrationError(("mode",), f"must be '5d' or '6d', got {mode!r}")
    T = _one_transform(flange_pose, "flange_pose")
    t = _tcp_vector(tcp_mm)
    Rwf = T[:3, :3]
    if mode == "6d":
        Rft = Rwf.T @ np.diag([1.0, -1.0, -1.0])
    else:
        Rft = _shortest_arc(_AXES[2], Rwf.T @ np.array([0.0, 0.0, -1.0]))
    tilt = float(np.degrees(np.arccos(np.clip(Rft[2, 2], -1.0, 1.0))))
    findings = [Finding("manual_alignment", (
        "the orientation is as good as the manual alignment (typically 0.5-2 deg); use ABC "
        "2-point for a measured axis"), ("flange_pose",), "info")]
    if tilt > 120.0:
        findings.append(Finding("axis_points_back", (
            f"the tool axis is {tilt:.0f} deg from the flange z axis, i.e. pointing back at the "
            f"robot: was the working direction pointing down (world -Z)?"), ("flange_pose",)))
    report = QualityReport(residuals_mm=np.zeros(0), warnings=tuple(findings),
                           extras={"axis_tilt_deg": tilt, "mode": mode})
    return CalibrationResult(f"tool.abc_world_{mode}", _tcp_frame(t, Rft), report)


def _two_point_rotation(t: FloatArray, R: FloatArray,
                        p: FloatArray) -> tuple[FloatArray, float, float]:
    """R_flange_tool of the 2-point construction, the axis lever and the plane-point radius."""
    q = R[0] @ t + p[0]  # reference point in base
    a = R[1].T @ (q - p[1])  # axis point in flange
    b = R[2].T @ (q - p[2])  # XZ-plane point in flange
    z = t - a
    lever = float(np.linalg.norm(z))
    z = z / max(lever, 1e-300)
    x = (b - t) - ((b - t) @ z) * z
    radius = float(np.linalg.norm(x))
    x = x / max(radius, 1e-300)
    return np.column_stack([x, np.cross(z, x), z]), lever, radius


def tool_abc_2point(tcp_mm: FloatArray, flange_poses: FloatArray) -> CalibrationResult:
    """ABC 2-point: tool axis and XZ plane from three touch-ups of one reference point.

    Touch-up 0: the TCP on the reference point, ``q = R_0 t + p_0`` (base).
    Touch-up 1: a point on the tool axis *behind* the TCP on q: ``a = R_1ᵀ (q - p_1)``.
    Touch-up 2: a point on the tool's +x side of its XZ plane on q: ``b = R_2ᵀ (q - p_2)``.
    Then (flange frame) ``z = (t - a)/|t - a|``, ``x ∝ (b - t) - ((b - t)·z) z``,
    ``y = z × x``, ``T_flange_tcp = [x y z | t]``. The 95% angle bound propagates a nominal
    touch repeatability of ``NOMINAL_TOUCH_SIGMA_MM`` (isotropic, each touch-up) through
    this construction to first order (exactly determined: no residual to estimate it).

    Parameters
    ----------
    tcp_mm : array_like, shape (3,)
        The TCP t in the flange frame (mm).
    flange_poses : ndarray, shape (3, 4, 4)
        T_base_flange at the three touch-ups in the order above.

    Returns
    -------
    CalibrationResult
        ``method="tool.abc_2point"``; ``frame`` = T_flange_tcp; empty residuals;
        ``angle_bound95_deg``, covariance (3x3, deg²) of the rotation vector
        ``("rx_deg", "ry_deg", "rz_deg")`` in the tool frame; ``extras``: ``lever_mm``
        (axis point to TCP), ``radius_mm`` (plane point to the axis).

    Raises
    ------
    CalibrationError
        ``("tcp_mm", i)`` not finite / implausible; ``("flange_poses",)`` not exactly 3
        poses; ``("flange_poses", k, ...)`` not finite / rigid; ``("flange_poses", 1)`` the
        axis point is closer than 5 mm to the TCP; ``("flange_poses", 2)`` the plane point
        lies within 5 mm of the tool axis.

    References
    ----------
    .. [1] KUKA System Software 8.x, Operating and Programming Instructions, "Defining the
       orientation: ABC 2-point method".

    Examples
    --------
    >>> from solvers.frames import matrix_from_kuka
    >>> t = np.array([0.0, 0.0, 150.0]); q = np.array([600.0, 0.0, 100.0])
    >>> T = matrix_from_kuka([[0, 0, 0, 0, 180, 0]] * 3)
    >>> for k, point in enumerate([t, [0, 0, 50.0], [40.0, 0, 150]]):
    ...     T[k, :3, 3] = q - T[k, :3, :3] @ point
    >>> np.round(tool_abc_2point(t, T).frame[:3, :3], 6).tolist()
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    """
    t = _tcp_vector(tcp_mm)
    T = as_transforms(flange_poses, "flange_poses", min_count=3)
    if len(T) != 3:
        raise CalibrationError(("flange_poses",), f"needs exactly 3 poses, got {len(T)}")
    R, p = T[:, :3, :3], T[:, :3, 3]
    Rft, lever, radius = _two_point_rotation(t, R, p)
    if lever < MIN_LEVER_MM:
        raise CalibrationError(("flange_poses", 1), (
            f"the axis point is only {lever:.2f} mm from the TCP: touch a point on the tool "
            f"axis at least {MIN_LEVER_MM:.0f} mm (better 50+ mm) behind the TCP"))
    if radius < MIN_LEVER_MM:
        raise CalibrationError(("flange_poses", 2), (
            f"the plane point lies on the tool axis ({radius:.2f} mm from it): touch a point "
            f"on the tool's +X side at least {MIN_LEVER_MM:.0f} mm from the axis"))
    # first-order propagation of touch noise (3 touches x 3 coordinates, in base)
    J = np.empty((3, 9))
    h = 1e-4
    Rinv = Rotation.from_matrix(Rft).inv()
    for i in range(9):
        dp = p.copy()
        dp[i // 3, i % 3] += h
        Ri, _, _ = _two_point_rotation(t, R, dp)
        J[:, i] = (Rinv * Rotation.from_matrix(Ri)).as_rotvec() / h
    cov = NOMINAL_TOUCH_SIGMA_MM**2 * np.degrees(np.degrees(J @ J.T))
    findings: list[Finding] = [Finding("exactly_determined", (
        f"three touch-ups determine the orientation exactly; the bound assumes "
        f"{NOMINAL_TOUCH_SIGMA_MM} mm touch repeatability"), ("flange_poses",), "info")]
    if Rft[2, 2] < 0:
        findings.append(Finding("axis_points_back", (
            "the tool axis points back towards the flange: was the axis point touched behind "
            "the TCP (between TCP and flange)?"), ("flange_poses", 1)))
    report = QualityReport(residuals_mm=np.zeros(0), parameter_names=("rx_deg", "ry_deg", "rz_deg"),
                           covariance=cov, sigma_mm=NOMINAL_TOUCH_SIGMA_MM,
                           angle_bound95_deg=bound95(cov), warnings=tuple(findings),
                           extras={"lever_mm": lever, "radius_mm": radius})
    return CalibrationResult("tool.abc_2point", _tcp_frame(t, Rft), report)


# --------------------------------------------------------------------------- numeric


def tool_numeric(pose: Pose) -> CalibrationResult:
    """Numeric input: the TCP typed in (x, y, z mm; a, b, c deg, KUKA ``Rz(a) Ry(b) Rx(c)``).

    Parameters
    ----------
    pose : Pose (or array_like of 6)
        T_flange_tcp as x, y, z, a, b, c.

    Returns
    -------
    CalibrationResult
        ``method="tool.numeric"``; ``frame = pose.as_matrix()``; empty report.

    Raises
    ------
    CalibrationError
        ``("pose", name)`` a value not finite, |x|, |y| or |z| >= 5000 mm, or an angle
        beyond +-360 deg.

    Examples
    --------
    >>> np.round(tool_numeric(Pose(0, 0, 120, 0, 30, 0)).frame[:3, 3], 6).tolist()
    [0.0, 0.0, 120.0]
    """
    names = ("x", "y", "z", "a", "b", "c")
    raw = pose.as_array() if isinstance(pose, Pose) else pose
    try:
        v = as_array(raw, "pose", (6,))
    except CalibrationError as e:
        if len(e.loc) == 2 and isinstance(e.loc[1], int):
            raise CalibrationError(("pose", names[e.loc[1]]), e.reason) from None
        raise
    for i, name in enumerate(names):
        limit, unit = (MAX_TCP_MM, "mm") if i < 3 else (360.0, "deg")
        if abs(v[i]) >= limit if i < 3 else abs(v[i]) > limit:
            raise CalibrationError(("pose", name), (
                f"{v[i]:.1f} {unit} is out of range (|{name}| {'<' if i < 3 else '<='} "
                f"{limit:.0f} {unit})"))
    return CalibrationResult("tool.numeric", Pose.from_array(v).as_matrix(),
                             QualityReport(residuals_mm=np.zeros(0)))


__all__ = ["tcp_xyz_4point", "tcp_xyz_reference", "tool_abc_world", "tool_abc_2point",
           "tool_numeric", "next_tcp_orientation"]
