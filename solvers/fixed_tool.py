"""Fixed tool > 5D / 6D: an external (stationary) TCP measured with a calibrated robot tool.

The controller stores the result like a base (KUKA BASE_DATA of type #TCP): the pose of the
fixed tool in world, ``T_world_fixedtool``, whose z axis is the fixed tool's axis.

Step 1, touch: the calibrated robot tool's TCP is jogged onto the fixed TCP, so the fixed
TCP's position in world is ``r = R_F1 t + f_1`` (flange pose 1, tool TCP t in flange).
Step 2, align: the flange frame F is jogged parallel to the fixed tool's frame E with
``-Z_E`` along ``+Z_F``, ``X_E`` along ``X_F`` and ``Y_E`` along ``-Y_F``: ``R_F_E = Rx(180°)``,
so ``R_world_E = R_world_F2 @ Rx(180°)`` [1]_.

References
----------
.. [1] A. D. Udai, "Fixed tool calibration: external TCP and workpiece calibration", NPTEL
   Industrial Robotics, week 7, lecture 31 (external TCP, 5D and 6D methods).
"""

from __future__ import annotations

from typing import Literal

import math

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.base import as_transform
from solvers.frames import angle_between_deg
from solvers.report import (CalibrationResult, Finding, QualityReport, bounds95, residual_sigma,
                            sigma_dof)
from solvers.validate import FloatArray, as_array, as_transforms

# Flange frame F relative to the fixed tool frame E at alignment: 180 deg about X.
R_FLANGE_FIXEDTOOL = Rotation.from_euler("x", 180.0, degrees=True).as_matrix()
TOUCH_SPREAD_WARN_MM = 0.5  # extra touches farther apart than this: the robot tool's TCP is off
#: The flange stands on the fixed tool's +Z side (above its tip) at a correct touch and
#: alignment; every flange position this far (deg) below the plane across the axis through
#: the fixed TCP means the alignment was done the other way round.
FLIP_ELEVATION_DEG = -30.0
FLIP_MIN_DISTANCE_MM = 10.0  # flange positions closer than this to r tell nothing


