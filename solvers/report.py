"""The quality report every calibration method returns, and the statistics behind it.

A pendant shows one number ("error 0.4 mm"); this report gives the residual of each
touch-up, the uncertainty of the result from the geometry and the residual, the point to
re-teach, geometry warnings in plain words, and where to touch next.
"""

from __future__ import annotations

import math

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from scipy import special, stats

from solvers.validate import FloatArray

CHI2_95 = {d: float(stats.chi2.ppf(0.95, d)) for d in (1, 2, 3)}


@dataclass(frozen=True)
class Finding:
    """A warning or note with a stable ``code``, plain ``message`` and the field it concerns."""

    code: str
    message: str
    loc: tuple[str | int, ...] = ()
    severity: Literal["warning", "info"] = "warning"


@dataclass(frozen=True)
class BadPoint:
    """A touch-up that does not agree with the others, and the result without it."""

    index: int
    residual_mm: float  # its distance from the fit made without it
    threshold_mm: float  # what the other points' scatter allows
    refit_frame: FloatArray  # the method's result without this point
    refit_rms_mm: float

    def message(self) -> str:
        return (f"point {self.index + 1} is {self.residual_mm:.3f} mm off the fit of the others "
                f"(they allow {self.threshold_mm:.3f} mm): re-teach it")


@dataclass(frozen=True)
class QualityReport:
    """What the solve says about itself.

    ``residuals_mm[k]`` is point k's distance from the model (mm); ``residuals_deg`` the
    orientation error where orientation is solved. ``covariance`` is that of
    ``parameter_names`` (mm, deg) from the geometry and ``sigma_mm``. ``sigma_source`` says
    where sigma comes from: ``"residual"`` (estimated from the residuals with ``dof`` degrees
    of freedom: the bounds use F quantiles), ``"assumed"`` (a documented nominal value, or the
    floor when the residual is smaller: chi-square quantiles, valid only if that sigma is
    right). ``position_bound95_mm`` / ``angle_bound95_deg`` are 95% bounds on the length of
    the position / rotation error (:func:`bound95`); ``mahalanobis_bound95`` bounds the
    Mahalanobis distance of all parameters jointly (:func:`mahalanobis_bound95`).
    """

    residuals_mm: FloatArray
    residuals_deg: FloatArray | None = None
    parameter_names: tuple[str, ...] = ()
    covariance: FloatArray | None = None
    sigma_mm: float | None = None  # noise level the covariance used
    sigma_source: Literal["residual", "assumed"] | None = None
    dof: int | None = None  # residual degrees of freedom behind sigma_mm (None: assumed)
    position_bound95_mm: float | None = None
    angle_bound95_deg: float | None = None
    mahalanobis_bound95: float | None = None  # of all parameter_names jointly
    tre_mm: float | None = None  # expected error at a target point (base frames)
    bad_point: BadPoint | None = None
    warnings: tuple[Finding, ...] = ()
    guidance: str | None = None
    next_orientation: FloatArray | None = None  # 3x3 flange orientation to touch up next
    extras: Mapping[str, Any] = field(default_factory=dict)

    @property
    def max_error_mm(self) -> float:
        return float(np.max(self.residuals_mm)) if len(self.residuals_mm) else 0.0

    @property
    def mean_error_mm(self) -> float:
        return float(np.mean(self.residuals_mm)) if len(self.residuals_mm) else 0.0

    @property
    def rms_error_mm(self) -> float:
        r = np.asarray(self.residuals_mm)
        return float(np.sqrt(np.mean(r**2))) if len(r) else 0.0

    @property
    def worst_point(self) -> int | None:
        return int(np.argmax(self.residuals_mm)) if len(self.residuals_mm) else None

    @property
    def max_error_deg(self) -> float | None:
        return None if self.residuals_deg is None else float(np.max(self.residuals_deg))


@dataclass(frozen=True)
class CalibrationResult:
    """A menu's answer: the frame to store and the report on it.

    ``frame`` is a 4x4 transform whose meaning the method states: ``T_flange_tcp`` for a
    robot-held tool, ``T_base_frame`` (or world) for a base and a fixed tool,
    ``T_flange_workpiece`` for a robot-held workpiece.
    """

    method: str
    frame: FloatArray
    report: QualityReport

    @property
    def position_mm(self) -> FloatArray:
        return self.frame[:3, 3]


def residual_sigma(residual_vector: FloatArray, n_parameters: int, floor: float = 0.0) -> float:
    """sigma-hat = sqrt(SSR / (m - p)) of a stacked residual vector (m scalars), at least ``floor``."""
    r = np.ravel(residual_vector)
    dof = r.size - n_parameters
    if dof <= 0:
        return floor
    return max(float(np.sqrt(r @ r / dof)), floor)


