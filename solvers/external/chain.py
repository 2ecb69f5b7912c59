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
from scipy import special
from scipy.spatial.transform import Rotation

from solvers.report import bound95, welch_dof
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


def _f_over_chi(dof: float | None, f: int = 3) -> float:
    """``sqrt(f F(f, dof; 0.95) / χ²(f; 0.95))``: how much wider an F bound is than the
    chi-square bound of the same covariance (1 for dof None or infinite)."""
    if dof is None or not np.isfinite(dof) or dof > 1e6:
        return 1.0  # F(f, dof) -> chi2(f)/f; scipy 1.14's fdtri gives nan for dof near 1e41
    dof = max(float(dof), 1.0)
    return float(np.sqrt(f * special.fdtri(f, dof, 0.95) / special.chdtri(f, 0.05)))


POSE_NAMES = ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")


def own_covariance(report: object) -> FloatArray | None:
    """The report's covariance of its frame (6, 6) when its parameters are the pose's
    (``solvers.base.POSE_PARAMETERS``), else None."""
    names = tuple(getattr(report, "parameter_names", ()) or ())
    C = getattr(report, "covariance", None)
    if C is None or names[:6] != POSE_NAMES:
        return None
    return np.asarray(C, dtype=float)[:6, :6]


def report_dof(report: object) -> int | None:
    """The degrees of freedom behind a report's sigma: ``report.dof``, else (the external
    kinematics' reports) ``extras["dof"]`` when sigma was estimated; None when assumed."""
    dof = getattr(report, "dof", None)
    if dof is not None:
        return int(dof) or None
    if getattr(report, "sigma_source", None) == "assumed":
        return None
    extra = (getattr(report, "extras", None) or {}).get("dof")
    return int(extra) if extra else None


def report_dofs(report: object) -> tuple[float | None, float | None]:
    """The degrees of freedom of a report's position and angle blocks: ``extras["position_dof"]``
    and ``extras["angle_dof"]`` where the report gives them (``ext.offset``,
    ``ext.positioner_2axis``: a covariance summed from shares of different dof, each block
    with its Welch-Satterthwaite dof, :func:`solvers.external.common.block_dof`), else
    :func:`report_dof` for both. The covariance they go with is the report's own, unwidened.

    Examples
    --------
    >>> from types import SimpleNamespace as R
    >>> report_dofs(R(dof=None, extras={"position_dof": 3.5, "angle_dof": None}))
    (3.5, None)
    >>> report_dofs(R(dof=6, extras={}))
    (6, 6)
    """
    extras = getattr(report, "extras", None) or {}
    if "position_dof" in extras or "angle_dof" in extras:
        pos, ang = extras.get("position_dof"), extras.get("angle_dof")
        return (None if pos is None else float(pos)), (None if ang is None else float(ang))
    dof = report_dof(report)
    return dof, dof


def _combine(own: float | None, dof: float | None, others: list[float],
             other_dofs: list[float | None], f: int) -> float | None:
    """Total of the solve's own bound (F with ``dof``, or chi-square) and the other terms'
    bounds (each F with its dof, or chi-square): their squares add on the chi-square scale,
    and the total takes the F quantile of the Welch-Satterthwaite dof
    (:func:`solvers.report.welch_dof`)."""
    if own is None:
        return None
    v_own = (own / _f_over_chi(dof, f)) ** 2
    v = [(b / _f_over_chi(n, f)) ** 2 for b, n in zip(others, other_dofs)]
    nu = welch_dof([v_own, *v], [dof, *other_dofs])
    return float(np.sqrt(v_own + sum(v))) * _f_over_chi(nu, f)


