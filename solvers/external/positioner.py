"""Two-axis positioner (tilt + turn): calibrated axis by axis, the second given the first.

KUKA calibrates a two-axis positioner as external kinematics axis by axis [1]_; the users'
complaint "the tilt axis tracks along a curve after combined calibration" is what happens when
the turn axis is assumed to cross the tilt axis and does not. Here:

1. the tilt axis (E1) by :func:`~solvers.external.root_point.root_point` from a mark touched
   at >= 3 tilt values with the turn axis at rest;
2. the turn axis (E2) by ``root_point`` from a mark touched at >= 3 turn values with the tilt
   axis at a known value τ; its root frame is carried into the tilt axis' flange frame,
   ``T_tiltflange_turnroot = (T_base_tiltroot Rz(τ))⁻¹ T_base_turnroot``, where it stays
   whatever the tilt;
3. the common normal of the two axes (its length: how far the turn axis misses the tilt axis)
   and the angle between them [2]_.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.base import POSE_PARAMETERS, perturbed
from solvers.external.common import TOUCH_SIGMA_MM, block_dof, cross, line_distance, rz, unit
from solvers.external.root_point import root_point
from solvers.report import CalibrationResult, Finding, QualityReport, bound95
from solvers.validate import FloatArray, as_array

#: a common normal shorter than this (mm) is not reported as "axes do not intersect"
INTERSECT_TOL_MM = 0.5
#: an angle between the axes this close (deg) to the nominal one is not reported
ANGLE_TOL_DEG = 0.2

_STEPS = np.r_[1e-3, 1e-3, 1e-3, 1e-4, 1e-4, 1e-4]


def _axes_geometry(T_tilt: FloatArray, T_turn: FloatArray,
                   tau_deg: float) -> tuple[FloatArray, float, float]:
    """(T_tiltflange_turnroot, signed common normal mm, angle between the axes deg).

    The signed length ``o·m`` with ``m = unit(e_z × w)`` is smooth where the axes intersect
    (|o·m| is not), so its uncertainty can be propagated there."""
    F = T_tilt @ rz([tau_deg])[0]
    X = np.linalg.inv(F) @ T_turn
    m = cross(np.array([0.0, 0.0, 1.0]), X[:3, 2])
    nm = float(np.linalg.norm(m))
    if nm > 1e-9:
        L = float(X[:3, 3] @ m) / nm
    else:  # parallel axes: the distance between them
        L, _, _ = line_distance(np.zeros(3), np.array([0.0, 0.0, 1.0]), X[:3, 3], X[:3, 2])
    angle = float(np.degrees(np.arccos(np.clip(X[2, 2], -1.0, 1.0))))
    return X, L, angle


def _geometry_jacobian(T_tilt: FloatArray, T_turn: FloatArray, tau_deg: float,
                       X: FloatArray) -> FloatArray:
    """J (8, 12): d(signed common normal mm, angle deg, pose parameters of X) / d(the 12 pose
    parameters of the two roots, tilt then turn), by central differences; the 24 relative
    rotations go through one ``Rotation.from_matrix`` call."""
    h = np.r_[_STEPS, _STEPS]
    rows, Xs = [], []
    for i in range(12):
        for sgn in (1.0, -1.0):
            d = np.zeros(12)
            d[i] = sgn * h[i]
            Xd, Ld, ad = _axes_geometry(perturbed(T_tilt, d[:6]), perturbed(T_turn, d[6:]),
                                        tau_deg)
            rows.append([Ld, ad, *(Xd[:3, 3] - X[:3, 3])])
            Xs.append(X[:3, :3].T @ Xd[:3, :3])
    rot = Rotation.from_matrix(np.array(Xs)).as_rotvec(degrees=True)
    G = np.c_[np.array(rows), rot].reshape(12, 2, 8)
    return ((G[:, 0] - G[:, 1]) / (2 * h[:, None])).T


def _common_normal_frame(X: FloatArray) -> FloatArray:
    """The turn root moved along its axis to the foot of the common normal (tilt flange frame):
    origin on the turn axis, z the turn axis, x along the common normal away from the tilt
    axis (or tilt z × turn z when they intersect)."""
    L, f1, f2 = line_distance(np.zeros(3), np.array([0.0, 0.0, 1.0]), X[:3, 3], X[:3, 2])
    z = X[:3, 2]
    x = f2 - f1 if L > 1e-9 else cross(np.array([0.0, 0.0, 1.0]), z)
    x = x - (x @ z) * z
    nx = np.linalg.norm(x)
    x = X[:3, 0] if nx < 1e-9 else x / nx
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, cross(z, x), z])
    T[:3, 3] = f2
    return T


def positioner_2axis(tilt_points_mm: object, tilt_values_deg: object, turn_points_mm: object,
                     turn_values_deg: object, turn_taught_at_tilt_deg: float, *,
                     nominal_tilt_axis: object = (1.0, 0.0, 0.0),
                     nominal_turn_axis: object = (0.0, 0.0, 1.0), nominal_root_mm: object = None,
                     nominal_angle_deg: float = 90.0,
                     touch_sigma_mm: float = TOUCH_SIGMA_MM) -> CalibrationResult:
    """Two-axis positioner: tilt axis, then turn axis given the tilt, with their common normal.

    Each axis by ``root_point`` (plane + circle fit, angles checked against the recorded
    values, its own warnings prefixed ``tilt`` / ``turn``). The turn axis' nominal direction
    is ``nominal_turn_axis`` (robot base, at tilt 0) turned by the fitted tilt axis through
    τ = ``turn_taught_at_tilt_deg``. In the tilt flange frame (z = tilt axis through the
    origin) the turn axis is the line ``(o, w)`` of ``X = T_tiltflange_turnroot``; the common
    normal has length ``|o·(e_z × w)| / |e_z × w|`` and the axes make ``acos(w_z)``. Their
    covariances come from both roots' covariances (independent touch-ups) by first-order
    propagation (central differences), ``C_g = J_t C_tilt J_tᵀ + J_u C_turn J_uᵀ`` over
    (common normal mm, angle deg, the frame's pose parameters mm / deg); ``report.covariance``
    is the frame's block of that plain sum. Each root's share carries a sigma estimated from
    its own ν_t, ν_u = 2N - 6 residual degrees of freedom, so every bound is
    :func:`solvers.report.bound95` of its block with the F quantile of the block's
    Welch-Satterthwaite degrees of freedom [3]_ [4]_ (:func:`~solvers.external.common.block_dof`)

        ``ν = (v_t + v_u)² / (v_t² / ν_t + v_u² / ν_u)``,  ``v_i = share_i / σ̂_i²``

    (share_i root i's variance of the common normal, mm², of the angle between the axes,
    deg², or the trace of the frame's position / angle block; σ̂_i its touch sigma, mm): the
    common normal's bound is ``sqrt(F(1, ν) (share_t + share_u))``. Satterthwaite's ν is that
    of the shares' true variances; both marks are touched with the same tool by the same
    hand, one touch sigma (as ``touch_sigma_mm`` already assumes), so their true ratio is that
    of the shares at unit sigma, known exactly from the geometry, while each share keeps its
    own σ̂_i². The shares with the σ̂_i themselves, each from 2 residual dof at 4 positions,
    give a ν as noisy as the σ̂_i (a σ̂_t² one tenth of σ² pushes ν to ν_u): on the coverage
    scene's 1000 trials that held the common normal 97.4 % (96.3 / 97.1 % on two more seeds)
    instead of 96.9 % (95.3 / 96.6 %). The ν are reported (``extras``: ``common_normal_dof``,
    ``axes_angle_dof``, ``position_dof``, ``angle_dof``) for the chain
    (``solvers.external.chain.report_dofs``). Until 2026-11 each root's share was widened by
    ``F(1, ν_i) / χ²(1)`` (4.8 x the variance at ν = 2) and the sum taken with chi-square: the
    bounds held the truth 97.9-99.5 % of the time instead of 95 %
    (``benchmarks/bounds_coverage.py``, 4 + 4 positions, 1000 trials).

    Parameters
    ----------
    tilt_points_mm, tilt_values_deg : array_like, shapes (N, 3), (N,)
        A mark on the table touched at N >= 3 tilt values (turn axis at rest).
    turn_points_mm, turn_values_deg : array_like, shapes (M, 3), (M,)
        A mark on the table touched at M >= 3 turn values.
    turn_taught_at_tilt_deg : float
        The tilt value while the turn axis was taught.
    nominal_tilt_axis, nominal_turn_axis : array_like, shape (3,), keyword-only
        The machine data's axis directions in the robot base (turn axis at tilt 0).
    nominal_root_mm : array_like, shape (3,), optional, keyword-only
        A point on the nominal tilt axis.
    nominal_angle_deg : float, keyword-only
        The designed angle between the axes.

    Returns
    -------
    CalibrationResult
        ``method="ext.positioner_2axis"``, ``frame = T_tiltflange_turnroot`` (the turn axis'
        root frame as ``root_point`` defines it, in the tilt flange frame); ``covariance`` is
        its own. ``extras``: ``common_normal_frame`` (that frame moved along the turn axis to
        the foot of the common normal, x along the normal), ``tilt`` and ``turn`` (the two
        ``root_point`` results, turn in the robot base), ``tilt_root`` (``T_base_tiltroot``),
        ``common_normal_mm`` and ``common_normal_bound95_mm``, ``axes_angle_deg`` and
        ``axes_angle_bound95_deg``, and the degrees of freedom of each bound (above).

    Raises
    ------
    CalibrationError
        As ``root_point`` for either axis, with the fields named ``tilt_points_mm``,
        ``tilt_values_deg``, ``turn_points_mm``, ``turn_values_deg``.

    References
    ----------
    .. [1] KUKA System Software 8.x, Operating and programming instructions for system
       integrators, "Calibrating external kinematics" (root point and offset per axis).
    .. [2] J. Denavit, R. S. Hartenberg, "A kinematic notation for lower-pair mechanisms based
       on matrices", J. Appl. Mech. 22:215-221, 1955 (the common normal of two joint axes).
    .. [3] F. E. Satterthwaite, "An approximate distribution of estimates of variance
       components", Biometrics Bulletin 2(6), 110-114, 1946.
    .. [4] B. L. Welch, "The generalization of 'Student's' problem when several different
       population variances are involved", Biometrika 34(1/2), 28-35, 1947.

    Examples
    --------
    >>> from solvers.external_sim import make_positioner
    >>> pos = make_positioner(axis_offset_mm=3.0)
    >>> tilt = pos.mark([150, 0, 0], [-60, -20, 20, 60], [0, 0, 0, 0])
    >>> turn = pos.mark([150, 0, 0], [0, 0, 0, 0], [0, 90, 180, 270])
    >>> res = positioner_2axis(tilt, [-60, -20, 20, 60], turn, [0, 90, 180, 270], 0.0)
    >>> ex = res.report.extras
    >>> round(ex["common_normal_mm"], 6), round(ex["axes_angle_deg"], 6)
    (3.0, 90.0)
    """
    tau = float(as_array(turn_taught_at_tilt_deg, "turn_taught_at_tilt_deg", ()))
    n_tilt = unit(nominal_tilt_axis, "nominal_tilt_axis")
    n_turn0 = unit(nominal_turn_axis, "nominal_turn_axis")
    tilt = root_point(tilt_points_mm, tilt_values_deg, nominal_axis=n_tilt,
                      nominal_root_mm=nominal_root_mm, touch_sigma_mm=touch_sigma_mm,
                      points_loc="tilt_points_mm", values_loc="tilt_values_deg")
    tilt_axis = tilt.frame[:3, 2]
    n_turn = Rotation.from_rotvec(np.radians(tau) * tilt_axis).apply(n_turn0)
    turn = root_point(turn_points_mm, turn_values_deg, nominal_axis=n_turn,
                      touch_sigma_mm=touch_sigma_mm, points_loc="turn_points_mm",
                      values_loc="turn_values_deg")
    X, L_signed, angle = _axes_geometry(tilt.frame, turn.frame, tau)
    L = abs(L_signed)

    J = _geometry_jacobian(tilt.frame, turn.frame, tau, X)
    parts = [(J[:, k:k + 6] @ r.report.covariance @ J[:, k:k + 6].T, r.report.extras["dof"] or None)
             for k, r in ((0, tilt), (6, turn))]  # each root's share, sigma from its own dof
    Cg = parts[0][0] + parts[1][0]
    # ν from the shares at one touch sigma (the same tool and touch-ups for both marks): the
    # shares' true ratio, not that of two noisy sigmas (docstring)
    shares = [(C, nu) if r.report.sigma_mm <= 0 else (C / r.report.sigma_mm**2, nu)
              for (C, nu), r in zip(parts, (tilt, turn))]
    nus = {name: block_dof(shares, block) for name, block in (
        ("common_normal", slice(0, 1)), ("axes_angle", slice(1, 2)),
        ("position", slice(2, 5)), ("angle", slice(5, 8)))}
    L_b = bound95(Cg[:1, :1], nus["common_normal"])
    angle_b = bound95(Cg[1:2, 1:2], nus["axes_angle"])

    warnings: list[Finding] = []
    for name, res in (("tilt", tilt), ("turn", turn)):
        for w in res.report.warnings:
            warnings.append(Finding(w.code, f"{name} axis: {w.message}", w.loc, w.severity))
    if L > max(L_b, INTERSECT_TOL_MM):
        warnings.append(Finding("axes_do_not_intersect", f"axes do not intersect: the turn axis "
                                f"misses the tilt axis by {L:.2f} mm (±{L_b:.2f}) along their "
                                "common normal; enter it in the machine data, or the table's "
                                "points will track along a curve when the tilt moves",
                                ("turn_points_mm",)))
    if abs(angle - nominal_angle_deg) > max(angle_b, ANGLE_TOL_DEG):
        warnings.append(Finding("axes_angle", f"the axes make {angle:.3f} deg (±{angle_b:.3f}), "
                                f"designed {nominal_angle_deg:g} deg", ("turn_points_mm",)))
    cov = Cg[2:, 2:]
    guidance = tilt.report.guidance if tilt.report.bad_point is not None else turn.report.guidance
    report = QualityReport(
        residuals_mm=np.r_[tilt.report.residuals_mm, turn.report.residuals_mm],
        residuals_deg=np.r_[tilt.report.residuals_deg, turn.report.residuals_deg],
        parameter_names=POSE_PARAMETERS, covariance=cov,
        sigma_mm=max(tilt.report.sigma_mm, turn.report.sigma_mm),
        position_bound95_mm=bound95(cov[:3, :3], nus["position"]),
        angle_bound95_deg=bound95(cov[3:, 3:], nus["angle"]),
        bad_point=tilt.report.bad_point or turn.report.bad_point, warnings=tuple(warnings),
        guidance=guidance,
        extras={"tilt": tilt, "turn": turn, "tilt_root": tilt.frame, "common_normal_mm": L,
                "common_normal_bound95_mm": L_b, "axes_angle_deg": angle,
                "axes_angle_bound95_deg": angle_b, "common_normal_frame": _common_normal_frame(X),
                **{f"{name}_dof": nu for name, nu in nus.items()}},
    )
    return CalibrationResult("ext.positioner_2axis", X, report)


__all__ = ["positioner_2axis"]
