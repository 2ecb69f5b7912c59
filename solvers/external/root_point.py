"""External kinematics > Root point: the axis of a turntable (or one positioner axis) from one mark.

KUKA *Start-up > Calibrate > External kinematics > Root point* [1]_; ABB's ``RobotAxisRot``
unit calibration alike (>= 4 points, each with its axis value) [2]_.

The result is the *root frame* ``T_base_root`` of the rotary axis, in the robot base:

- z: the axis, oriented so that increasing axis values turn the flange right-handed about z;
- origin: the centre of the mark's circle (the axis point in the mark's plane; where along the
  axis the root sits is not observable from one mark and is fixed this way);
- x: from the centre towards the mark at axis value 0, so the external kinematic's flange frame
  at axis value θ is ``T_base_flange(θ) = T_base_root @ Rz(θ)``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solvers.base import POSE_PARAMETERS, base_numeric
from solvers.errors import CalibrationError
from solvers.external.circle import (CircleFit, _basis, circle_jacobian, fit_circle_3d,
                                     fit_circle_algebraic)
from solvers.external.common import (MIN_OFF_LINE_MM, MIN_RADIUS_MM, SIGMA_FLOOR_MM,
                                     TOUCH_SIGMA_MM, axis_values, check_rotary_steps, cross,
                                     off_line_rms_mm, outlier_critical, scale95,
                                     sigma_from_residuals, unit, wrap_rad)
from solvers.frames import Pose
from solvers.report import BadPoint, CalibrationResult, Finding, QualityReport, bound95
from solvers.validate import FloatArray, as_array, as_points

#: An axis tilted less than this (deg) against nominal is not reported (mechanical tolerance).
TILT_TOL_DEG = 0.2
#: A root point closer than this (mm) to the nominal one is not reported.
ROOT_TOL_MM = 0.5
#: |scale - 1| below this is not reported (0.2 %).
SCALE_TOL = 0.002
#: Angle residuals (RMS, deg) beyond this after the best linear fit: the values do not follow.
AXIS_WRONG_DEG = 1.0
#: An arc of the fitted angles shorter than this (deg) is flagged.
SHORT_ARC_DEG = 90.0


def _root_frame(centre: FloatArray, n: FloatArray, u: FloatArray, v: FloatArray, phi0: float,
                sign: int) -> FloatArray:
    """``T_base_root``: origin c, z = sign n, x towards angle φ0 about n."""
    x = np.cos(phi0) * u + np.sin(phi0) * v
    z = sign * n
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, cross(z, x), z])
    T[:3, 3] = centre
    return T


def _check_points(P: FloatArray, theta_deg: FloatArray, loc: str) -> None:
    """Refuse a mark on the axis and collinear touch-ups (names ``loc``)."""
    d = np.abs(theta_deg[:, None] - theta_deg[None, :]) % 360.0
    d = np.minimum(d, 360.0 - d)
    i, j = np.unravel_index(int(np.argmax(d)), d.shape)
    chord = float(np.linalg.norm(P[i] - P[j]))
    r_est = chord / (2.0 * np.sin(np.radians(max(d[i, j], 1e-9)) / 2.0))
    if r_est < MIN_RADIUS_MM:
        raise CalibrationError((loc,), f"the mark is about {r_est:.1f} mm from the axis (points "
                               f"{i + 1} and {j + 1} are {chord:.2f} mm apart although the axis "
                               f"turned {d[i, j]:.1f} deg): a mark on the axis does not move; put "
                               f"it at least {MIN_RADIUS_MM:g} mm off the axis")
    off = off_line_rms_mm(P)
    if off < MIN_OFF_LINE_MM:
        raise CalibrationError((loc,), f"all {len(P)} touch-ups lie on one line (RMS {off:.2f} "
                               "mm off it): a turning axis moves the mark on a circle; was a "
                               "linear axis moved, or is the mark touched on the axis line?")


def angle_check(fit: CircleFit, P: FloatArray, theta_deg: FloatArray, sigma_mm: float) -> dict:
    """Compare the fitted angles φ_k with the recorded axis values θ_k.

    The sign s = ±1 is the one for which ``φ_k - s θ_k`` scatters least (circular spread);
    the unwrapped angles ``φ_k' = s θ_k + φ0 + wrap(φ_k - s θ_k - φ0)`` then give the scale
    by the regression ``φ_k' = a + ŝ θ_k``, ``σ(ŝ) = (σ/r) / sqrt(Σ(θ-θ̄)²)``. The frame uses
    ``φ0 = circmean(φ_k - s θ_k)`` (unit scale); its residuals are ``residuals_deg``.
    """
    th = np.radians(theta_deg)
    phi = fit.angles_rad(P)
    best = None
    for s in (1, -1):
        d = phi - s * th
        phi0 = float(np.angle(np.exp(1j * d).mean()))
        e = wrap_rad(d - phi0)
        spread = float(np.sqrt(np.mean(e**2)))
        if best is None or spread < best[0] - 1e-12:
            best = (spread, s, phi0, e)
    _, s, phi0, e = best
    phi_u = s * th + phi0 + e
    A = np.c_[np.ones_like(th), th]
    (a, slope), *_ = np.linalg.lstsq(A, phi_u, rcond=None)
    lin = phi_u - (a + slope * th)
    sxx = float(((th - th.mean()) ** 2).sum())
    sigma_phi = sigma_mm / fit.radius_mm
    return {"sign": s, "phi0": phi0, "residuals_rad": e, "slope": float(slope),
            "slope_sigma": sigma_phi / np.sqrt(sxx), "linear_rms_deg": float(np.degrees(
                np.sqrt(np.mean(lin**2)))), "sigma_phi": sigma_phi, "phi": phi}


def _next_axis_value(fit: CircleFit, phi0: float, sign: int,
                     limits_deg: FloatArray) -> tuple[float, FloatArray]:
    """The axis value whose touch-up shrinks the centre and axis uncertainty most.

    Candidate points on the fitted circle every 5 deg within the limits; the one minimising
    ``tr C_c + r² tr C_tilt`` of ``(JᵀJ + J_newᵀ J_new)⁻¹`` (unit sigma). Returns (value,
    the centre's covariance C_c with that point added, unit sigma)."""
    JtJ = fit.jacobian.T @ fit.jacobian
    cand = np.arange(limits_deg[0], limits_deg[1] + 1e-9, 5.0)
    phis = phi0 + sign * np.radians(cand)
    pts = fit.centre_mm + fit.radius_mm * (np.cos(phis)[:, None] * fit.u
                                           + np.sin(phis)[:, None] * fit.v)
    Jn = circle_jacobian(pts, fit.centre_mm, fit.normal, fit.u, fit.v).reshape(len(cand), 2, 6)
    M = JtJ[None] + np.einsum("kai,kaj->kij", Jn, Jn)
    C = np.linalg.inv(M)
    cost = np.trace(C[:, :3, :3], axis1=1, axis2=2) + fit.radius_mm**2 * (C[:, 3, 3] + C[:, 4, 4])
    k = int(np.argmin(cost))
    return float(cand[k]), C[k, :3, :3]


def root_point(points_mm: object, axis_values_deg: object, *,
               nominal_axis: object = (0.0, 0.0, 1.0), nominal_root_mm: object = None,
               touch_sigma_mm: float = TOUCH_SIGMA_MM, axis_limits_deg: object = (-180.0, 180.0),
               points_loc: str = "points_mm",
               values_loc: str = "axis_values_deg") -> CalibrationResult:
    """Root point: one mark on the turning flange touched at N >= 3 (better >= 4) axis values.

    1. Plane by SVD of the centred points: its normal is the axis direction [3]_.
    2. Circle in that plane (Kåsa [4]_), refined as the orthogonal-distance circle in space,
       ``min Σ_k h_k² + (ρ_k - r)²`` over centre c, normal n and radius r
       (:func:`~solvers.external.circle.fit_circle_3d`, maximum likelihood for isotropic touch
       noise; the recorded axis values are *not* used, so they can be checked).
    3. Fitted angles ``φ_k = atan2((p_k - c)·v, (p_k - c)·u)`` against the recorded ``θ_k``:
       sign ``s`` and scale ``ŝ`` of ``φ_k ≈ φ0 + ŝ θ_k`` (:func:`angle_check`). A
       disagreement is named: *sign reversed* (s = -1 about the nominal axis), *scale off*
       (|ŝ| ≠ 1 beyond its 95 % bound and 0.2 %), *axis wrong* (the angles do not follow
       the values at all), and against the nominal machine data *axis tilted* and
       *root offset*.

    ``T_base_root``: origin c, ``z = s n``, x towards the mark at θ = 0 (module docstring).
    Covariance of the circle ``C = σ² (JᵀJ)⁻¹`` (J of the stacked ``[h_k, ρ_k - r]``),
    ``σ² = SSR / (2N - 6)`` (``touch_sigma_mm`` when N = 3); the angle about the axis adds
    ``σ² / (N r²)``. The bounds are :func:`solvers.report.bound95` of the centre's and of the
    tilts' covariance blocks (F quantiles with ν = 2N - 6 when σ is estimated), like every
    other method's: the 95 % radius of the error's actual ellipsoid. (Until 2026-11 they were
    ``sqrt(k F(k, ν) λ_max)``, the radius of a sphere as wide as the ellipsoid's longest axis:
    the centre's ellipsoid over a 270 deg arc has axes about 1 : 0.8 : 0.65, so that bound
    held the truth 98 % of the time instead of 95 % -- wide, not honest.)

    Parameters
    ----------
    points_mm : array_like, shape (N, 3)
        The mark touched with a calibrated TCP, in the robot base, mm.
    axis_values_deg : array_like, shape (N,)
        The external axis value recorded with each touch-up, deg.
    nominal_axis : array_like, shape (3,), keyword-only
        The axis direction in the machine data (robot base); positive values should turn the
        flange right-handed about it. Default +z (a table with a vertical axis).
    nominal_root_mm : array_like, shape (3,), optional, keyword-only
        A point on the nominal axis (the machine data's root): its distance from the fitted
        axis is reported as ``extras["root_offset_mm"]``.
    touch_sigma_mm : float, keyword-only
        Touch noise assumed when N = 3 leaves no redundancy.
    axis_limits_deg : array_like, shape (2,), keyword-only
        Where the next axis value may be suggested.

    Returns
    -------
    CalibrationResult
        ``method="ext.root_point"``, ``frame = T_base_root``. ``report.covariance`` is that of
        the root frame (``POSE_PARAMETERS``), ``position_bound95_mm`` the centre's,
        ``angle_bound95_deg`` the axis direction's (2 dof). ``extras``: ``axis_direction``,
        ``centre_mm``, ``radius_mm``, ``scale`` (ŝ, signed), ``scale_bound95``,
        ``axis_tilt_deg``, ``root_offset_mm``, ``angle_residuals_deg`` (signed),
        ``circle_covariance``, ``next_axis_value_deg``.

    Raises
    ------
    CalibrationError
        Fewer than 3 points or not finite (``points_mm``); values not one per point
        (``axis_values_deg``); two axis values < 10 deg apart (``axis_values_deg``, k); the mark
        on the axis or the touch-ups on one line (``points_mm``).

    References
    ----------
    .. [1] KUKA System Software 8.x, Operating and programming instructions for system
       integrators, "Calibrating external kinematics: Root point calibration" and "Offset".
    .. [2] ABB, Application manual - Robot Web Services, 3HAC050973-001, "Calibration for
       RobotAxisRot" (``POST /rw/motionsystem/mechunits/{mechunit}/calib``, at least 4
       points, each ``[x, y, z, q1, q2, q3, q4, axis_value]``).
    .. [3] C. M. Shakarji, J. Res. NIST 103(6):633-641, 1998.
    .. [4] I. Kåsa, IEEE Trans. Instrum. Meas. IM-25(1):8-14, 1976.

    Examples
    --------
    >>> a = np.radians([0, 90, 180, 270])
    >>> P = np.c_[250 * np.cos(a), 250 * np.sin(a), np.zeros(4)] + [1500, 0, 300]
    >>> res = root_point(P, [0, 90, 180, 270])
    >>> res.frame[:3, 3].round(6).tolist(), res.frame[:3, 2].round(6).tolist()
    ([1500.0, 0.0, 300.0], [0.0, 0.0, 1.0])
    >>> res = root_point(P, [0, -90, -180, -270])
    >>> [w.code for w in res.report.warnings]
    ['sign_reversed']
    """
    P = as_points(points_mm, points_loc, min_count=3)
    theta = axis_values(axis_values_deg, values_loc, len(P), points_loc)
    nominal = unit(nominal_axis, "nominal_axis")
    q_root = None if nominal_root_mm is None else as_array(nominal_root_mm, "nominal_root_mm", (3,))
    limits = as_array(axis_limits_deg, "axis_limits_deg", (2,))
    check_rotary_steps(theta, values_loc)
    _check_points(P, theta, points_loc)
    n_pts = len(P)

    fit = fit_circle_3d(P, towards=nominal)
    sigma, dof, estimated = sigma_from_residuals(fit.residual_vectors_mm, 6, touch_sigma_mm)
    C6 = sigma**2 * np.linalg.inv(fit.jacobian.T @ fit.jacobian)
    ang = angle_check(fit, P, theta, sigma)
    s, phi0 = ang["sign"], ang["phi0"]
    r = fit.radius_mm

    # covariance of (c, a, b, r, φ0): φ0 = mean(φ_k - s θ_k) moves with c through the tangents
    w = P - fit.centre_mm
    tang = cross(fit.normal, w - (w @ fit.normal)[:, None] * fit.normal)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    g = np.r_[-tang.mean(axis=0) / r, 0.0, 0.0, 0.0]
    C7 = np.zeros((7, 7))
    C7[:6, :6] = C6
    C7[6, :6] = C7[:6, 6] = g @ C6
    C7[6, 6] = g @ C6 @ g + sigma**2 / (n_pts * r**2)

    T = _root_frame(fit.centre_mm, fit.normal, fit.u, fit.v, phi0, s)
    # root frame pose parameters: δorigin = δc; small rotation in base ω = a u + b v + δφ0 n
    # (the tilt moves z, φ0 turns x about n), about the frame's own axes Rᵀω, in deg
    J = np.zeros((6, 7))
    J[:3, :3] = np.eye(3)
    J[3:, 3], J[3:, 4], J[3:, 6] = (np.degrees(T[:3, :3].T @ e) for e in (fit.u, fit.v, fit.normal))
    C_root = J @ C7 @ J.T

    k_one = scale95(1, dof, estimated)
    nu = dof if estimated and dof > 0 else None  # None: sigma assumed, chi-square
    pos_b = bound95(C6[:3, :3], nu)
    axis_b = float(np.degrees(bound95(C6[3:5, 3:5], nu)))
    radius_b = float(np.sqrt(k_one * C6[5, 5]))
    scale_b = float(np.sqrt(k_one) * ang["slope_sigma"])

    warnings: list[Finding] = []
    lin_rms = ang["linear_rms_deg"]
    lin_allow = max(AXIS_WRONG_DEG, 5.0 * np.degrees(ang["sigma_phi"]))
    axis_wrong = n_pts >= 3 and lin_rms > lin_allow
    if axis_wrong:
        warnings.append(Finding("axis_wrong", f"axis wrong: the mark's angles do not follow the "
                                f"recorded axis values (RMS {lin_rms:.2f} deg off the best "
                                f"straight line): was another axis moved or recorded?",
                                (values_loc,)))
    if s < 0 and not axis_wrong:
        warnings.append(Finding("sign_reversed", "sign reversed: increasing axis values turn the "
                                "flange clockwise about the nominal axis ({:.2f}, {:.2f}, {:.2f}); "
                                "flip the axis direction in the machine data".format(*nominal),
                                (values_loc,)))
    scale_dev = abs(abs(ang["slope"]) - 1.0)
    if not axis_wrong and scale_dev > max(scale_b, SCALE_TOL):
        warnings.append(Finding("scale_off", f"scale off: the flange turns {abs(ang['slope']):.4f} "
                                f"deg per deg of axis value (±{scale_b:.4f}); check the gear "
                                f"ratio in the machine data", (values_loc,)))
    tilt_deg = float(np.degrees(np.arccos(np.clip(fit.normal @ nominal, -1.0, 1.0))))
    if tilt_deg > max(axis_b, TILT_TOL_DEG):
        warnings.append(Finding("axis_tilted", f"axis tilted: the fitted axis is {tilt_deg:.3f} "
                                f"deg (±{axis_b:.3f}) off the nominal axis ({nominal[0]:.2f}, "
                                f"{nominal[1]:.2f}, {nominal[2]:.2f})", ("nominal_axis",)))
    root_offset = root_offset_b = None
    if q_root is not None:
        # distance of q from the line (c, n): e = (I - n nᵀ)(q - c),
        # d|e| = -ê·δc - (n·w) ê·δn with δn = -a v + b u
        w_q = q_root - fit.centre_mm
        e_q = w_q - (w_q @ fit.normal) * fit.normal
        root_offset = float(np.linalg.norm(e_q))
        e_hat = e_q / max(root_offset, 1e-12)
        h_q = float(w_q @ fit.normal)
        j = np.r_[-e_hat, h_q * (e_hat @ fit.v), -h_q * (e_hat @ fit.u), 0.0]
        root_offset_b = float(np.sqrt(k_one * (j @ C6 @ j)))
        if root_offset > max(root_offset_b, ROOT_TOL_MM):
            warnings.append(Finding("root_offset", f"root offset: the fitted axis runs "
                                    f"{root_offset:.2f} mm (±{root_offset_b:.2f}) from the "
                                    f"nominal root point", ("nominal_root_mm",)))

    phi = ang["phi"]
    span = _covered_arc_deg(phi)
    if span < SHORT_ARC_DEG:
        warnings.append(Finding("short_arc", f"the touch-ups cover only {span:.0f} deg of the "
                                f"circle: {SHORT_ARC_DEG:g} deg or more keeps centre and axis "
                                "steadier",
                                (values_loc,)))
    if n_pts == 3:
        warnings.append(Finding("few_points", "3 points fix a circle exactly: the residuals are "
                                "zero and the bounds assume touch_sigma_mm; teach 4 or more to "
                                "check them",
                                (points_loc,), "info"))

    phi_u = s * np.radians(theta) + phi0 + ang["residuals_rad"]
    bad = None if axis_wrong else circle_bad_point(P, phi_u, np.radians(theta), touch_sigma_mm,
                                                   frame=T)
    next_value, next_C = _next_axis_value(fit, phi0, s, limits)
    if bad is not None:
        warnings.append(Finding("bad_point", bad.message(), (points_loc, bad.index)))
        guidance = f"re-teach point {bad.index + 1}"
    else:
        guidance = (f"touch the mark at axis value {next_value:.0f} deg next: the centre's 95 % "
                    f"bound would shrink from {pos_b:.3f} to about "
                    f"{bound95(sigma**2 * next_C, None if nu is None else nu + 2):.3f} mm")

    report = QualityReport(
        residuals_mm=fit.distances_mm,
        residuals_deg=np.degrees(np.abs(ang["residuals_rad"])),
        parameter_names=POSE_PARAMETERS,
        covariance=C_root,
        sigma_mm=sigma,
        position_bound95_mm=pos_b,
        angle_bound95_deg=axis_b,
        bad_point=bad,
        warnings=tuple(warnings),
        guidance=guidance,
        extras={"axis_direction": T[:3, 2].copy(), "centre_mm": fit.centre_mm.copy(),
                "radius_mm": r, "radius_bound95_mm": radius_b, "scale": ang["slope"],
                "scale_bound95": scale_b, "sign": s, "axis_tilt_deg": tilt_deg,
                "root_offset_mm": root_offset, "root_offset_bound95_mm": root_offset_b,
                "angles_deg": np.degrees(phi),
                "angle_residuals_deg": np.degrees(ang["residuals_rad"]),
                "covered_arc_deg": span, "circle_covariance": C6, "dof": dof,
                "next_axis_value_deg": next_value},
    )
    return CalibrationResult("ext.root_point", T, report)


def _refit_frame(centre: FloatArray, normal: FloatArray, frame: FloatArray | None) -> FloatArray:
    """A root frame at ``centre`` with z along ``normal`` (turned as ``frame``'s z) and x as
    ``frame``'s x projected into the plane (any perpendicular without ``frame``): a rotation."""
    ref = np.eye(4) if frame is None else np.asarray(frame, dtype=float)
    z = normal if normal @ ref[:3, 2] >= 0 else -normal
    x = ref[:3, 0] - (ref[:3, 0] @ z) * z
    if np.linalg.norm(x) < 1e-9:  # the reference x along the axis: any perpendicular
        x, _ = _basis(z)
    x = x / np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, cross(z, x), z])
    T[:3, 3] = centre
    return T


