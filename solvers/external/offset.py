"""External kinematics > Offset: a base on the moving flange of a turntable or positioner.

KUKA *Calibrate > External kinematics > Offset* [1]_; ABB's ``BaseFrameMoving`` calibration
(Robot Web Services, 3HAC050973-001, "Calibration for BaseFrameMoving") alike: a work
base that moves with the external axis is stored in the flange frame of the external
kinematic, so the controller can follow it when the axis turns.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.base import (BASE_3POINT_LOCS, POSE_PARAMETERS, as_transform, base_numeric,
                          frame_from_three_points,
                          three_point_report)
from solvers.external.common import TOUCH_SIGMA_MM, rz, scale95
from solvers.frames import Pose
from solvers.report import CalibrationResult, Finding, QualityReport, bound95
from solvers.validate import FloatArray, as_array

def _perturbed(T: FloatArray, d: FloatArray) -> FloatArray:
    """T moved by pose parameters d: origin + d[:3] (parent frame, mm), rotation about its own
    axes by d[3:] (deg) -- the parameters of :data:`POSE_PARAMETERS`."""
    Tp = T.copy()
    Tp[:3, 3] += d[:3]
    Tp[:3, :3] = T[:3, :3] @ Rotation.from_rotvec(d[3:], degrees=True).as_matrix()
    return Tp


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
    :data:`~solvers.base.POSE_PARAMETERS`.

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
        The residual degrees of freedom its sigma was estimated from (``extras["dof"]``); its
        share of the covariance is widened by ``3 F(3, dof) / chi2(3)``, 0 = sigma known.
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
    cov = J3 @ np.array(rep3.covariance) @ J3.T
    warnings = list(rep3.warnings)
    if root_covariance is not None:
        C_root = as_array(root_covariance, "root_covariance", (6, 6))
        J_root = root_jacobian(T_root, T_base_wb, theta)
        C_add = J_root @ C_root @ J_root.T
        # a root sigma estimated from few residuals: widen its share like its own bounds are
        widen = scale95(3, int(root_dof), root_dof > 0) / scale95(3, 0, False)
        cov = cov + widen * C_add
    else:
        warnings.append(Finding("root_uncertainty_ignored", "no root_covariance given: the bounds "
                                "hold the touch noise only, not the root point's uncertainty",
                                ("root_covariance",), "info"))
    report = QualityReport(
        residuals_mm=rep3.residuals_mm, parameter_names=POSE_PARAMETERS, covariance=cov,
        sigma_mm=rep3.sigma_mm, position_bound95_mm=bound95(cov[:3, :3]),
        angle_bound95_deg=bound95(cov[3:, 3:]), warnings=tuple(warnings),
        extras={**rep3.extras, "base_in_robot_base": T_base_wb, "axis_value_deg": theta,
                "flange_frame": T_flange},
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