def sigma_dof(sigma: float, dof: int | None, floor: float = 0.0) -> int | None:
    """The degrees of freedom the bounds may use: ``dof`` when sigma was estimated from the
    residual (above ``floor`` and ``dof >= 1``), else None (sigma assumed: chi-square)."""
    if dof is None or dof < 1 or sigma <= floor:
        return None
    return int(dof)


def bound95(covariance: FloatArray, dof: float | None = None) -> float:
    """95% bound on the length of an error vector with this (k x k) covariance.

    The radius ``b`` with ``P(|e| <= b) = 0.95`` for ``e ~ N(0, C)``. ``|e|²`` is a weighted
    sum of chi-squares, ``Σ λ_i z_i²`` (λ_i the eigenvalues of C), approximated after
    Satterthwaite and Box [1]_ by ``c χ²_f`` with the same mean and variance:
    ``c = Σλ²/Σλ``, ``f = (Σλ)²/Σλ²``. When C was scaled by a sigma estimated from the
    residual with ``dof`` degrees of freedom, ``|e|²/(c f)`` over ``σ̂²/σ²`` is ``F(f, dof)``
    distributed, so ``b² = c f F(f, dof; 0.95)``; with sigma assumed (``dof=None``)
    ``b² = c χ²(f; 0.95)``. ``dof`` may be fractional (a Welch-Satterthwaite effective
    dof of summed shares). Exact for an isotropic C (f = k) and for a single dominant axis
    (f = 1); between them the coverage is within 0.2 % of 95 % (Monte Carlo over eigenvalue
    ratios down to 1/100 and dof from 2 to infinity, 2 000 000 draws a cell: 94.97-95.20 %;
    the furthest, eigenvalues (1, 0.2, 0.2) at dof 10, is 95.19 % by quadrature, wide;
    ``python benchmarks/bound95_coverage.py --samples 2000000 --seed 7 --exact``).

    References
    ----------
    .. [1] G. E. P. Box, "Some theorems on quadratic forms applied in the study of analysis
       of variance problems, I", Ann. Math. Statist. 25(2), 290-302, 1954.

    Examples
    --------
    >>> round(bound95(np.diag([0.01, 0.01, 0.01])), 4)  # isotropic: sqrt(chi2(3) * 0.01)
    0.2795
    >>> round(bound95(np.diag([0.04, 0.0, 0.0])), 4)  # one axis: 1.96 * 0.2
    0.392
    >>> round(bound95(np.diag([0.01, 0.01, 0.01]), dof=6), 4)  # sigma estimated: wider
    0.3778
    """
    return bound95_of_eigenvalues(np.linalg.eigvalsh(np.asarray(covariance, dtype=float)), dof)


def bound95_of_eigenvalues(eigenvalues: Sequence[float] | FloatArray,
                           dof: float | None = None) -> float:
    """:func:`bound95` from the covariance's eigenvalues (negative round-off taken as 0).
    The quantiles are ``scipy.special.chdtri`` / ``fdtri``, the functions behind
    ``scipy.stats.chi2.ppf`` / ``scipy.stats.f.ppf``, without their per-call overhead."""
    lam = [max(float(x), 0.0) for x in eigenvalues]
    s1, s2 = sum(lam), sum(x * x for x in lam)
    if s1 <= 0.0:
        return 0.0
    c, f = s2 / s1, s1 * s1 / s2
    # F(f, dof) -> chi2(f)/f as dof grows; a Welch-Satterthwaite dof of a sum dominated by a
    # known-sigma term can be 1e41, where scipy 1.14's fdtri gives nan
    chi = dof is None or not math.isfinite(dof) or dof > 1e6
    q = special.chdtri(f, 0.05) if chi else f * special.fdtri(f, dof, 0.95)
    return math.sqrt(c * float(q))


def welch_dof(variances: Sequence[float], dofs: Sequence[float | None]) -> float | None:
    """Welch-Satterthwaite effective degrees of freedom of a sum of independent variance
    terms ``v_i``, term i's sigma estimated with ``ν_i`` degrees of freedom [1]_ [2]_ [3]_:

        ``ν = (Σ v_i)² / Σ (v_i² / ν_i)``

    A term with sigma known (``ν_i`` None or 0: infinite) adds to the numerator only; with
    every sigma known, or no variance at all, the result is None (infinite: chi-square
    quantiles, as :func:`bound95` takes None). A variance's round-off below 0 counts as 0.
    ν is at least the smallest ν_i of the terms that count, and one term gives its own ν_i.
    The bound of the summed covariance is then :func:`bound95` with this dof.

    References
    ----------
    .. [1] F. E. Satterthwaite, "An approximate distribution of estimates of variance
       components", Biometrics Bulletin 2(6), 110-114, 1946.
    .. [2] B. L. Welch, "The generalization of 'Student's' problem when several different
       population variances are involved", Biometrika 34(1/2), 28-35, 1947.
    .. [3] JCGM 100:2008 (GUM), Evaluation of measurement data - Guide to the expression of
       uncertainty in measurement, G.4.1.

    Examples
    --------
    >>> welch_dof([0.01, 0.01], [None, 2])  # equal terms, one known: (0.02)² / (0.01² / 2)
    8.0
    >>> welch_dof([0.01, 0.01], [4, 4])  # two equal terms of 4 dof: 8, as if pooled
    8.0
    >>> welch_dof([0.01, 0.02], [None, 0]) is None, welch_dof([], []) is None
    (True, True)
    """
    v = [max(float(x), 0.0) for x in variances]
    den = sum(x * x / n for x, n in zip(v, dofs) if n)
    if den <= 0 or sum(v) <= 0:
        return None  # every term with sigma known, or no variance at all: chi-square
    return sum(v) ** 2 / den