def _combine_cov(own: FloatArray, dof: float | None, others: list[FloatArray],
                 other_dofs: list[float | None]) -> float:
    """Bound of the summed covariance ``own + Σ others`` (each scaled by its own sigma):
    :func:`solvers.report.bound95` of the total with the Welch-Satterthwaite dof of the
    traces, the F quantile taken at the total's own effective dimension as bound95 takes it
    for the solve's own bound. (Until 2026-11-27 the chi-square bound times
    :func:`_f_over_chi` at the full dimension: for an elongated covariance that is wider than
    bound95 with the same dof, so a negligible term moved the total away from the solve's own
    bound: diag(1, 0.01, 0.01) at dof 3 from 3.21 to 3.71.)"""
    total = own + sum(others, np.zeros_like(own))
    nu = welch_dof([float(np.trace(C)) for C in (own, *others)], [dof, *other_dofs])
    return bound95(total, nu)


def combined_bounds(position_bound95_mm: float | None, angle_bound95_deg: float | None,
                    terms: dict[str, FloatArray],
                    dof: float | None | tuple[float | None, float | None] = None,
                    own_covariance: FloatArray | None = None,
                    term_dofs: dict[str, float | None] | None = None) -> dict[str, object]:
    """The result's 95 % bounds with every term: the solve's own (touch scatter; F quantiles
    with ``dof`` when its sigma was estimated, else chi-square) and each propagated covariance
    (6, 6) of ``terms`` (:func:`propagate` of a stored covariance, its sigma estimated with
    ``term_dofs[name]`` degrees of freedom, or known: None).

    A term's bound is :func:`solvers.report.bound95` of its position (angle) block. With the
    solve's own covariance ``own_covariance`` (6, 6: position mm, rotation deg about the
    solved frame's axes) the covariances add and the total is the bound of their sum;
    without it the squared bounds add on the chi-square scale (exact for terms of one shape,
    wide otherwise). With an estimated sigma the total takes the F quantile of the
    Welch-Satterthwaite degrees of freedom (:func:`_combine`, :func:`_combine_cov`). ``dof``
    may be a pair, the position block's and the angle block's (:func:`report_dofs`).

    Returns
    -------
    dict
        ``position_bound95_mm``, ``angle_bound95_deg`` (totals) and ``terms``: per term name
        ``{"position_bound95_mm", "angle_bound95_deg"}``, the touch term first.

    References
    ----------
    .. [1] F. E. Satterthwaite, "An approximate distribution of estimates of variance
       components", Biometrics Bulletin 2(6), 110-114, 1946.

    Examples
    --------
    >>> C = np.diag([0.01, 0.01, 0.01, 0.0, 0.0, 0.0])
    >>> round(combined_bounds(0.2795, None, {"tool 1": C})["position_bound95_mm"], 4)
    0.3953
    """
    dof_pos, dof_ang = dof if isinstance(dof, tuple) else (dof, dof)
    out_terms: dict[str, dict[str, float | None]] = {
        "touch": {"position_bound95_mm": position_bound95_mm,
                  "angle_bound95_deg": angle_bound95_deg}}
    pos, ang, nus = [], [], []
    for name, C in terms.items():
        C = np.asarray(C, dtype=float)
        nu = (term_dofs or {}).get(name)
        nus.append(nu)
        bp, ba = bound95(C[:3, :3], nu), bound95(C[3:, 3:], nu)
        out_terms[name] = {"position_bound95_mm": bp, "angle_bound95_deg": ba}
        pos.append(bp)
        ang.append(ba)
    if own_covariance is not None and terms:
        C0 = np.asarray(own_covariance, dtype=float)
        Cs = [np.asarray(C, dtype=float) for C in terms.values()]
        return {"position_bound95_mm": None if position_bound95_mm is None else
                _combine_cov(C0[:3, :3], dof_pos, [C[:3, :3] for C in Cs], nus),
                "angle_bound95_deg": None if angle_bound95_deg is None else
                _combine_cov(C0[3:, 3:], dof_ang, [C[3:, 3:] for C in Cs], nus),
                "terms": out_terms}
    return {"position_bound95_mm": _combine(position_bound95_mm, dof_pos, pos, nus, 3),
            "angle_bound95_deg": _combine(angle_bound95_deg, dof_ang, ang, nus, 3),
            "terms": out_terms}


__all__ = ["combined_bounds", "frame_vector", "own_covariance", "propagate", "rail_shift",
           "report_dof", "report_dofs", "to_world", "welch_dof"]
