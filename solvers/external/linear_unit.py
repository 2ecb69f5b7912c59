"""External kinematics > Linear unit: a rail (track) carrying the robot.

KUKA *Calibrate > External kinematics > Linear unit* [1]_; ABB ``SingleTrack`` alike [2]_. One
fixed mark in the cell is touched from N >= 3 rail positions. The robot moves with the
carriage, so in its own base the mark moves the opposite way:

    ``p_k = p_0 - k e_k d + ε_k``

with d the travel direction in the robot base (unit), k the scale of the encoder (mm of travel
per mm counted, 1 when right) and e_k the recorded rail values. The straight line
``p_k = a + b e_k`` by least squares (three independent regressions on e) gives
``d = -b / |b|`` and ``k = |b|``; the residuals perpendicular to the line are the rail's
straightness.
"""

from __future__ import annotations

import numpy as np

from solvers.errors import CalibrationError
from solvers.external.common import (MIN_OFF_LINE_MM, TOUCH_SIGMA_MM, axis_values,
                                     check_linear_steps, cross, scale95, sigma_from_residuals, unit)
from solvers.report import CalibrationResult, Finding, QualityReport
from solvers.validate import FloatArray, as_points

#: travel direction this far (deg) off nominal is not reported
DIRECTION_TOL_DEG = 0.2
#: |scale - 1| below this is not reported
SCALE_TOL = 0.001
#: a rail whose touch-ups scatter more than this (RMS mm, perpendicular) is "not straight"
STRAIGHTNESS_TOL_MM = 0.2

RAIL_PARAMETERS = ("ax_mm", "ay_mm", "az_mm", "bx", "by", "bz")


def _rail_frame(d: FloatArray) -> FloatArray:
    """``T_base_rail`` rotation: z = travel d, x = the robot base z made perpendicular to d (base
    x when d is nearly vertical), origin the robot base origin."""
    up = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = up - (up @ d) * d
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, cross(d, x), d])
    return T


