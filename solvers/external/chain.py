"""The kinematic chain of a touch-up: world -> rail -> robot base -> flange -> tool.

A robot on a rail (KUKA ``$ERSYSROOT`` with a linear unit's ``EX_KIN``, ABB a track unit)
records its flange in its own base, which rides on the carriage. World is the robot base at
rail position 0; at rail value e the base has moved ``k e d`` (d the travel direction in the
base at 0, k the encoder scale), so

    ``T_world_flange = Trans(k e d) @ T_base_flange``.

With ``b = -k d`` (the slope ``ext.linear_unit`` fits, :mod:`solvers.external.linear_unit`)
the shift is ``-b e``. Every menu solves from ``T_world_flange`` and so gives the same frame
whatever rail position it was taught at.

:func:`propagate` carries the uncertainty of an input (the touching tool's TCP, the rail's
slope) into the result by central differences of the menu's own solve: ``C = J Σ Jᵀ`` with J
the derivative of the result's position (mm) and rotation vector (deg) by the input.
:func:`combined_bounds` adds the terms to the solve's own 95 % bounds.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.report import bound95
from solvers.validate import FloatArray


def rail_shift(values_mm: object, direction: object, scale: float = 1.0) -> FloatArray:
    """``T_world_base`` (N, 4, 4) at the rail values: a translation by ``scale e d``.

    Parameters
    ----------
    values_mm : array_like, shape (N,)
        The rail encoder values, mm.
    direction : array_like, shape (3,)
        The travel direction in the robot base at rail 0 (normalised here).
    scale : float
        Travel per mm counted.

    Examples
    --------
    >>> rail_shift([100.0], [1.0, 0.0, 0.0], 1.002)[0, :3, 3].round(6).tolist()
    [100.2, 0.0, 0.0]
    """
    e = np.atleast_1d(np.asarray(values_mm, dtype=float))
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    T = np.tile(np.eye(4), (len(e), 1, 1))
    T[:, :3, 3] = (scale * e)[:, None] * d
    return T


def to_world(flange_poses: object, values_mm: object, direction: object,
             scale: float = 1.0) -> FloatArray:
    """``T_world_flange = rail_shift(e) @ T_base_flange`` of N recorded flange poses (N, 4, 4).

    Examples
    --------
    >>> F = np.tile(np.eye(4), (2, 1, 1))
    >>> to_world(F, [0.0, 250.0], [1.0, 0.0, 0.0])[:, 0, 3].tolist()
    [0.0, 250.0]
    """
    F = np.asarray(flange_poses, dtype=float)
    return rail_shift(values_mm, direction, scale) @ F


def frame_vector(T: FloatArray, T_ref: FloatArray) -> FloatArray:
    """(6,) position of ``T`` (mm) and the rotation vector of ``R_ref^T R`` (deg)."""
    rv = Rotation.from_matrix(T_ref[:3, :3].T @ T[:3, :3]).as_rotvec(degrees=True)
    return np.concatenate([T[:3, 3], rv])


def propagate(solve: Callable[[FloatArray], FloatArray], x0: object, covariance: object,
              step: float = 1e-3) -> FloatArray:
    """Covariance (6, 6) of the result's position (mm) and rotation (deg) from an input ``x``
    with ``covariance``: ``J Σ Jᵀ``, J by central differences of ``solve(x) -> T`` (4, 4)
    scaled to the input's own standard deviations (``step`` of one sigma each way).

    Examples
    --------
    >>> shift = lambda x: np.block([[np.eye(3), np.c_[x]], [np.zeros((1, 3)), np.ones((1, 1))]])
    >>> np.diag(propagate(shift, np.zeros(3), np.eye(3) * 0.04))[:3].round(6).tolist()
    [0.04, 0.04, 0.04]
    """
    x0 = np.asarray(x0, dtype=float)
    S = np.asarray(covariance, dtype=float)
    lam, V = np.linalg.eigh(S)
    T0 = solve(x0)
    cols = []
    for k in range(len(lam)):
        s = float(np.sqrt(max(lam[k], 0.0)))
        if s == 0.0:
            continue
        h = V[:, k] * s * step
        d = (frame_vector(solve(x0 + h), T0) - frame_vector(solve(x0 - h), T0)) / (2 * step)
        cols.append(d)  # the result's change per one sigma along eigenvector k
    if not cols:
        return np.zeros((6, 6))
    J = np.array(cols).T
    return J @ J.T


def combined_bounds(position_bound95_mm: float | None, angle_bound95_deg: float | None,
                    terms: dict[str, FloatArray]) -> dict[str, object]:
    """The result's 95 % bounds with every term: the solve's own (touch scatter) and each
    propagated covariance (6, 6) of ``terms`` (:func:`propagate`).

    A term's bound is :func:`solvers.report.bound95` of its position (angle) block; the total
    is the root sum of squares of the terms' bounds. It is exact when the terms have one shape
    (isotropic, or one dominant axis) and errs wide otherwise (two equal perpendicular 1-D
    terms: 98.5 % instead of 95 %).

    Returns
    -------
    dict
        ``position_bound95_mm``, ``angle_bound95_deg`` (totals) and ``terms``: per term name
        ``{"position_bound95_mm", "angle_bound95_deg"}``, the touch term first.

    Examples
    --------
    >>> C = np.diag([0.01, 0.01, 0.01, 0.0, 0.0, 0.0])
    >>> round(combined_bounds(0.2795, None, {"tool 1": C})["position_bound95_mm"], 4)
    0.3953
    """
    out_terms: dict[str, dict[str, float | None]] = {
        "touch": {"position_bound95_mm": position_bound95_mm,
                  "angle_bound95_deg": angle_bound95_deg}}
    pos2 = (position_bound95_mm or 0.0) ** 2
    ang2 = (angle_bound95_deg or 0.0) ** 2
    for name, C in terms.items():
        C = np.asarray(C, dtype=float)
        bp, ba = bound95(C[:3, :3]), bound95(C[3:, 3:])
        out_terms[name] = {"position_bound95_mm": bp, "angle_bound95_deg": ba}
        pos2 += bp**2
        ang2 += ba**2
    return {"position_bound95_mm": None if position_bound95_mm is None else float(np.sqrt(pos2)),
            "angle_bound95_deg": None if angle_bound95_deg is None else float(np.sqrt(ang2)),
            "terms": out_terms}


__all__ = ["rail_shift", "to_world", "frame_vector", "propagate", "combined_bounds"]
