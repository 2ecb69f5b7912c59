"""Checks and statistics shared by the external-kinematics methods (turntable, positioner, rail)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import lru_cache

import numpy as np
from scipy import stats
from scipy.spatial.transform import Rotation

from solvers.errors import CalibrationError
from solvers.report import welch_dof
from solvers.validate import FloatArray, as_array

#: Default touch-up noise (1 sigma per coordinate, mm) when the residual has no redundancy.
TOUCH_SIGMA_MM = 0.05
#: The scatter never drops below this (robot repeatability), mm.
SIGMA_FLOOR_MM = 0.01
#: Two rotary axis positions closer than this (deg) are refused.
MIN_AXIS_STEP_DEG = 10.0
#: Two rail positions closer than this (mm) are refused.
MIN_RAIL_STEP_MM = 10.0
#: A mark closer than this to the axis (mm) is refused: its circle is too small to fit.
MIN_RADIUS_MM = 20.0
#: Touch-ups whose RMS distance from their best line is below this (mm) are "collinear".
MIN_OFF_LINE_MM = 0.5


def cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a × b`` of 3-vectors (..., 3): the formula, without ``np.cross``'s per-call overhead.

    Examples
    --------
    >>> cross(np.array([1.0, 0, 0]), np.array([0, 1.0, 0])).tolist()
    [0.0, 0.0, 1.0]
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def rz(angles_deg: FloatArray) -> FloatArray:
    """(N, 4, 4) rotations about z by N angles (deg), through SciPy's ``Rotation``: the flange
    of a rotary axis relative to its root, ``T_root_flange(θ) = Rz(θ)``.

    Examples
    --------
    >>> rz([90.0])[0, :3, 0].round(6).tolist()
    [0.0, 1.0, 0.0]
    """
    a = np.atleast_1d(np.asarray(angles_deg, dtype=float))
    T = np.tile(np.eye(4), (len(a), 1, 1))
    T[:, :3, :3] = Rotation.from_euler("z", a[:, None], degrees=True).as_matrix()
    return T


def wrap_rad(a: FloatArray) -> FloatArray:
    """Angles wrapped into (-π, π]."""
    return -((-np.asarray(a, dtype=float) + np.pi) % (2 * np.pi) - np.pi)


def unit(v: object, loc: str) -> FloatArray:
    """A finite non-zero 3-vector, normalised (a nominal direction typed by the user)."""
    a = as_array(v, loc, (3,))
    n = float(np.linalg.norm(a))
    if n < 1e-9:
        raise CalibrationError((loc,), "is the zero vector: give a direction")
    return a / n


def axis_values(value: object, loc: str, count: int, points_loc: str) -> FloatArray:
    """The recorded axis values, one per touch-up (finite, same count as the points)."""
    v = as_array(value, loc, (None,))
    if len(v) != count:
        raise CalibrationError((loc,), f"has {len(v)} values but {points_loc} has {count} points: "
                               "record the axis value with every touch-up")
    return v


def check_rotary_steps(values_deg: FloatArray, loc: str,
                       min_step_deg: float = MIN_AXIS_STEP_DEG) -> None:
    """Refuse two rotary axis positions less than ``min_step_deg`` apart (modulo 360 deg).

    Examples
    --------
    >>> check_rotary_steps(np.array([0.0, 90.0, 355.0]), "axis_values_deg")
    Traceback (most recent call last):
    ...
    solvers.errors.CalibrationError: axis_values_deg.2: axis value 355.00 deg is 5.00 deg from \