def linear_unit(points_mm: object, axis_values_mm: object, *,
                nominal_direction: object = (1.0, 0.0, 0.0),
                touch_sigma_mm: float = TOUCH_SIGMA_MM) -> CalibrationResult:
    """Linear unit: travel direction, encoder scale and straightness from one fixed mark.

    ``p_k = a + b e_k`` by least squares: ``b = Σ (e_k - ē)(p_k - p̄) / Σ (e_k - ē)²``,
    ``a = p̄ - b ē``. Travel ``d = -b/|b|`` (robot base), scale ``k = |b|``. With
    ``σ² = Σ |p_k - a - b e_k|² / (3N - 6)`` (at least 0.01 mm),
    ``Cov(b) = σ² I / Σ (e - ē)²``, so the direction has ``σ_d = σ_b / k`` (rad) about each
    perpendicular axis and the scale ``σ_k = σ_b`` [3]_. Named against the machine data:
    *sign reversed* (d·nominal < 0: the encoder counts the other way), *direction wrong*
    (angle beyond its 95 % bound and 0.2 deg), *scale off* (|k - 1| beyond its bound and
    0.1 %), *not straight* (perpendicular RMS > 0.2 mm and beyond 3 sigma of the touch noise).

    The frame is ``T_base_rail``: z the travel direction (KUKA: a linear unit travels along z
    of its transformation), x the robot base z made perpendicular to it, origin at the robot
    base. Its inverse is the robot's base on the carriage up to the rotation about the travel
    direction, which one mark cannot observe.

    Parameters
    ----------
    points_mm : array_like, shape (N, 3)
        The fixed mark touched with a calibrated TCP, in the robot base, N >= 3.
    axis_values_mm : array_like, shape (N,)
        The rail encoder value recorded with each touch-up, mm.
    nominal_direction : array_like, shape (3,), keyword-only
        The travel direction in the machine data, in the robot base.
    touch_sigma_mm : float, keyword-only
        Touch noise for the straightness test.

    Returns
    -------
    CalibrationResult
        ``method="ext.linear_unit"``, ``frame = T_base_rail``; ``angle_bound95_deg`` of the
        direction (2 dof); ``extras``: ``travel_direction``, ``scale``, ``scale_bound95``,
        ``direction_error_deg``, ``straightness_mm`` (largest perpendicular deviation),
        ``mark_at_zero_mm`` (a), ``residual_vectors_mm``, ``base_on_carriage``
        (``T_rail_base``, the robot base in the rail frame: its tilt against the travel).

    Raises
    ------
    CalibrationError
        Fewer than 3 points, not finite (``points_mm``); values not one per point, or two rail
        positions < 10 mm apart (``axis_values_mm``); the mark did not move although the rail
        did (``points_mm``).

    References
    ----------
    .. [1] KUKA System Software 8.x, Operating and programming instructions for system
       integrators, "Calibrating a linear unit".
    .. [2] ABB, Application manual - Robot Web Services, 3HAC050973-001, "Calibration for
       SingleTrack" (``POST /rw/motionsystem/mechunits/{mechunit}/calib``).
    .. [3] N. R. Draper, H. Smith, "Applied Regression Analysis", 3rd ed., Wiley, 1998, ch. 1
       (straight-line regression, variance of the slope).

    Examples
    --------
    >>> e = np.array([0.0, 500.0, 1000.0, 1500.0])
    >>> P = np.array([1200.0, 300.0, 0.0]) - e[:, None] * [1.0, 0.0, 0.0]
    >>> res = linear_unit(P, e)
    >>> res.frame[:3, 2].round(6).tolist(), round(res.report.extras["scale"], 6)
    ([1.0, 0.0, 0.0], 1.0)
    """
    P = as_points(points_mm, "points_mm", min_count=3)
    e = axis_values(axis_values_mm, "axis_values_mm", len(P), "points_mm")
    nominal = unit(nominal_direction, "nominal_direction")
    check_linear_steps(e, "axis_values_mm")
    n = len(P)
    e_bar, p_bar = e.mean(), P.mean(axis=0)
    see = float(((e - e_bar) ** 2).sum())
    b = ((e - e_bar) @ (P - p_bar)) / see
    k = float(np.linalg.norm(b))
    moved = k * (e.max() - e.min())
    if moved < MIN_OFF_LINE_MM:
        raise CalibrationError(("points_mm",), f"the mark moved only {moved:.2f} mm in the robot "
                               f"base while the rail travelled {e.max() - e.min():.0f} mm: did "
                               "the robot ride on the carriage, and was the mark fixed in the "
                               "cell?")
    a = p_bar - b * e_bar
    E = P - (a + np.outer(e, b))
    d = -b / k
    sigma, dof, estimated = sigma_from_residuals(E, 6, touch_sigma_mm)
    sigma_b = sigma / np.sqrt(see)
    k_two, k_one = scale95(2, dof, estimated), scale95(1, dof, estimated)
    angle_b = float(np.degrees(np.sqrt(k_two) * sigma_b / k))
    scale_b = float(np.sqrt(k_one) * sigma_b)
    perp = E - np.outer(E @ d, d)
    perp_norm = np.linalg.norm(perp, axis=1)
    straightness = float(perp_norm.max())
    perp_rms = float(np.sqrt((perp**2).sum() / max(2 * n - 4, 1)))

    warnings: list[Finding] = []
    cosang = float(d @ nominal)
    if cosang < 0:
        warnings.append(Finding("sign_reversed", "sign reversed: increasing rail values move the "
                                "carriage against the nominal travel direction; flip the axis "
                                "direction in the machine data", ("axis_values_mm",)))
    dir_err = float(np.degrees(np.arccos(np.clip(abs(cosang), -1.0, 1.0))))
    if dir_err > max(angle_b, DIRECTION_TOL_DEG):
        warnings.append(Finding("direction_wrong", f"direction wrong: the rail travels "
                                f"{dir_err:.3f} deg (±{angle_b:.3f}) off the nominal direction "
                                "({:.3f}, {:.3f}, {:.3f}) in the robot base: set the travel "
                                "direction (z of the linear unit's transformation) to "
                                "({:.4f}, {:.4f}, {:.4f})".format(*nominal, *d),
                                ("nominal_direction",)))
    if abs(k - 1.0) > max(scale_b, SCALE_TOL):
        warnings.append(Finding("scale_off", f"scale off: the carriage moves {k:.5f} mm per mm "
                                f"counted (±{scale_b:.5f}); correct the encoder scaling",
                                ("axis_values_mm",)))
    if n >= 4 and perp_rms > max(STRAIGHTNESS_TOL_MM, 3.0 * touch_sigma_mm):
        worst = int(np.argmax(perp_norm))
        warnings.append(Finding("not_straight", f"not straight: the mark scatters {perp_rms:.2f} "
                                f"mm RMS across the travel (point {worst + 1}: "
                                f"{straightness:.2f} mm); check the rail's alignment or the "
                                "mark's fixing", ("points_mm", worst)))
    if n == 3:
        warnings.append(Finding("few_points", "3 positions leave 3 redundant numbers: teach 4 or "
                                "more to check the straightness", ("points_mm",), "info"))
    # the next rail position: the far end of the longest unused stretch widens Σ(e - ē)² most
    span = e.max() - e.min()
    guidance = (f"touch the mark again at rail positions beyond {e.min():.0f} .. {e.max():.0f} mm "
                f"(the direction's bound falls with the travel span, now {span:.0f} mm)")

    T = _rail_frame(d)
    cov = np.zeros((6, 6))
    cov[:3, :3] = sigma**2 * (1.0 / n + e_bar**2 / see) * np.eye(3)
    cov[3:, 3:] = sigma_b**2 * np.eye(3)
    cov[:3, 3:] = cov[3:, :3] = -sigma**2 * e_bar / see * np.eye(3)
    report = QualityReport(
        residuals_mm=np.linalg.norm(E, axis=1), parameter_names=RAIL_PARAMETERS, covariance=cov,
        sigma_mm=sigma, position_bound95_mm=float(np.sqrt(scale95(3, dof, estimated)
                                                          * cov[0, 0])),
        angle_bound95_deg=angle_b, warnings=tuple(warnings), guidance=guidance,
        extras={"travel_direction": d, "scale": k, "scale_bound95": scale_b,
                "direction_error_deg": dir_err, "straightness_mm": straightness,
                "straightness_rms_mm": perp_rms, "mark_at_zero_mm": a, "residual_vectors_mm": E,
                "base_on_carriage": np.linalg.inv(T), "dof": dof},
    )
    return CalibrationResult("ext.linear_unit", T, report)


__all__ = ["linear_unit"]
