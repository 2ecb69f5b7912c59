"""Coverage of ``solvers.report.bound95``'s Satterthwaite–Box approximation, by Monte Carlo
over eigenvalue ratios and residual degrees of freedom.

``bound95(C, dof)`` approximates the 95 % radius of ``e ~ N(0, C)`` by matching ``|e|²`` to
``c χ²_f`` (``c f F(f, dof)`` when sigma was estimated). Its docstring and docs/methods.md
say the coverage is exact for an isotropic C and for one dominant axis, and between them
within a stated margin of 95 %. Each cell here measures it as the solvers use the bound:
the covariance is ``C = σ̂² C_unit`` (sigma estimated from ``dof`` residual degrees of
freedom, ``σ̂²/σ² ~ χ²_dof/dof`` independent of e; ``dof=None``: σ assumed, σ̂ = σ) and the
truth's error is ``e ~ N(0, σ² C_unit)``; a sample is covered when
``|e| <= bound95(σ̂² C_unit, dof)``. ``bound95`` is homogeneous of degree 1 in σ̂ (checked
below), so it is computed once per cell for σ̂ = σ = 1 and scaled by σ̂.

Shapes (the eigenvalues of ``C_unit``, largest 1): k = 2 ``(1, r)``; k = 3 ``(1, 1, r)``,
``(1, r, r)`` and ``(1, r, r²)``; r in 1, 0.5, 0.2, 0.1, 0.05, 0.01 (r = 1: isotropic,
listed once per k). dof in 2, 3, 5, 10, 30 and ∞ (None). 200 000 samples a cell by default
(binomial standard error 0.049 % at 95 %), seeded. The lowest and highest of 132 noisy cells
stray about 3 standard errors beyond the true extremes, so a cell counts as outside a margin
only when it is more than 3 standard errors beyond it. ``--exact`` also integrates the
coverage numerically (``scipy.integrate.quad``; shapes with two distinct eigenvalues: all but
``(1,r,r²)``) for the three cells furthest from 95 %. The last line:

    bound95_coverage_min=<%> bound95_coverage_max=<%> worst=<shape,dof>

    PYTHONPATH=. python benchmarks/bound95_coverage.py [--samples 200000] [--seed 95] [--exact]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy import integrate, special, stats

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from solvers.report import bound95

RATIOS = (1.0, 0.5, 0.2, 0.1, 0.05, 0.01)
DOFS: tuple[int | None, ...] = (2, 3, 5, 10, 30, None)
SHAPES = {  # name: eigenvalues of C_unit as a function of r
    "(1,r)": lambda r: (1.0, r),
    "(1,1,r)": lambda r: (1.0, 1.0, r),
    "(1,r,r)": lambda r: (1.0, r, r),
    "(1,r,r²)": lambda r: (1.0, r, r * r),
}


def cells() -> list[tuple[str, float, tuple[float, ...]]]:
    """(shape, r, eigenvalues) of every cell, each set of eigenvalues once (r = 1 per k)."""
    out, seen = [], set()
    for name, shape in SHAPES.items():
        for r in RATIOS:
            lam = shape(r)
            if lam not in seen:
                seen.add(lam)
                out.append((name, r, lam))
    return out


def coverage(eigenvalues: tuple[float, ...], dof: int | None, samples: int,
             rng: np.random.Generator) -> float:
    """P(|e| <= bound95(σ̂² C_unit, dof)) for ``e ~ N(0, diag(eigenvalues))`` (σ = 1),
    ``σ̂² ~ χ²_dof/dof`` (1 when ``dof`` is None), estimated from ``samples`` draws."""
    lam = np.asarray(eigenvalues, dtype=float)
    b = bound95(np.diag(lam), dof)  # at σ̂ = σ; the bound scales with σ̂
    e2 = (rng.standard_normal((samples, lam.size)) ** 2) @ lam
    s2 = 1.0 if dof is None else rng.chisquare(dof, samples) / dof
    return float(np.mean(e2 <= s2 * b * b))


def exact_coverage(eigenvalues: tuple[float, ...], dof: int | None) -> float | None:
    """The coverage of :func:`coverage` by quadrature, for eigenvalues ``1`` (m1 times) and
    ``r`` (m2 times) with m1 + m2 <= 3; None for three distinct eigenvalues."""
    lam = sorted(eigenvalues, reverse=True)
    r = lam[-1]
    m1 = sum(1 for x in lam if x == 1.0)
    m2 = len(lam) - m1
    if lam[0] != 1.0 or any(x not in (1.0, r) for x in lam):
        return None
    b2 = bound95(np.diag(lam), dof) ** 2

    def cdf(t: float) -> float:  # P(χ²_m1 + r χ²_m2 <= t)
        if m2 == 0:
            return float(special.chdtr(m1, t))
        if m1 == 1:  # χ²_1 = z², z half-normal
            f = lambda z: 2 * stats.norm.pdf(z) * special.chdtr(m2, (t - z * z) / r)
            return integrate.quad(f, 0, math.sqrt(t), epsabs=1e-13, epsrel=1e-12)[0]
        f = lambda a: 0.5 * math.exp(-a / 2) * special.chdtr(m2, (t - a) / r)
        return integrate.quad(f, 0, t, epsabs=1e-13, epsrel=1e-12)[0]

    if dof is None:
        return cdf(b2)
    g = lambda x: cdf(x * b2 / dof) * stats.chi2.pdf(x, dof)
    return integrate.quad(g, 0, np.inf, epsabs=1e-12, limit=200)[0]


def check_homogeneous() -> None:
    """bound95(s² C, dof) = s bound95(C, dof): what lets a cell compute the bound once."""
    for lam in ((1.0, 0.3), (1.0, 0.2, 0.01)):
        C = np.diag(lam)
        for dof in DOFS:
            b = bound95(C, dof)
            for s in (0.1, 0.7, 3.0):
                assert math.isclose(bound95(C * s * s, dof), s * b, rel_tol=1e-12), (lam, dof, s)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=int, default=200_000, help="draws a cell")
    ap.add_argument("--seed", type=int, default=95)
    ap.add_argument("--exact", action="store_true",
                    help="integrate the three cells furthest from 95 %% (two distinct eigenvalues)")
    args = ap.parse_args()
    check_homogeneous()
    rng = np.random.default_rng(args.seed)
    se = 100 * math.sqrt(0.95 * 0.05 / args.samples)
    t0 = time.perf_counter()
    dof_names = ["∞" if d is None else str(d) for d in DOFS]
    print(f"coverage of bound95 (%), {args.samples} samples a cell, standard error {se:.3f} %, "
          f"seed {args.seed}")
    print(f"{'shape':<10}{'r':>6}  " + "".join(f"{'dof ' + d:>10}" for d in dof_names))
    results: list[tuple[float, str]] = []
    where: dict[str, tuple[tuple[float, ...], int | None]] = {}
    for name, r, lam in cells():
        row = []
        for dof, dname in zip(DOFS, dof_names):
            cov = 100 * coverage(lam, dof, args.samples, rng)
            row.append(cov)
            results.append((cov, f"{name} r={r:g},dof={dname}"))
            where[results[-1][1]] = (lam, dof)
        print(f"{name:<10}{r:>6g}  " + "".join(f"{c:>10.2f}" for c in row))
    lo, hi = min(results), max(results)
    worst = max(results, key=lambda x: abs(x[0] - 95.0))
    beyond = [c for c, _ in results if abs(c - 95.0) > 0.2]
    significant = [c for c, _ in results if abs(c - 95.0) > 0.2 + 3 * se]
    print(f"{len(results)} cells in {time.perf_counter() - t0:.1f} s; lowest {lo[0]:.2f} % "
          f"({lo[1]}), highest {hi[0]:.2f} % ({hi[1]}); beyond 95 ± 0.2 %: {len(beyond)} cells, "
          f"by more than 3 standard errors: {len(significant)}")
    if args.exact:
        print("exact (quadrature) where the Monte Carlo strays furthest from 95 %:")
        shown = 0
        for cov, label in sorted(results, key=lambda x: -abs(x[0] - 95.0)):
            exact = exact_coverage(*where[label])
            if exact is not None:
                print(f"  {label}: Monte Carlo {cov:.3f} %, exact {100 * exact:.3f} %")
                shown += 1
                if shown == 3:
                    break
    print(f"bound95_coverage_min={lo[0]:.2f} bound95_coverage_max={hi[0]:.2f} "
          f"worst=<{worst[1].replace(' ', ',')}>")


if __name__ == "__main__":
    main()