point 1 (0.00 deg): teach the axis positions at least 10 deg apart
    """
    v = np.asarray(values_deg, dtype=float)
    for j in range(1, len(v)):
        d = np.abs(v[:j] - v[j]) % 360.0
        d = np.minimum(d, 360.0 - d)
        i = int(np.argmin(d))
        if d[i] < min_step_deg:
            raise CalibrationError((loc, j), f"axis value {v[j]:.2f} deg is {d[i]:.2f} deg from "
                                   f"point {i + 1} ({v[i]:.2f} deg): teach the axis positions at "
                                   f"least {min_step_deg:g} deg apart")


def check_linear_steps(values_mm: FloatArray, loc: str,
                       min_step_mm: float = MIN_RAIL_STEP_MM) -> None:
    """Refuse two rail positions less than ``min_step_mm`` apart."""
    v = np.asarray(values_mm, dtype=float)
    for j in range(1, len(v)):
        d = np.abs(v[:j] - v[j])
        i = int(np.argmin(d))
        if d[i] < min_step_mm:
            raise CalibrationError((loc, j), f"rail position {v[j]:.2f} mm is {d[i]:.2f} mm from "
                                   f"point {i + 1} ({v[i]:.2f} mm): teach the rail positions at "
                                   f"least {min_step_mm:g} mm apart")


def off_line_rms_mm(points_mm: FloatArray) -> float:
    """RMS distance of points from their best-fit line, ``sqrt((s2² + s3²) / N)`` (SVD)."""
    P = np.asarray(points_mm, dtype=float)
    s = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)
    return float(np.sqrt((s[1:] ** 2).sum() / len(P)))


@lru_cache(maxsize=512)
def scale95(k: int, dof: int, estimated: bool) -> float:
    """Squared 95 % radius factor of k parameters: ``k F(k, dof)`` when sigma was estimated
    from dof residual degrees of freedom, else ``chi2(k)`` (sigma taken as known).

    Examples
    --------
    >>> round(scale95(1, 10, True), 3), round(scale95(1, 0, False), 3)
    (4.965, 3.841)
    """
    if estimated and dof > 0:
        return float(k * stats.f.ppf(0.95, k, dof))
    return float(stats.chi2.ppf(0.95, k))


@lru_cache(maxsize=512)
def outlier_critical(k: int, dof: int, q: float) -> float:
    """The q quantile of ``k F(k, dof)`` (``chi2(k)`` when dof = 0: sigma known)."""
    if dof > 0:
        return float(k * stats.f.ppf(q, k, dof))
    return float(stats.chi2.ppf(q, k))


def block_dof(parts: Sequence[tuple[FloatArray, float | None]], block: slice) -> float | None:
    """Welch-Satterthwaite degrees of freedom (:func:`solvers.report.welch_dof`) of one block
    of a covariance summed from independent shares ``C = Σ_i C_i``, share i scaled by a sigma
    estimated with ``ν_i`` residual degrees of freedom (None or 0: sigma known), the terms
    ``v_i = tr C_i[block, block]`` (mm² for a position block, deg² for an angle block; a share
    with sigma known adds to the numerator only). The estimated total ``tr Ĉ = Σ v_i w_i``,
    ``w_i ~ χ²(ν_i)/ν_i``, has mean ``tr C`` and variance ``2 Σ v_i²/ν_i``, those of
    ``tr C · χ²(ν_eff)/ν_eff``: the block's bound is :func:`solvers.report.bound95` of the
    summed (unwidened) block with ``F(f, ν_eff)`` quantiles, the rule
    :func:`solvers.external.chain.combined_bounds` applies to a chain's terms. None when every
    share's sigma is known (chi-square). A single share gives its own ν; ν_eff is at least the
    smallest ν_i of the shares that count.

    Examples
    --------
    >>> touch, root = np.eye(3) * 0.01, np.eye(3) * 0.01  # equal shares, the root's from ν = 2
    >>> block_dof([(touch, None), (root, 2)], slice(0, 3))
    8.0
    >>> block_dof([(touch, None)], slice(0, 3)) is None
    True
    """
    traces = [float(np.trace(np.asarray(C, dtype=float)[block, block])) for C, _ in parts]
    return welch_dof(traces, [nu for _, nu in parts])


def sigma_from_residuals(residuals: FloatArray, n_parameters: int,
                         nominal_mm: float) -> tuple[float, int, bool]:
    """(sigma, dof, estimated): ``sqrt(SSR / dof)`` (at least the floor) when dof > 0, else the
    nominal touch sigma."""
    r = np.ravel(residuals)
    dof = r.size - n_parameters
    if dof <= 0:
        return float(nominal_mm), 0, False
    s = float(np.sqrt(r @ r / dof))
    return max(s, SIGMA_FLOOR_MM), dof, s >= SIGMA_FLOOR_MM


def propagate(f: Callable[[FloatArray], FloatArray], x0: FloatArray, cov: FloatArray,
              steps: FloatArray) -> tuple[FloatArray, FloatArray]:
    """First-order covariance of ``f(x)`` at x0: ``J C Jᵀ`` with J by central differences.

    Returns (J, J C Jᵀ). ``steps`` are the difference steps per parameter.
    """
    x0 = np.asarray(x0, dtype=float)
    cols = []
    for i, h in enumerate(steps):
        dx = np.zeros_like(x0)
        dx[i] = h
        cols.append((np.asarray(f(x0 + dx)) - np.asarray(f(x0 - dx))) / (2 * h))
    J = np.atleast_2d(np.array(cols).T)
    return J, J @ cov @ J.T


def line_distance(p1: FloatArray, d1: FloatArray, p2: FloatArray, d2: FloatArray) -> tuple[
        float, FloatArray, FloatArray]:
    """Common normal of two lines ``p_i + t d_i`` (unit d_i): (length, foot on 1, foot on 2).

    Parallel lines: the feet are p1 and its projection onto line 2.

    Examples
    --------
    >>> L, f1, f2 = line_distance(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 5.0, 3.0]),
    ...                           np.array([0, 0, 1.0]))
    >>> round(L, 9), f1.tolist(), f2.tolist()
    (5.0, [0.0, 0.0, 0.0], [0.0, 5.0, 0.0])
    """
    w = p1 - p2
    b = float(d1 @ d2)
    den = 1.0 - b * b
    if den < 1e-12:
        f1 = p1
        f2 = p2 + ((p1 - p2) @ d2) * d2
    else:
        d, e = float(d1 @ w), float(d2 @ w)
        t1 = (b * e - d) / den
        t2 = (e - b * d) / den
        f1, f2 = p1 + t1 * d1, p2 + t2 * d2
    return float(np.linalg.norm(f2 - f1)), f1, f2
