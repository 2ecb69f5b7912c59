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

from solvers.base import POSE_PARAMETERS
from solvers.external.common import TOUCH_SIGMA_MM, cross, line_distance, rz, scale95, unit
from solvers.external.offset import _perturbed
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


def _geometry_covariance(T_tilt: FloatArray, T_turn: FloatArray, tau_deg: float, X: FloatArray,
                         C: FloatArray) -> FloatArray:
    """Covariance of (signed common normal, angle, pose parameters of X) from the 12 pose
    parameters of the two roots (covariance C), to first order by central differences; the
    24 relative rotations go through one ``Rotation.from_matrix`` call."""
    h = np.r_[_STEPS, _STEPS]
    rows, Xs = [], []
    for i in range(12):
        for sgn in (1.0, -1.0):
            d = np.zeros(12)
            d[i] = sgn * h[i]
            Xd, Ld, ad = _axes_geometry(_perturbed(T_tilt, d[:6]), _perturbed(T_turn, d[6:]),
                                        tau_deg)
            rows.append([Ld, ad, *(Xd[:3, 3] - X[:3, 3])])
            Xs.append(X[:3, :3].T @ Xd[:3, :3])
    rot = Rotation.from_matrix(np.array(Xs)).as_rotvec(degrees=True)
    G = np.c_[np.array(rows), rot].reshape(12, 2, 8)
    J = ((G[:, 0] - G[:, 1]) / (2 * h[:, None])).T
    return J @ C @ J.T


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
    propagation (central differences); 1-D bounds use ``F(1, dof)`` of the smaller dof.

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
        ``common_normal_mm`` and ``common_normal_bound95_mm``, ``axes_angle_deg`` and ``axes_angle_bound95_deg``.

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

    dof_t, dof_u = tilt.report.extras["dof"], turn.report.extras["dof"]
    C = np.zeros((12, 12))
    C[:6, :6] = tilt.report.covariance * scale95(1, dof_t, dof_t > 0) / scale95(1, 0, False)
    C[6:, 6:] = turn.report.covariance * scale95(1, dof_u, dof_u > 0) / scale95(1, 0, False)
    Cg = _geometry_covariance(tilt.frame, turn.frame, tau, X, C)
    z95 = np.sqrt(scale95(1, 0, False))
    L_b = float(z95 * np.sqrt(Cg[0, 0]))
    angle_b = float(z95 * np.sqrt(Cg[1, 1]))

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
        position_bound95_mm=bound95(cov[:3, :3]), angle_bound95_deg=bound95(cov[3:, 3:]),
        bad_point=tilt.report.bad_point or turn.report.bad_point, warnings=tuple(warnings),
        guidance=guidance,
        extras={"tilt": tilt, "turn": turn, "tilt_root": tilt.frame, "common_normal_mm": L,
                "common_normal_bound95_mm": L_b, "axes_angle_deg": angle,
                "axes_angle_bound95_deg": angle_b, "common_normal_frame": _common_normal_frame(X)},
    )
    return CalibrationResult("ext.positioner_2axis", X, report)


__all__ = ["positioner_2axis"]
