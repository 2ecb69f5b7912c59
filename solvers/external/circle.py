"""A circle in space from points on it: plane by SVD, circle in that plane, then the 3-D fit.

The geometry behind every rotary external axis (``ext.root_point``, the two-axis positioner):
a mark on the turning flange, touched at several axis positions, lies on a circle whose
normal is the axis and whose centre is on it.

Model: ``p_k = c + r (cos φ_k u + sin φ_k v) + e_k``, ``(u, v, n)`` right-handed, the φ_k
unknown (nuisance). The orthogonal-distance (maximum-likelihood for isotropic Gaussian e_k)
fit minimises ``Σ_k h_k² + (ρ_k - r)²`` with ``h_k = (p_k - c)·n`` (height over the plane)
and ``ρ_k = |(p_k - c) - h_k n|`` (distance from the axis): the tangential part of e_k is
absorbed by φ_k. Start: plane through the centroid with the normal of the smallest singular
value [1]_, circle in the plane by the algebraic fit of Kåsa [2]_; refined by
``scipy.optimize.least_squares`` with the analytic Jacobian [3]_.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from solvers.external.common import cross
from solvers.validate import FloatArray

#: the six fitted parameters: centre, tilts of the normal about u and v (rad), radius
CIRCLE_PARAMETERS = ("cx_mm", "cy_mm", "cz_mm", "tilt_u_rad", "tilt_v_rad", "radius_mm")


@dataclass(frozen=True)
class CircleFit:
    """A circle in space: centre, unit normal ``n`` with in-plane basis (u, v, n) right-handed.

    ``residual_vectors_mm`` (N, 2) holds ``[h_k, ρ_k - r]`` per point, ``jacobian`` (2N, 6) the
    derivative of that stacked residual by :data:`CIRCLE_PARAMETERS` at the solution.
    """

    centre_mm: FloatArray
    normal: FloatArray
    u: FloatArray
    v: FloatArray
    radius_mm: float
    residual_vectors_mm: FloatArray
    jacobian: FloatArray

    @property
    def distances_mm(self) -> FloatArray:
        """Each point's orthogonal distance from the circle (mm)."""
        return np.linalg.norm(self.residual_vectors_mm, axis=1)

    def angles_rad(self, points_mm: FloatArray) -> FloatArray:
        """φ_k = atan2((p_k - c)·v, (p_k - c)·u): where each point sits on the circle (rad)."""
        d = np.asarray(points_mm, dtype=float) - self.centre_mm
        return np.arctan2(d @ self.v, d @ self.u)