def mahalanobis_bound95(n_parameters: int, dof: int | None = None) -> float:
    """95% bound on the Mahalanobis distance ``sqrt(eᵀ C⁻¹ e)`` of all p parameters jointly:
    ``sqrt(p F(p, dof; 0.95))`` when sigma was estimated with ``dof`` degrees of freedom (the
    joint confidence region of linear least squares), ``sqrt(χ²(p; 0.95))`` when assumed.

    Examples
    --------
    >>> round(mahalanobis_bound95(3), 4), round(mahalanobis_bound95(3, dof=6), 4)
    (2.7955, 3.7777)
    """
    if dof is None:  # scipy.special's chdtri / fdtri: stats.chi2.ppf / stats.f.ppf without overhead
        return math.sqrt(float(special.chdtri(n_parameters, 0.05)))
    return math.sqrt(n_parameters * float(special.fdtri(n_parameters, dof, 0.95)))


def mahalanobis_distance(error: FloatArray, covariance: FloatArray) -> float:
    """``sqrt(eᵀ C⁻¹ e)`` (C positive definite), to compare with ``mahalanobis_bound95``."""
    e = np.asarray(error, dtype=float)
    return float(np.sqrt(e @ np.linalg.solve(np.asarray(covariance, dtype=float), e)))


def bounds95(covariance: FloatArray, dof: int | None, position: slice | None = slice(0, 3),
             angle: slice | None = None) -> dict[str, float | None]:
    """The three 95% bounds of a report from one covariance (mm, deg): the keyword arguments
    ``position_bound95_mm``, ``angle_bound95_deg``, ``mahalanobis_bound95`` of
    :class:`QualityReport` for the parameter blocks ``position`` and ``angle``."""
    C = np.asarray(covariance, dtype=float)
    return {"position_bound95_mm": None if position is None else bound95(C[position, position], dof),
            "angle_bound95_deg": None if angle is None else bound95(C[angle, angle], dof),
            "mahalanobis_bound95": mahalanobis_bound95(len(C), dof),
            "dof": dof, "sigma_source": "assumed" if dof is None else "residual"}


def leave_one_out_bad_point(n: int, fit: Callable[[Sequence[int]], tuple[FloatArray, Callable[[int], float]]],
                            n_parameters: int, floor_mm: float = 0.02, k_sigma: float = 4.0,
                            min_points: int | None = None) -> BadPoint | None:
    """Find the one touch-up that disagrees with the rest.

    ``fit(indices)`` solves from those points only and returns ``(frame, error_of)`` where
    ``error_of(i)`` is point i's distance (mm) from that solution. For every point the fit
    without it predicts it; the point with the largest prediction error is bad when that
    error exceeds ``k_sigma`` times the scatter of the others (their RMS residual corrected
    for the fitted parameters) and ``floor_mm``. Needs enough points that the fit without one
    is still over-determined, else returns None.
    """
    if n < (min_points or 0) or n < 2:
        return None
    worst: tuple[float, int, FloatArray, float, float] | None = None
    for i in range(n):
        keep = [j for j in range(n) if j != i]
        try:
            frame, error_of = fit(keep)
        except ValueError:
            continue
        others = np.array([error_of(j) for j in keep])
        dof = max(len(keep) - n_parameters, 1)
        scatter = float(np.sqrt((others**2).sum() / dof))
        e = error_of(i)
        score = e / max(scatter, 1e-12)
        if worst is None or score > worst[0]:
            worst = (score, i, frame, e, scatter)
    if worst is None:
        return None
    score, i, frame, e, scatter = worst
    threshold = max(k_sigma * scatter, floor_mm)
    if e <= threshold:
        return None
    _, error_of = fit([j for j in range(n) if j != i])
    rms = float(np.sqrt(np.mean([error_of(j) ** 2 for j in range(n) if j != i])))
    return BadPoint(index=i, residual_mm=float(e), threshold_mm=float(threshold), refit_frame=frame,
                    refit_rms_mm=rms)
