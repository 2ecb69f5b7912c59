"""The quality report every calibration method returns, and the statistics behind it.

A pendant shows one number ("error 0.4 mm"); this report gives the residual of each
touch-up, the uncertainty of the result from the geometry and the residual, the point to
re-teach, geometry warnings in plain words, and where to touch next.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from scipy import stats

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
    ``parameter_names`` (mm, deg) from the geometry and the residual; the 95% bounds are
    radii of the 95% confidence ellipsoid's largest axis.
    """

    residuals_mm: FloatArray
    residuals_deg: FloatArray | None = None
    parameter_names: tuple[str, ...] = ()
    covariance: FloatArray | None = None
    sigma_mm: float | None = None  # noise level the covariance used
    position_bound95_mm: float | None = None
    angle_bound95_deg: float | None = None
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


def bound95(covariance: FloatArray) -> float:
    """Radius of the largest axis of the 95% confidence ellipsoid of a (k x k) covariance.

    Examples
    --------
    >>> round(bound95(np.diag([0.01, 0.01, 0.04])), 4)
    0.5591
    """
    C = np.asarray(covariance, dtype=float)
    k = C.shape[0]
    return float(np.sqrt(CHI2_95[k] * max(np.linalg.eigvalsh(C).max(), 0.0)))


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
