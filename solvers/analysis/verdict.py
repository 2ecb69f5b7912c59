"""Steps 3 and 4, stand-ins and verdict: is structure left, and what only stands in for it.

*Structure test.* The residual outside the final model is F-tested (Seber & Wild, *Nonlinear
Regression*, sec. 5.3) against each generic group of smooth functions
(``locate.structure_groups``: low- and high-order Fourier terms of each joint's angle, and
time), the family controlled with Holm's procedure at ``ALPHA_STRUCTURE`` (Holm, Scand. J.
Statist. 6:65-70, 1979).

*Stand-ins.* When structure remains, a finding that loses its significance, or changes by
more than half, once the strongest remaining group is added may only stand in for that
structure. It is **kept** (it was selected because it lowers the held-out error, and
withholding it would cost that accuracy) and named as a stand-in in its evidence and
explanation.

*Refused candidates.* A candidate the selection refused as physically impossible
(``forward.Refused``: it ranked above what its step accepted, but its fitted value lies
beyond ``screen.PLAUSIBLE``) joins the groups as one more structure: its regressor fitted
real structure that no possible value of it explains. If the final residual still carries
it, that is structure left (the verdict cannot be ``explained``), and the findings that
lose their significance or change by more than half once it is added (the stand-in measure
above) may only stand in for it.

*Verdict.* ``unexplained_structure`` when a group (or a refused candidate) still tests
significant, else ``explained`` with findings, else ``no_missing_physics``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solvers.analysis.baseline import Baseline
from solvers.analysis.forward import ALPHA, group_gains, model, significance_in
from solvers.analysis.selection import fit_linear, holm_pass, orth, project_out, residual_ratio

ALPHA_STRUCTURE = 1e-4  # family-wise level of the final structure test (Holm)
PART_OF = 0.1          # a finding this far inside the structure group is part of it
STANDIN_CHANGE = 0.5    # relative change of a finding's parameters that marks a stand-in


@dataclass
class StandIn:
    """A finding that may stand in for unexplained structure (kept in the model)."""

    key: str
    structure: str                 # the group it stands in for
    p_value_with_structure: float
    relative_change: float


def structure_test(y, Q, groups, n_rows, alpha=ALPHA_STRUCTURE):
    """Holm test of every structure group on the residual outside span(Q): (name, p, gain)."""
    res = group_gains(project_out(Q, y), Q, groups, n_rows)
    ok = holm_pass([r[2] for r in res], alpha) if res else []
    return sorted([(r[0], r[2], r[1]) for r, o in zip(res, ok) if o], key=lambda t: t[1])


def stand_ins(y, base: Baseline, chosen, groups, n_rows, alpha: float = ALPHA,
              refused=()) -> list[StandIn]:
    """The findings that may only stand in for the strongest remaining structure, or for a
    refused candidate's structure that remains (``refused``: (name, columns) groups)."""
    if not chosen:
        return []
    Q = orth(model(base, chosen))
    every = list(groups) + list(refused)
    sig = structure_test(y, Q, every, n_rows)
    if not sig:
        return []
    rnames = {n for n, _ in refused}
    # each refused candidate's structure that remains (the more specific claim: its best
    # explanation was impossible), then the strongest structure; strongest first
    targets = [n for n, _, _ in sig if n in rnames]
    targets += [sig[0][0]] if sig[0][0] not in rnames else []
    b_old = fit_linear(y, model(base, chosen))[0]
    found: dict[str, StandIn] = {}
    for name in targets:
        S = [cols for n, cols in every if n == name]
        b_new = fit_linear(y, model(base, chosen, S))[0]
        col = base.B.shape[1]
        for c in chosen:
            k = c.columns.shape[1]
            bo, bn = b_old[col:col + k], b_new[col:col + k]
            col += k
            if c.key in found:
                continue
            change = float(np.linalg.norm(bn - bo) / max(np.linalg.norm(bo), 1e-300))
            if residual_ratio(orth(S[0]), c.columns) < PART_OF:
                continue   # one component of that very structure (a gear harmonic), not a stand-in
            p = significance_in(y, base, chosen, c, S, n_rows)
            if not (p * len(chosen) < alpha and change < STANDIN_CHANGE):
                found[c.key] = StandIn(c.key, name, float(p), round(change, 3))
    return [found[c.key] for c in chosen if c.key in found]


def verdict_of(structure: list, n_findings: int) -> str:
    if structure:
        return "unexplained_structure"
    return "explained" if n_findings else "no_missing_physics"