def circle_bad_point(points_mm: FloatArray, phi_rad: FloatArray, theta_rad: FloatArray,
                     touch_sigma_mm: float, false_alarm: float = 0.01,
                     frame: FloatArray | None = None) -> BadPoint | None:
    """The one touch-up that disagrees with the others (N >= 5), by leave-one-out prediction.

    For each k the others give the circle (:func:`~solvers.external.circle.fit_circle_algebraic`)
    and the line ``φ = a + ŝ θ`` through their unwrapped angles ``phi_rad``; they predict
    ``e_k = [h_k, ρ_k - r, r (φ_k - a - ŝ θ_k)]`` (mm: off the plane, off the radius, along the
    circle) with covariance ``σ² S``, ``S = diag(I + J_k (JᵀJ)⁻¹ J_kᵀ, 1 + 1/(N-1) +
    (θ_k - θ̄)² / Σ(θ - θ̄)²)`` and ``σ = max(σ̂_others, touch_sigma_mm)``. Point k is bad
    when
    ``e_kᵀ S⁻¹ e_k / σ²`` exceeds the ``1 - false_alarm / N`` quantile of ``3 F(3, dof)``
    (``chi2(3)`` when σ is the nominal one): the externally studentised residual with a
    Bonferroni correction over the N points [1]_. The worst such point is named, with the
    root frame the others give (``refit_frame``: their centre, z along their normal turned as
    ``frame``'s z, x as ``frame``'s x in their plane; a rotation, whatever way the axis points).

    References
    ----------
    .. [1] R. D. Cook, S. Weisberg, "Residuals and Influence in Regression", Chapman & Hall,
       1982, ch. 2 (externally studentised residuals, outlier test with Bonferroni bound).
    """
    P = np.asarray(points_mm, dtype=float)
    n = len(P)
    if n < 5:
        return None
    worst = None
    q = 1.0 - false_alarm / n
    for k in range(n):
        idx = [j for j in range(n) if j != k]
        c, nrm, r = fit_circle_algebraic(P[idx])
        d = P[idx] - c
        h = d @ nrm
        th = theta_rad[idx]
        A = np.c_[np.ones(n - 1), th]
        (a0, slope), *_ = np.linalg.lstsq(A, phi_rad[idx], rcond=None)
        res = np.c_[h, np.linalg.norm(d - h[:, None] * nrm, axis=1) - r,
                    r * (phi_rad[idx] - a0 - slope * th)]
        dof = res.size - 8
        s_hat = float(np.sqrt((res**2).sum() / dof))
        estimated = s_hat > touch_sigma_mm
        sigma = s_hat if estimated else touch_sigma_mm
        u, v = _basis(nrm)
        J = circle_jacobian(P[idx], c, nrm, u, v)
        Jk = circle_jacobian(P[k:k + 1], c, nrm, u, v)
        S = np.zeros((3, 3))
        S[:2, :2] = np.eye(2) + Jk @ np.linalg.solve(J.T @ J, Jk.T)
        dth = th - th.mean()
        S[2, 2] = 1.0 + 1.0 / (n - 1) + (theta_rad[k] - th.mean()) ** 2 / (dth @ dth)
        dk = P[k] - c
        hk = float(dk @ nrm)
        e = np.array([hk, np.linalg.norm(dk - hk * nrm) - r,
                      r * (phi_rad[k] - a0 - slope * theta_rad[k])])
        stat = float(e @ np.linalg.solve(S, e)) / sigma**2
        crit = outlier_critical(3, dof if estimated else 0, q)
        if stat > crit and (worst is None or stat / crit > worst[0]):
            allow = float(sigma * np.sqrt(crit * np.linalg.eigvalsh(S).max()))
            T = _refit_frame(c, nrm, frame)
            worst = (stat / crit, k, float(np.linalg.norm(e)), allow, T,
                     float(np.sqrt(np.mean((res**2).sum(axis=1)))))
    if worst is None or worst[2] <= SIGMA_FLOOR_MM:
        return None
    _, k, e, allow, T, rms = worst
    return BadPoint(index=k, residual_mm=e, threshold_mm=allow, refit_frame=T, refit_rms_mm=rms)


