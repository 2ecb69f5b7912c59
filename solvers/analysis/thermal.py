"""The warm-up time constant of a thermal-drift finding, by profiling.

A first-order warm-up ``D (1 - exp(-t/tau))`` (the response ISO 230-3 measures on machine
tools) is linear in the drift vector D for a fixed tau; tau enters nonlinearly. The
selection offers a grid of tau (``effects.TAU_GRID``); here, with the other findings held in
the model, the residual sum of squares is profiled over tau (log-spaced, from a fiftieth of
the recording's span to twenty spans, and the linear limit), the minimum refined by a bounded
scalar search, and a 95 % profile-likelihood interval taken where
``(RSS(tau) - RSS_min) / sigma^2 < chi2_1(0.95) = 3.84`` (Venzon & Moolgavkar, "A method for
computing profile-likelihood-based confidence intervals", Appl. Statist. 37:87-94, 1988).

The interval says whether the recording's time span separates tau: when it reaches the
linear limit, a linear drift explains the data as well (tau is not separable from a long
one); when it reaches the shortest tau tried, the warm-up is over before the second sample
(a step).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from solvers.analysis.baseline import Baseline
from solvers.analysis.effects import Candidate, thermal_candidate
from solvers.analysis.forward import model
from solvers.analysis.selection import orth, project_out

CHI2_1_95 = 3.841
GRID = np.geomspace(1 / 50, 20.0, 28)   # tau / span


@dataclass
class TauProfile:
    tau_s: float | None            # best fit (None: linear)
    range_s: tuple[float | None, float | None]   # 95 % interval (None: unbounded that side)
    separable: bool                # the interval is bounded on both sides
    span_s: float


def _rss(y, base, chosen, i, cand) -> float:
    Q = orth(model(base, chosen[:i] + [cand] + chosen[i + 1:]))
    r = project_out(Q, y)
    return float(r @ r)


def profile_tau(rec, base: Baseline, y, chosen: list[Candidate], i: int
                ) -> tuple[Candidate, TauProfile]:
    """Refit the time constant of ``chosen[i]`` (a thermal_drift candidate)."""
    t = np.asarray(rec.t_s, float)
    span = float(np.ptp(t))
    taus = list(GRID * span)
    rss = [_rss(y, base, chosen, i, thermal_candidate(rec, base, tau)) for tau in taus]
    rss_lin = _rss(y, base, chosen, i, thermal_candidate(rec, base, None))
    j = int(np.argmin(rss))
    best_tau, best = taus[j], rss[j]
    if 0 < j < len(taus) - 1:
        res = minimize_scalar(
            lambda lt: _rss(y, base, chosen, i, thermal_candidate(rec, base, float(np.exp(lt)))),
            bounds=(np.log(taus[j - 1]), np.log(taus[j + 1])), method="bounded",
            options={"xatol": 1e-3})
        if res.fun < best:
            best_tau, best = float(np.exp(res.x)), float(res.fun)
    if rss_lin <= best:
        best_tau, best = None, rss_lin
    p = orth(model(base, chosen)).shape[1]
    sigma2 = best / max(y.size - p, 1)
    lin_inside = (rss_lin - best) / sigma2 < CHI2_1_95

    def excess(lt: float) -> float:
        return (_rss(y, base, chosen, i, thermal_candidate(rec, base, float(np.exp(lt)))) - best) \
            / sigma2 - CHI2_1_95

    # the interval's ends: the first grid point outside on each side, then a root between
    centre = np.log(best_tau) if best_tau is not None else np.log(taus[-1])
    lo = hi = None
    below = [t for t, r in zip(taus, rss) if np.log(t) < centre and (r - best) / sigma2 >= CHI2_1_95]
    if below:
        a = np.log(below[-1])
        b = min([np.log(t) for t in taus if np.log(t) > a] + [centre])
        lo = float(np.exp(brentq(excess, a, b, xtol=1e-3))) if excess(b) < 0 else float(np.exp(b))
    above = [t for t, r in zip(taus, rss) if np.log(t) > centre and (r - best) / sigma2 >= CHI2_1_95]
    if above and not lin_inside:
        b = np.log(above[0])
        a = max([np.log(t) for t in taus if np.log(t) < b] + [centre])
        hi = float(np.exp(brentq(excess, a, b, xtol=1e-3))) if excess(a) < 0 else float(np.exp(a))
    prof = TauProfile(best_tau, (lo, hi), lo is not None and hi is not None, span)
    return thermal_candidate(rec, base, best_tau), prof
