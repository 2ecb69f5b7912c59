"""External kinematics > Offset: a base on the moving flange of a turntable or positioner.

KUKA *Calibrate > External kinematics > Offset* [1]_; ABB's ``BaseFrameMoving`` calibration
(Robot Web Services, 3HAC050973-001, "Calibration for BaseFrameMoving") alike: a work
base that moves with the external axis is stored in the flange frame of the external
kinematic, so the controller can follow it when the axis turns.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solvers.base import (BASE_3POINT_LOCS, POSE_PARAMETERS, as_transform, base_numeric,
                          frame_from_three_points, three_point_report)
from solvers.external.common import TOUCH_SIGMA_MM, block_dof, rz
from solvers.frames import Pose
from solvers.report import CalibrationResult, Finding, QualityReport, bound95
from solvers.validate import FloatArray, as_array

def root_jacobian(T_root: FloatArray, T_base_wb: FloatArray, theta_deg: float) -> FloatArray:
    """d(pose parameters of T)/d(pose parameters of T_root) for ``T = Rz(θ)⁻¹ T_root⁻¹ W``.

    With ``T_root' = (t_r + δt, R_r Exp(ω))`` and ``q = R_rᵀ (t_W - t_r)``: the result's
    rotation about its own axes moves by ``-(R_Wᵀ R_r) ω`` and its origin by
    ``R_zᵀ ([q]× ω - R_rᵀ δt)`` (first order; translations mm, rotations deg).

    Examples
    --------
    >>> J = root_jacobian(np.eye(4), np.eye(4), 0.0)
    >>> np.diag(J).tolist()
    [-1.0, -1.0, -1.0, -1.0, -1.0, -1.0]
    """
    Rr, tr = T_root[:3, :3], T_root[:3, 3]
    Rz = rz([theta_deg])[0][:3, :3]
    q = Rr.T @ (T_base_wb[:3, 3] - tr)
    qx = np.array([[0.0, -q[2], q[1]], [q[2], 0.0, -q[0]], [-q[1], q[0], 0.0]])
    J = np.zeros((6, 6))
    J[:3, :3] = -Rz.T @ Rr.T
    J[:3, 3:] = Rz.T @ qx * (np.pi / 180.0)
    J[3:, 3:] = -(T_base_wb[:3, :3].T @ Rr)
    return J


def offset(origin_mm: object, x_point_mm: object, xy_point_mm: object, axis_value_deg: float,
           root_frame: object, *, root_covariance: object = None, root_dof: int = 0,
           root_sigma_mm: float | None = None,
           touch_sigma_mm: float = TOUCH_SIGMA_MM) -> CalibrationResult:
    """Offset: a 3-point base touched on the turntable, stored in the kinematic's flange frame.

    The three points (origin, a point on +X, a point in the XY plane) are touched in the robot
    base at axis value θ and give ``T_base_workbase`` (``x = unit(P2 - P1)``,
    ``z = unit(x × (P3 - P1))``, ``y = z × x`` [2]_). The kinematic's flange at θ is
    ``T_base_flange(θ) = T_base_root Rz(θ)`` (``ext.root_point``), so

        ``T_flange_workbase = Rz(θ)⁻¹ T_base_root⁻¹ T_base_workbase``

    which stays fixed while the axis turns. The covariance adds the touch noise through the
    three points (``three_point_report``, origin turned into the flange frame) and, when given,
    the root frame's covariance carried through ``T_root⁻¹`` to first order,
    ``C = J₃ C_3pt J₃ᵀ + J_r C_root J_rᵀ`` (J_r from :func:`root_jacobian`), all in
    :data:`~solvers.base.POSE_PARAMETERS` (mm², mm·deg, deg²). ``report.covariance`` is that
    plain sum. The touch share rests on the assumed ``touch_sigma_mm`` (known: infinite
    degrees of freedom), the root's on a sigma estimated from ``root_dof`` residual degrees of
    freedom, so each bound is :func:`solvers.report.bound95` of its block of C with the F
    quantile of the block's Welch-Satterthwaite degrees of freedom [3]_ [4]_
    (:func:`~solvers.external.common.block_dof`):

        ``ν_pos = (v_touch + v_root)² / (v_root² / root_dof)``,
        ``v_touch = tr P_touch``,  ``v_root = tr P_root (touch_sigma_mm / root_sigma_mm)²``

    (P the position blocks of the two shares, mm²; the angle's alike with the deg² blocks).
    Satterthwaite's ν is that of the shares' true variances: the root's mark and the three
    points are touched with the same tool by the same hand, one touch sigma, so the root's
    share is weighed at ``touch_sigma_mm`` (``root_sigma_mm``: the sigma its covariance was
    scaled by) while the bound keeps the share as estimated. Weighed with the root's own
    sigma, estimated from 2 residual dof at 4 positions, ν is as noisy as that sigma (a small
    one makes the share look small and ν large): the position bound then held the truth
    93.7 % of the time (93.3 / 94.7 % on two more seeds, 91.2 % over 400 trials of a fourth)
    instead of 95.4 % (94.9 / 96.3 / 94.2 %) (``benchmarks/bounds_coverage.py``). Without
    ``root_sigma_mm`` the share is weighed as given. The ν are reported as
    ``extras["position_dof"]`` and ``extras["angle_dof"]`` (None: every share's sigma known,
    chi-square). The chain (``server.service.external.solve_in_chain``) reads the plain
    covariance with these degrees of freedom (``solvers.external.chain.report_dofs``). Until
    2026-11 the root's share was widened by ``3 F(3, root_dof) / χ²(3)`` (7.3 x the variance at
    ``root_dof`` = 2) and the sum taken with chi-square: the F quantile of the root's own ν
    for a sum that has more, and the bounds held the truth 98.1 % (position) and 97.2 %
    (angle) of the time instead of 95 % (``benchmarks/bounds_coverage.py``, 1000 trials).

    Parameters
    ----------
    origin_mm, x_point_mm, xy_point_mm : array_like, shape (3,)
        P1, P2, P3 touched in the robot base with a calibrated TCP, mm.
    axis_value_deg : float
        The external axis value while the three points were touched.
    root_frame : array_like, shape (4, 4), or Pose
        ``T_base_root`` from ``ext.root_point`` or ``ext.root_point_numeric``.
    root_covariance : array_like, shape (6, 6), optional, keyword-only
        Its covariance (``report.covariance`` of ``ext.root_point``).
    root_dof : int, keyword-only
        The residual degrees of freedom its sigma was estimated from (``extras["dof"]``), for
        the bounds' Welch-Satterthwaite degrees of freedom; 0 = sigma known.
    root_sigma_mm : float, optional, keyword-only
        The sigma its covariance was scaled by (``report.sigma_mm`` of ``ext.root_point``),
        mm: the root's share is weighed at ``touch_sigma_mm`` for the degrees of freedom.
    touch_sigma_mm : float, keyword-only
        Touch-up noise per coordinate (mm).

    Returns
    -------
    CalibrationResult
        ``method="ext.offset"``, ``frame = T_flange_workbase``; ``extras["base_in_robot_base"]``
        is ``T_base_workbase`` as touched.

    Raises
    ------
    CalibrationError
        Points not finite, closer than 10 mm, or collinear (the field of the offending point);
        ``root_frame`` not a rigid transform; ``axis_value_deg`` not finite.

    References
    ----------
    .. [1] KUKA System Software 8.x, Operating and programming instructions for system
       integrators, "Calibrating external kinematics: Offset".
    .. [2] A. D. Udai, NPTEL Industrial Robotics, week 7, lecture 31 (3-point frame).
    .. [3] F. E. Satterthwaite, "An approximate distribution of estimates of variance
       components", Biometrics Bulletin 2(6), 110-114, 1946.
    .. [4] B. L. Welch, "The generalization of 'Student's' problem when several different
       population variances are involved", Biometrika 34(1/2), 28-35, 1947.

    Examples
    --------
    >>> root = np.eye(4); root[:3, 3] = [1500, 0, 300]
    >>> res = offset([1600, 0, 300], [1700, 0, 300], [1600, 100, 300], 90.0, root)
    >>> res.frame[:3, 3].round(6).tolist(), res.frame[:3, 0].round(6).tolist()
    ([0.0, -100.0, 0.0], [0.0, -1.0, 0.0])
    """
    theta = float(as_array(axis_value_deg, "axis_value_deg", ()))
    T_root = as_transform(root_frame, "root_frame")
    T_base_wb = frame_from_three_points(origin_mm, x_point_mm, xy_point_mm)
    P = np.array([as_array(p, loc, (3,)) for p, loc in zip((origin_mm, x_point_mm, xy_point_mm),
                                                            BASE_3POINT_LOCS)])
    T_flange = T_root @ rz([theta])[0]
    T = np.linalg.inv(T_flange) @ T_base_wb
    rep3 = three_point_report(P, BASE_3POINT_LOCS, touch_sigma_mm, frame=T_base_wb)
    # the 3-point covariance is T_base_wb's: T = F⁻¹ T_base_wb keeps the rotation about its own
    # axes, its origin moves by R_Fᵀ δt
    J3 = np.eye(6)
    J3[:3, :3] = T_flange[:3, :3].T
    parts: list[tuple[FloatArray, float | None]] = [(J3 @ np.array(rep3.covariance) @ J3.T,
                                                     None)]  # the touch share: sigma assumed
    warnings = list(rep3.warnings)
    if root_covariance is not None:
        C_root = as_array(root_covariance, "root_covariance", (6, 6))
        J_root = root_jacobian(T_root, T_base_wb, theta)
        parts.append((J_root @ C_root @ J_root.T, int(root_dof) if root_dof > 0 else None))
    else:
        warnings.append(Finding("root_uncertainty_ignored", "no root_covariance given: the bounds "
                                "hold the touch noise only, not the root point's uncertainty",
                                ("root_covariance",), "info"))
    cov = sum(C for C, _ in parts)
    # ν from the shares at one touch sigma (the root's mark and the plate touched alike), not
    # with the root's noisy sigma (docstring)
    shares = parts if root_sigma_mm is None or not root_sigma_mm > 0 or len(parts) < 2 else [
        parts[0], (parts[1][0] * (touch_sigma_mm / float(root_sigma_mm)) ** 2, parts[1][1])]
    nu_pos, nu_ang = block_dof(shares, slice(0, 3)), block_dof(shares, slice(3, 6))
    report = QualityReport(
        residuals_mm=rep3.residuals_mm, parameter_names=POSE_PARAMETERS, covariance=cov,
        sigma_mm=rep3.sigma_mm, position_bound95_mm=bound95(cov[:3, :3], nu_pos),
        angle_bound95_deg=bound95(cov[3:, 3:], nu_ang), warnings=tuple(warnings),
        extras={**rep3.extras, "base_in_robot_base": T_base_wb, "axis_value_deg": theta,
                "flange_frame": T_flange, "position_dof": nu_pos, "angle_dof": nu_ang},
    )
    return CalibrationResult("ext.offset", T, report)


def offset_numeric(pose: Pose | object) -> CalibrationResult:
    """Offset (numeric): the base in the kinematic's flange frame typed in as KUKA X, Y, Z, A, B, C.

    ``T_flange_workbase`` with ``R = Rz(A) @ Ry(B) @ Rx(C)`` (intrinsic Z, Y', X''), mm, deg [1]_.

    Raises
    ------
    CalibrationError
        A value that is not a finite number (loc ``("pose", i)``).

    References
    ----------
    .. [1] KUKA System Software 8.x, "Offset (numeric)".

    Examples
    --------
    >>> offset_numeric(Pose(0, 100, 50, 0, 0, 0)).frame[:3, 3].tolist()
    [0.0, 100.0, 50.0]
    """
    return replace(base_numeric(pose), method="ext.offset_numeric")


__all__ = ["offset", "offset_numeric"]