def fit_plane(points_mm: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Least-squares plane: (centroid, unit normal, singular values of the centred points).

    The normal is the right singular vector of the smallest singular value of ``P - p̄`` [1]_.

    Examples
    --------
    >>> c, n, s = fit_plane([[0, 0, 5], [10, 0, 5], [0, 10, 5], [10, 10, 5]])
    >>> c.tolist(), np.abs(n).round(6).tolist()
    ([5.0, 5.0, 5.0], [0.0, 0.0, 1.0])
    """
    P = np.asarray(points_mm, dtype=float)
    c = P.mean(axis=0)
    _, s, Vt = np.linalg.svd(P - c, full_matrices=False)
    return c, Vt[-1], s


def fit_circle_2d_algebraic(xy: FloatArray) -> tuple[FloatArray, float]:
    """Kåsa's algebraic circle [2]_: ``x² + y² + D x + E y + F = 0`` by linear least squares.

    Centre ``(-D/2, -E/2)``, radius ``sqrt(D²/4 + E²/4 - F)``. Exact for exact points; a good
    start for the geometric fit otherwise.

    Examples
    --------
    >>> a = np.radians([0, 90, 180])
    >>> c, r = fit_circle_2d_algebraic(np.c_[3 + 2 * np.cos(a), -1 + 2 * np.sin(a)])
    >>> c.round(9).tolist(), round(r, 9)
    ([3.0, -1.0], 2.0)
    """
    xy = np.asarray(xy, dtype=float)
    A = np.c_[xy, np.ones(len(xy))]
    b = -(xy**2).sum(axis=1)
    (D, E, F), *_ = np.linalg.lstsq(A, b, rcond=None)
    centre = np.array([-D / 2.0, -E / 2.0])
    return centre, float(np.sqrt(max(centre @ centre - F, 0.0)))


def _basis(n: FloatArray) -> tuple[FloatArray, FloatArray]:
    """An in-plane basis (u, v) with (u, v, n) right-handed."""
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = cross(a, n)
    u /= np.linalg.norm(u)
    return u, cross(n, u)


def _residuals(P: FloatArray, c: FloatArray, n: FloatArray,
               r: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(h, ρ, w): heights over the plane, distances from the axis, in-plane vectors (N, 3)."""
    d = P - c
    h = d @ n
    w = d - h[:, None] * n
    return h, np.linalg.norm(w, axis=1), w


def circle_jacobian(points_mm: FloatArray, centre_mm: FloatArray, n: FloatArray, u: FloatArray,
                    v: FloatArray) -> FloatArray:
    """d[h_k, ρ_k - r]/d(c, a, b, r), shape (2N, 6), with ``n(a, b) = Exp(a u + b v) n``.

    ``dn/da = u × n = -v``, ``dn/db = v × n = u``; with d = p - c and ŵ the unit in-plane
    direction: ``dh = -n·dc + d·dn``, ``dρ = -ŵ·dc - h ŵ·dn``, ``d(ρ - r)/dr = -1``.
    """
    P = np.atleast_2d(np.asarray(points_mm, dtype=float))
    h, rho, w = _residuals(P, centre_mm, n, 0.0)
    wh = w / np.maximum(rho, 1e-300)[:, None]
    d = P - centre_mm
    J = np.zeros((len(P), 2, 6))
    J[:, 0, :3] = -n
    J[:, 0, 3] = -(d @ v)
    J[:, 0, 4] = d @ u
    J[:, 1, :3] = -wh
    J[:, 1, 3] = h * (wh @ v)
    J[:, 1, 4] = -h * (wh @ u)
    J[:, 1, 5] = -1.0
    return J.reshape(-1, 6)


def fit_circle_algebraic(points_mm: FloatArray) -> tuple[FloatArray, FloatArray, float]:
    """(centre, unit normal, radius) from the SVD plane and Kåsa's circle in it: no iteration."""
    P = np.asarray(points_mm, dtype=float)
    m, n, _ = fit_plane(P)
    u, v = _basis(n)
    c2, r = fit_circle_2d_algebraic(np.c_[(P - m) @ u, (P - m) @ v])
    return m + c2[0] * u + c2[1] * v, n, r


def fit_circle_3d(points_mm: FloatArray, towards: FloatArray | None = None) -> CircleFit:
    """Orthogonal-distance circle in space through N >= 3 points (no angles needed).

    Minimises ``Σ_k h_k² + (ρ_k - r)²`` over the centre c, the normal n (two tilts about the
    current in-plane axes, re-based at every evaluation) and the radius r, started from
    :func:`fit_circle_algebraic`, solved by ``scipy.optimize.least_squares`` [3]_. For N = 3
    the circle passes through the points exactly.

    Parameters
    ----------
    points_mm : ndarray, shape (N, 3)
        Points near one circle; the caller has refused coincident and collinear sets.
    towards : ndarray, shape (3,), optional
        The returned normal points to this side (``n·towards >= 0``).

    Returns
    -------
    CircleFit

    References
    ----------
    .. [1] C. M. Shakarji, "Least-squares fitting algorithms of the NIST algorithm testing
       system", J. Res. NIST 103(6):633-641, 1998 (planes by SVD, circles in space).
    .. [2] I. Kåsa, "A circle fitting procedure and its error analysis", IEEE Trans. Instrum.
       Meas. IM-25(1):8-14, 1976.
    .. [3] scipy.optimize.least_squares (trust-region reflective), SciPy 1.11+.

    Examples
    --------
    >>> a = np.radians([0, 70, 160, 250])
    >>> P = np.c_[100 * np.cos(a), 100 * np.sin(a), np.full(4, 30.0)] + [500, 0, 0]
    >>> fit = fit_circle_3d(P, towards=[0, 0, 1])
    >>> fit.centre_mm.round(6).tolist(), fit.normal.round(6).tolist(), round(fit.radius_mm, 6)
    ([500.0, 0.0, 30.0], [0.0, 0.0, 1.0], 100.0)
    """
    P = np.asarray(points_mm, dtype=float)
    c0, n0, r0 = fit_circle_algebraic(P)
    u0, v0 = _basis(n0)

    def frame(x: FloatArray) -> FloatArray:
        return Rotation.from_rotvec(x[3] * u0 + x[4] * v0).as_matrix()

    def fun(x: FloatArray) -> FloatArray:
        h, rho, _ = _residuals(P, x[:3], frame(x) @ n0, x[5])
        return np.c_[h, rho - x[5]].ravel()

    def jac(x: FloatArray) -> FloatArray:
        R = frame(x)
        # tilts about the rotated axes; at x[3:5] = 0 (where the covariance is taken) exact
        return circle_jacobian(P, x[:3], R @ n0, R @ u0, R @ v0)

    x0 = np.r_[c0, 0.0, 0.0, r0]
    scale = max(r0, 1.0)
    sol = least_squares(fun, x0, jac=jac, method="lm",
                        x_scale=np.r_[scale, scale, scale, 1.0, 1.0, scale], xtol=1e-12,
                        ftol=1e-12, gtol=1e-12)
    R = frame(sol.x)
    n, u, v = R @ n0, R @ u0, R @ v0
    c, r = sol.x[:3], float(sol.x[5])
    if towards is not None and n @ np.asarray(towards, dtype=float) < 0:
        n, v = -n, -v  # (u, -v, -n) is right-handed again
    h, rho, _ = _residuals(P, c, n, r)
    return CircleFit(centre_mm=c, normal=n, u=u, v=v, radius_mm=r,
                     residual_vectors_mm=np.c_[h, rho - r],
                     jacobian=circle_jacobian(P, c, n, u, v))


__all__ = ["CircleFit", "CIRCLE_PARAMETERS", "fit_plane", "fit_circle_2d_algebraic",
           "fit_circle_algebraic", "fit_circle_3d", "circle_jacobian"]