def axis_frame_5d(z_axis: FloatArray) -> FloatArray:
    """Rotation whose z column is ``z_axis``; X is world +X projected across the axis.

    The 5D convention: only the tool axis is measured, so X is chosen as the projection of
    world +X onto the plane perpendicular to the axis, ``x = unit(e_x - (e_x . z) z)``, and
    ``y = z × x``. Within 1 deg of world ±X that projection vanishes and world -Z is
    projected instead. No rule is continuous for every axis direction (a hairy-ball fact):
    this one puts its seam where fixed tools rarely point (along world ±X), so an axis
    straight down (``z = -e_z``, the 180 deg turn about world X) and every tilt around it give
    an X that moves smoothly with the axis.

    Examples
    --------
    >>> axis_frame_5d([0, 0, -1]).round(6).tolist()
    [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]
    >>> axis_frame_5d([1, 0, 0]).round(6).tolist()  # along world X: X from world -Z
    [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]
    """
    z = np.asarray(z_axis, dtype=float)
    z = z / np.linalg.norm(z)
    ref = np.array([1.0, 0.0, 0.0])
    if abs(z @ ref) > math.cos(math.radians(1.0)):
        ref = np.array([0.0, 0.0, -1.0])
    x = ref - (ref @ z) * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def flange_elevation_deg(flange_positions_mm: FloatArray, fixed_tcp_mm: FloatArray,
                         z_axis: FloatArray) -> FloatArray:
    """Elevation (deg) of each flange position above the plane through the fixed TCP across
    its axis: ``asin((f_k - r) . z_E / |f_k - r|)``; NaN within ``FLIP_MIN_DISTANCE_MM`` of r.

    A robot reaches a fixed tool from the side its tip faces: touching the fixed TCP with a
    pointer and aligning with flange +Z pointing into the fixed tool, the flange stands on the
    +Z_E side (elevation > 0; about 0 for a touch from the side). Elevations all well below 0
    mean z_E points into the fixed tool: the alignment was done the other way round.

    Examples
    --------
    >>> flange_elevation_deg([[600, 0, 400], [700, 0, 300]], [600, 0, 300], [0, 0, 1]).round(6).tolist()
    [90.0, 0.0]
    """
    d = np.asarray(flange_positions_mm, dtype=float) - np.asarray(fixed_tcp_mm, dtype=float)
    dist = np.linalg.norm(d, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        sin = np.clip(d @ np.asarray(z_axis, dtype=float) / dist, -1.0, 1.0)
    return np.where(dist < FLIP_MIN_DISTANCE_MM, np.nan, np.degrees(np.arcsin(sin)))


def _fixed_tool(mode: Literal["5d", "6d"], touch_flange_pose: object, tool_tcp_mm: object,
                align_flange_pose: object, extra_touch_poses: object) -> CalibrationResult:
    T1 = as_transform(touch_flange_pose, "touch_flange_pose")
    tcp = as_array(tool_tcp_mm, "tool_tcp_mm", (3,))
    T2 = as_transform(align_flange_pose, "align_flange_pose")
    touches = T1[None]
    if extra_touch_poses is not None:
        extra = as_transforms(extra_touch_poses, "extra_touch_poses", min_count=0)
        touches = np.concatenate([touches, extra])
    tips = touches[:, :3, :3] @ tcp + touches[:, :3, 3]  # robot tool TCP at each touch, world
    r = tips.mean(axis=0)
    residuals = np.linalg.norm(tips - r, axis=1)

    R6 = T2[:3, :3] @ R_FLANGE_FIXEDTOOL  # the lecture's B_Q_E = B_Q_F F_Q_E
    z_axis = R6[:, 2]  # = -Z of the aligned flange
    R = R6 if mode == "6d" else axis_frame_5d(z_axis)
    frame = np.eye(4)
    frame[:3, :3] = R
    frame[:3, 3] = r

    warnings: list[Finding] = []
    if np.linalg.norm(tcp) < 1.0:
        warnings.append(Finding("tcp_at_flange", "tool_tcp_mm is the flange centre: touch with a "
                                "calibrated tool, not the bare flange", ("tool_tcp_mm",), "info"))
    n = len(tips)
    cov = sigma = None
    bounds: dict = {}
    if n > 1:
        sigma = residual_sigma(tips - r, 3)
        cov = np.eye(3) * sigma**2 / n
        bounds = bounds95(cov, sigma_dof(sigma, 3 * (n - 1)))
        worst = int(np.argmax(residuals))
        if residuals[worst] > TOUCH_SPREAD_WARN_MM:
            loc = ("touch_flange_pose",) if worst == 0 else ("extra_touch_poses", worst - 1)
            warnings.append(Finding("touch_spread", f"touch {worst + 1} is {residuals[worst]:.2f} "
                                    f"mm from the mean of the touches: re-check the robot tool's "
                                    f"TCP (tool_tcp_mm) or re-teach that touch", loc))
    elevation = flange_elevation_deg(np.concatenate([touches, T2[None]])[:, :3, 3], r, z_axis)
    known = elevation[~np.isnan(elevation)]
    if known.size and known.max() < FLIP_ELEVATION_DEG:
        warnings.append(Finding("alignment_flipped", (
            f"the flange stood {-known.max():.0f} deg or more below the fixed TCP's plane at every "
            f"touch and at the alignment, i.e. behind the fixed tool: the alignment was probably "
            f"done with flange +Z along the fixed tool's +Z, which reverses the axis (180 deg). "
            f"Align again with flange -Z along the fixed tool's +Z (flange +Z pointing into the "
            f"fixed tool)"), ("align_flange_pose",)))
    tilt_deg = float(angle_between_deg(T1[:3, :3], T2[:3, :3]))
    twist_deg = float(angle_between_deg(R, R6))  # rotation about z the 5D convention discards
    extras = {"fixed_tcp_mm": r, "tool_axis": z_axis, "touch_tips_mm": tips,
              "align_distance_mm": float(np.linalg.norm(T2[:3, 3] - r)),
              "touch_to_align_deg": tilt_deg, "flange_elevation_deg": elevation, "mode": mode}
    if mode == "5d":
        extras["twist_discarded_deg"] = twist_deg
    names = ("x_mm", "y_mm", "z_mm") if cov is not None else ()
    guidance = None if n > 1 else ("touch the fixed TCP again from another orientation "
                                   "(extra_touch_poses) to check the robot tool's TCP")
    report = QualityReport(residuals_mm=residuals, parameter_names=names, covariance=cov,
                           sigma_mm=sigma, **bounds, warnings=tuple(warnings),
                           guidance=guidance, extras=extras)
    return CalibrationResult(f"fixed_tool.{mode}", frame, report)


def fixed_tool_5d(touch_flange_pose: object, tool_tcp_mm: object, align_flange_pose: object, *,
                  extra_touch_poses: object = None) -> CalibrationResult:
    """Fixed tool > 5D: position of an external TCP and the direction of its axis.

    ``r = R_F1 t + f_1``; tool axis ``z_E = R_world_F2 Rx(180°) e_z = -z_F2`` [1]_; X and Y by
    :func:`axis_frame_5d` (X = world +X projected across the axis). Use 5D when the rotation about the tool axis does not matter
    (glue nozzle, spindle with a round tool).

    Parameters
    ----------
    touch_flange_pose : ndarray (4, 4) or Pose
        ``T_world_flange`` with the calibrated robot tool's TCP on the fixed TCP.
    tool_tcp_mm : array_like, shape (3,)
        The calibrated robot tool's TCP in the flange frame, mm.
    align_flange_pose : ndarray (4, 4) or Pose
        ``T_world_flange`` with the flange's -Z along the fixed tool's +Z (for 5D only the
        flange's Z axis matters).
    extra_touch_poses : ndarray (M, 4, 4), optional, keyword-only
        More touches of the fixed TCP with the robot tool from other orientations: r is then
        their mean and their scatter is the report's residual.

    Returns
    -------
    CalibrationResult
        ``method="fixed_tool.5d"``, ``frame = T_world_fixedtool``. ``residuals_mm`` are the
        touches' distances from r (one touch: ``[0.0]``); ``extras["tool_axis"]``,
        ``extras["twist_discarded_deg"]`` (the rotation about the axis the 6D reading would
        have had), ``extras["align_distance_mm"]``.

    Raises
    ------
    CalibrationError
        NaN, wrong shapes, or a pose whose rotation is not a proper rotation matrix.

    References
    ----------
    .. [1] A. D. Udai, NPTEL Industrial Robotics, week 7, lecture 31 (external TCP, 5D).

    Examples
    --------
    >>> T1 = np.eye(4); T1[:3, 3] = [600, 0, 300]       # robot tool pointing down, tip 100 mm
    >>> T2 = np.eye(4); T2[:3, :3] = np.diag([1, -1, -1.0]); T2[:3, 3] = [600, 0, 100]
    >>> res = fixed_tool_5d(T1, [0, 0, -100], T2)        # flange turned over: fixed tool points up
    >>> res.frame.round(6).tolist()
    [[1.0, 0.0, 0.0, 600.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 200.0], [0.0, 0.0, 0.0, 1.0]]
    """
    return _fixed_tool("5d", touch_flange_pose, tool_tcp_mm, align_flange_pose, extra_touch_poses)


def fixed_tool_6d(touch_flange_pose: object, tool_tcp_mm: object, align_flange_pose: object, *,
                  extra_touch_poses: object = None) -> CalibrationResult:
    """Fixed tool > 6D: position and full orientation of an external TCP.

    ``r = R_F1 t + f_1``; ``R_world_E = R_world_F2 @ Rx(180°)`` [1]_: at alignment the flange
    frame F has ``+Z_F`` along ``-Z_E``, ``X_F`` along ``X_E`` and ``Y_F`` along ``-Y_E``.

    Parameters
    ----------
    touch_flange_pose, tool_tcp_mm, align_flange_pose, extra_touch_poses
        As :func:`fixed_tool_5d`; here all three flange axes are aligned.

    Returns
    -------
    CalibrationResult
        ``method="fixed_tool.6d"``, ``frame = T_world_fixedtool``.

    Raises
    ------
    CalibrationError
        NaN, wrong shapes, or a pose whose rotation is not a proper rotation matrix.

    References
    ----------
    .. [1] A. D. Udai, NPTEL Industrial Robotics, week 7, lecture 31 (external TCP, 6D):
       ``B_Q_E = B_Q_F F_Q_E`` with ``F_Q_E = Rx(180°)``.

    Examples
    --------
    >>> T1 = np.eye(4); T1[:3, 3] = [600, 0, 300]
    >>> T2 = np.eye(4); T2[:3, 3] = [600, 0, 400]       # flange untouched: fixed tool points down
    >>> res = fixed_tool_6d(T1, [0, 0, -100], T2)
    >>> res.frame[:3, :3].round(6).tolist(), res.frame[:3, 3].tolist()
    ([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]], [600.0, 0.0, 200.0])
    """
    return _fixed_tool("6d", touch_flange_pose, tool_tcp_mm, align_flange_pose, extra_touch_poses)


__all__ = ["fixed_tool_5d", "fixed_tool_6d", "axis_frame_5d", "R_FLANGE_FIXEDTOOL"]