def _covered_arc_deg(phi: FloatArray) -> float:
    """The arc the angles cover: 360 deg minus the largest gap between neighbours."""
    a = np.sort(np.mod(phi, 2 * np.pi))
    gaps = np.diff(np.r_[a, a[0] + 2 * np.pi])
    return float(np.degrees(2 * np.pi - gaps.max()))


def root_point_numeric(pose: Pose | object) -> CalibrationResult:
    """Root point (numeric): the root frame typed in as KUKA X, Y, Z, A, B, C (mm, deg).

    ``T_base_root`` with ``R = Rz(A) @ Ry(B) @ Rx(C)`` (intrinsic Z, Y', X''): z is the axis,
    from the manufacturer's data sheet or a measurement [1]_.

    Raises
    ------
    CalibrationError
        A value that is not a finite number (loc ``("pose", i)``).

    References
    ----------
    .. [1] KUKA System Software 8.x, "Root point (numeric)".

    Examples
    --------
    >>> res = root_point_numeric(Pose(1500, 0, 300, 0, 0, 0))
    >>> res.frame[:3, 3].tolist(), res.method
    ([1500.0, 0.0, 300.0], 'ext.root_point_numeric')
    """
    return replace(base_numeric(pose), method="ext.root_point_numeric")


__all__ = ["root_point", "root_point_numeric", "angle_check"]
