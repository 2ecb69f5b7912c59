"""Workpiece > Direct / Indirect: a robot-held workpiece measured on a calibrated fixed TCP.

The controller treats the workpiece like a tool: the result is ``T_flange_workpiece``.
Every method first turns each touch into the contact point in flange coordinates: the fixed
TCP r (world) touches the workpiece at flange pose ``(R_k, f_k)``, so the touched workpiece
point in the flange frame is

    ``c_k = R_k^T (r - f_k)``

which is the lecture's ``F_t_W = [R_Q_F]^-1 (r - f_1)`` and ``F_p_i = [R_Q_F]^-1 (t - f_i)``
for every step, also when the orientation changes between steps [1]_. With a constant
orientation ``R``, ``c_2 - c_1 = R^T (f_1 - f_2)`` is the lecture's
``u = r - f_2 - R_Q_F F_t_W`` expressed in the flange frame.

References
----------
.. [1] A. D. Udai, "Fixed tool calibration: external TCP and workpiece calibration", NPTEL
   Industrial Robotics, week 7, lecture 31 (workpiece direct and indirect methods).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solvers.base import MIN_DISTANCE_MM, SIGMA_FLOOR_MM, TOUCH_SIGMA_MM, frame_from_three_points
from solvers.base import register_points, three_point_report
from solvers.errors import CalibrationError
from solvers.report import CalibrationResult
from solvers.validate import FloatArray, as_array, as_transforms


def contact_points_flange(fixed_tcp_mm: FloatArray, flange_poses: FloatArray) -> FloatArray:
    """Touched workpiece points in the flange frame, ``c_k = R_k^T (r - f_k)`` (N, 3), mm.

    Examples
    --------
    >>> T = np.eye(4); T[:3, 3] = [500, 0, 400]
    >>> contact_points_flange([500, 0, 300], T[None]).tolist()
    [[0.0, 0.0, -100.0]]
    """
    r = np.asarray(fixed_tcp_mm, dtype=float)
    T = np.asarray(flange_poses, dtype=float)
    return np.einsum("nji,nj->ni", T[:, :3, :3], r - T[:, :3, 3])


def workpiece_direct(fixed_tcp_mm: object, flange_poses: object, *,
                     touch_sigma_mm: float = TOUCH_SIGMA_MM,
                     min_distance_mm: float = MIN_DISTANCE_MM) -> CalibrationResult:
    """Workpiece > Direct: origin, a +X point and an XY-plane point brushed on the fixed TCP.

    ``c_k = R_k^T (r - f_k)`` for k = origin, +X point, XY point; then the frame from three
    points in flange coordinates: ``x = unit(c_2 - c_1)``, ``z = unit(x × (c_3 - c_1))``,
    ``y = z × x``, origin ``c_1`` (the lecture's ``t``, ``u``, ``v``, ``w = u × v`` [1]_,
    generalised to orientations that change between steps).

    Parameters
    ----------
    fixed_tcp_mm : array_like, shape (3,)
        The calibrated fixed TCP r in world, mm (from ``fixed_tool.5d``/``6d``).
    flange_poses : ndarray, shape (3, 4, 4)
        ``T_world_flange`` with the workpiece's origin, a point on its +X axis and a point on
        the +Y side of its XY plane on the fixed TCP, in that order.
    touch_sigma_mm : float, keyword-only
        Touch noise (1 sigma per coordinate, mm) for the sensitivity in the report.
    min_distance_mm : float, keyword-only
        Smallest distance between the touched points and of the XY point from the X line.

    Returns
    -------
    CalibrationResult
        ``method="workpiece.direct"``, ``frame = T_flange_workpiece``. Residuals are zero by
        construction; the covariance is ``touch_sigma_mm`` propagated through the lever arms;
        ``extras["contact_points_mm"]`` holds c_k.

    Raises
    ------
    CalibrationError
        NaN or wrong shapes; not exactly 3 poses; a rotation that is not proper; two touched
        points closer than ``min_distance_mm`` (names which, and the distance); the three
        points collinear (gives the XY point's distance and angle from the X line).

    References
    ----------
    .. [1] A. D. Udai, NPTEL Industrial Robotics, week 7, lecture 31 (workpiece direct).

    Examples
    --------
    >>> poses = np.stack([np.eye(4)] * 3)
    >>> poses[:, :3, 3] = [[500, 0, 400], [300, 0, 400], [500, -150, 400]]
    >>> res = workpiece_direct([500, 0, 300], poses)   # flange moved -X, then -Y
    >>> res.frame.round(6).tolist()
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, -100.0], [0.0, 0.0, 0.0, 1.0]]
    """
    r = as_array(fixed_tcp_mm, "fixed_tcp_mm", (3,))
    T = as_transforms(flange_poses, "flange_poses", min_count=3)
    if len(T) != 3:
        raise CalibrationError(("flange_poses",), f"needs exactly 3 poses (origin, +X point, "
                               f"XY-plane point), got {len(T)}")
    c = contact_points_flange(r, T)
    locs = [("flange_poses", k) for k in range(3)]
    frame = frame_from_three_points(*c, locs=locs, min_distance_mm=min_distance_mm)
    report = three_point_report(c, locs, touch_sigma_mm, frame=frame)
    report = replace(report, extras={**report.extras, "contact_points_mm": c})
    return CalibrationResult("workpiece.direct", frame, report)


def workpiece_indirect(fixed_tcp_mm: object, flange_poses: object, known_mm: object, *,
                       target_mm: object = None,
                       sigma_floor_mm: float = SIGMA_FLOOR_MM) -> CalibrationResult:
    """Workpiece > Indirect: N >= 4 points known on the workpiece, each brought to the fixed TCP.

    ``c_k = R_k^T (r - f_k)``, then the best-fit rigid ``T_flange_workpiece`` with
    ``c_k ≈ T known_k`` (least squares; see :func:`solvers.base.register_points`). The
    lecture's ``F_T_W = F_P [W_P]^-1`` [1]_ with four homogeneous points is the exact N = 4
    case of this fit; the least squares also takes more points, coplanar points (where
    ``W_P`` is singular) and noisy ones, and reports residuals, TRE and the bad point.

    Parameters
    ----------
    fixed_tcp_mm : array_like, shape (3,)
        The calibrated fixed TCP in world, mm.
    flange_poses : ndarray, shape (N, 4, 4)
        ``T_world_flange`` with known point k on the fixed TCP.
    known_mm : array_like, shape (N, 3)
        The points in workpiece coordinates (drawing / CAD), mm.
    target_mm : array_like, shape (3,), optional, keyword-only
        A workpiece point where the expected error matters (``report.tre_mm``); default the
        known point farthest from the centroid.
    sigma_floor_mm : float, keyword-only
        The scatter never drops below this in the covariance and TRE.

    Returns
    -------
    CalibrationResult
        ``method="workpiece.indirect"``, ``frame = T_flange_workpiece``; residual per touch,
        covariance, ``tre_mm``, ``bad_point`` (N >= 5), ``extras["contact_points_mm"]``.

    Raises
    ------
    CalibrationError
        NaN or wrong shapes, N < 4, counts that differ, an improper rotation, coincident or
        collinear known points or contact points.

    References
    ----------
    .. [1] A. D. Udai, NPTEL Industrial Robotics, week 7, lecture 31 (workpiece indirect).
    .. [2] K. S. Arun, T. S. Huang, S. D. Blostein, IEEE Trans. PAMI 9(5), 1987.
    .. [3] J. M. Fitzpatrick, J. B. West, C. R. Maurer, IEEE Trans. Med. Imaging 17(5), 1998.

    Examples
    --------
    >>> known = np.array([[0, 0, 0], [200, 0, 0], [200, 100, 0], [0, 100, 0.0]])
    >>> poses = np.stack([np.eye(4)] * 4)
    >>> poses[:, :3, 3] = [500, 0, 400] - known             # workpiece 100 mm below the flange
    >>> res = workpiece_indirect([500, 0, 300], poses, known)
    >>> res.frame[:3, 3].round(6).tolist(), round(res.report.max_error_mm, 6)
    ([0.0, 0.0, -100.0], 0.0)
    """
    r = as_array(fixed_tcp_mm, "fixed_tcp_mm", (3,))
    T = as_transforms(flange_poses, "flange_poses", min_count=4)
    c = contact_points_flange(r, T)
    frame, report = register_points(c, known_mm, measured_loc="flange_poses", known_loc="known_mm",
                                    target_mm=target_mm, sigma_floor_mm=sigma_floor_mm)
    report = replace(report, extras={**report.extras, "contact_points_mm": c})
    return CalibrationResult("workpiece.indirect", frame, report)


__all__ = ["workpiece_direct", "workpiece_indirect", "contact_points_flange"]
