"""Step 2, selection: forward selection of candidate effects, then a backward check.

At each step every identifiable candidate not yet in the model is tested against the current
model M (baseline + findings so far) with the extra-sum-of-squares F-test

    F = ((RSS_M - RSS_{M+X}) / k) / (RSS_{M+X} / (n - p - k))  ~  F(k, n - p - k)

(Seber & Wild, *Nonlinear Regression*, Wiley 1989, sec. 5.3, applied to the model linearised
at the current fit). The family of the step's p-values is controlled with Holm's step-down
procedure at level ``alpha`` (Holm, "A simple sequentially rejective multiple test
procedure", Scand. J. Statist. 6:65-70, 1979): every harmonic of every joint's gear error and
every warm-up time constant counts in the family, so scanning a periodogram or a grid of tau
costs what it should. Of the candidates that pass, the one with the largest penalised gain
``RSS reduction - k sigma^2`` (Mallows' C_p) is added if it also lowers the K-fold
cross-validated (held-out) RMS by at least ``MIN_CV_GAIN`` (Stone, "Cross-validatory choice
and assessment of statistical predictions", JRSS B 36:111-147, 1974) and explains at least
``GUARD_FRACTION`` of what the generic structure groups could (so an effect is not named for
a small share of a large unexplained structure).

A gear harmonic must also be *resolved* (``resolved``): still fit the residual, by the
alternatives' margin ``ALTERNATIVE_LR`` sigma^2, once any harmonic of the same joint that
the joint's travel left out (``effects.Library.longer``: periods longer than the travel,
never named themselves) is in the model. Over a travel of T deg the harmonics k and k+1 drift apart in
phase by only T deg, so on a narrow travel (a touch recording:
20-90 deg) their regressors, outside the rigid model, have principal cosines of 0.95-0.999
and two offered harmonics span a left-out one to |cos| 0.999: a left-out 6-per-turn error
over 59 deg came out as 7 and 8 per turn at twice its amplitude. If a left-out (longer)
period explains what it does, the data show a smooth trend over the travel, which the travel rule
already says no harmonic is named for; the harmonic is not named (``Selection.unresolved``),
nor listed among another finding's alternatives.

The best-ranked candidate of a step whose fitted value is physically impossible
(``plausible``), if it ranks above the one the step accepts (or nothing is accepted), is
*refused*, not forgotten (``Selection.refused``): its regressor fits real structure (it
passed the step's tests) that no possible value of it explains, so what is accepted after it
may only stand in for that structure (``verdict.py`` tests it on the final residual; a value
beyond the limits of the possible points at a gross error: a wrong robot model, a wrong
unit, a broken sensor).

The backward check drops a finding that is no longer significant in the full model
(Bonferroni over the findings), and refuses one whose value there is no longer possible.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solvers.analysis.baseline import Baseline
from solvers.analysis.effects import Candidate
from solvers.analysis.screen import IDENT_TOL, PLAUSIBLE
from solvers.analysis.selection import (CV, batch_f_tests, f_test, fit_linear, holm_pass,
                                        identifiable_part, normalise, orth, project_out,
                                        residual_ratio)
from solvers.analysis.text import unresolved_reason

ALPHA = 1e-3            # family-wise level of each selection step (Holm)
GUARD_FRACTION = 0.05   # a named effect must explain this share of the structure found
MIN_CV_GAIN = 0.002     # relative held-out RMS improvement an effect must bring
SAME_COS = 0.999        # |cos| between projected regressors: indistinguishable effects
ALTERNATIVE_LR = 4.0    # RSS difference / sigma^2 under which another candidate is as good
PRIORITY = ("joint_offset", "joint_compliance", "backlash", "link_length", "link_twist",
            "gear_transmission_error", "thermal_drift", "trigger_latency", "tool_deflection")


@dataclass
class StepStats:
    """The evidence of one selection step (what made the chosen candidate a finding)."""

    p_value: float                 # F-test p-value against the model before this step
    family: int                    # candidates tested in the step (Holm's family)
    r: float                       # sqrt(share of the remaining residual it explains)
    identifiability: float         # relative residual of its regressor outside the model
    structure_share: float         # its penalised gain / that of the best structure group
    alternatives: list[Candidate] = field(default_factory=list)   # almost as good
    same: list[Candidate] = field(default_factory=list)           # indistinguishable here
    periodogram: dict[int, float] = field(default_factory=dict)   # gear: k -> RSS share


@dataclass
class Refused:
    """A candidate that fitted the residual best (at its step) with an impossible value."""

    candidate: Candidate
    beta: np.ndarray               # its fitted parameter(s), effects.py units (linearised)
    std: np.ndarray                # their standard deviations
    step: int                      # 1-based selection step at which it was refused
    preferred_over: str | None     # key of the candidate accepted at that step (None: none)
    dropped: bool = False          # named at ``step``, its value impossible once others joined

    @property
    def size(self) -> float:
        """What ``plausible`` compares with ``screen.PLAUSIBLE`` (the parameters' norm)."""
        return float(np.linalg.norm(self.beta))


@dataclass
class Selection:
    """The chosen candidates, in order, with the evidence of each step."""

    chosen: list[Candidate] = field(default_factory=list)
    steps: list[StepStats] = field(default_factory=list)
    # gear harmonics not named because a period longer than the travel fits as well (report
    # entries, ``not_identifiable``), by key
    unresolved: dict[str, dict] = field(default_factory=dict)
    # each step's best-ranked candidate refused as physically impossible (ranked above what
    # the step accepted, if anything), by key
    refused: dict[str, Refused] = field(default_factory=dict)

    def keys(self) -> list[str]:
        return [c.key for c in self.chosen]


def model(base: Baseline, chosen: list[Candidate], extra: list | None = None) -> np.ndarray:
    """The model's Jacobian: baseline columns, then each chosen effect's, then ``extra``."""
    return np.hstack([base.B] + [c.columns for c in chosen] + (extra or []))


_GROUP_X: dict = {}   # the stacked, normalised columns of the last groups seen (and the
                      # groups themselves, so their ids stay valid while cached)


def group_gains(y_perp, Q, groups, n_rows):
    """(name, gain, p, k) of each structure group; only its identifiable directions count."""
    if not groups:
        return []
    key = tuple(id(cols) for _, cols in groups)
    if _GROUP_X.get("key") != key:        # the same groups at every step of a selection
        _GROUP_X.update(key=key, X=np.hstack([normalise(cols) for _, cols in groups]),
                        groups=groups)
    X = _GROUP_X["X"]
    ends = np.cumsum([cols.shape[1] for _, cols in groups])
    blocks = [slice(int(e - cols.shape[1]), int(e)) for (_, cols), e in zip(groups, ends)]
    _, gain, p, k = batch_f_tests(Q, X, blocks, y_perp, n_rows, IDENT_TOL)
    return [(name, float(g), float(pp), int(kk))
            for (name, _), g, pp, kk in zip(groups, gain, p, k)]


def _indistinguishable(c, Q, tests) -> list[Candidate]:
    """One-parameter candidates whose regressor, outside span(Q), is c's (|cos| > SAME_COS)."""
    if c.columns.shape[1] != 1:
        return []
    ones = [t[0] for t in tests if t[0] is not c and t[0].columns.shape[1] == 1]
    if not ones:
        return []
    Xp = project_out(Q, normalise(np.hstack([c.columns] + [d.columns for d in ones])))
    Xp = Xp / np.maximum(np.linalg.norm(Xp, axis=0), 1e-300)
    cos = np.abs(Xp[:, 1:].T @ Xp[:, 0])
    return [d for d, v in zip(ones, cos) if v > SAME_COS]


class Longer:
    """The gear harmonics left out for too little travel (``effects.Library.longer``), as
    yardsticks of what a smooth trend over each joint's travel fits (see ``resolved``)."""

    def __init__(self, cands: list[Candidate] | None):
        self.by_joint: dict[int, list[Candidate]] = {}
        for c in cands or []:
            self.by_joint.setdefault(c.joint, []).append(c)


def resolved(c: Candidate, Q, y_perp, n_rows: int, longer: Longer) -> Candidate | None:
    """None if gear harmonic ``c`` still fits the residual once any left-out (longer) harmonic
    of its joint is in the model; else the longer harmonic that leaves it the least.

    With the current model (orthonormal basis ``Q``, residual ``y_perp`` outside it) and a
    left-out harmonic d added, c's extra sum of squares must be at least ``ALTERNATIVE_LR``
    residual variances of the model with both (``sigma^2 = RSS / (n - p)``): the margin
    under which ``alternatives`` calls two candidates equally good. Below it, what c explains
    a harmonic whose period is longer than the travel (a smooth trend over it) explains too,
    and the data give no evidence for c's own period (the module docstring). Only d's
    directions standing out of the model by ``IDENT_TOL`` count, as for every candidate.
    """
    if c.effect != "gear_transmission_error":
        return None
    Xc = project_out(Q, normalise(c.columns))
    best, least = None, ALTERNATIVE_LR
    for d in longer.by_joint.get(c.joint, []):
        Pd = identifiable_part(Q, d.columns, IDENT_TOL)
        if Pd.shape[1] == 0:
            continue
        Qd = orth(Pd)
        r = y_perp - Qd @ (Qd.T @ y_perp)
        Qc = orth(project_out(Qd, Xc), 1e-6)
        extra = float(np.sum((Qc.T @ r) ** 2))
        dof = n_rows - Q.shape[1] - Qd.shape[1] - Qc.shape[1]
        s2 = max(float(r @ r) - extra, 1e-300) / max(dof, 1)
        if extra / s2 < least:          # the longer harmonic that leaves c the least
            best, least = d, extra / s2
    return best


def _unresolved(test, Q, y_perp, n_rows, longer: Longer) -> Candidate | None:
    """:func:`resolved` of a step's test tuple (candidate, gain, p, k, _)."""
    return resolved(test[0], Q, y_perp, n_rows, longer)


def plausible(c: Candidate, beta: np.ndarray) -> bool:
    """Whether the candidate's fitted value ``beta`` is physically possible: the norm of its
    parameter(s) within ``screen.PLAUSIBLE``.

    A value beyond ``screen.PLAUSIBLE`` (e.g. a gear's transmission error of degrees, where
    strain-wave and cycloidal gears stay within arcminutes) means the candidate's regressor
    only fits some other structure; it is then not named, whatever the held-out gain. Those
    values are therefore upper limits of what each effect can be, not typical sizes: a
    latency limit of 20 ms (docs/emulator.md's own example) left that recording unnamed.
    """
    return float(np.linalg.norm(beta)) <= PLAUSIBLE[c.effect]


def fitted(y, M, c: Candidate) -> tuple[np.ndarray, np.ndarray]:
    """The candidate's fitted parameter(s) with the model M and their standard deviations."""
    beta, cov, _, _ = fit_linear(y, np.hstack([M, c.columns]))
    k = M.shape[1]
    return beta[k:], np.sqrt(np.maximum(np.diag(cov)[k:], 0.0))


def forward(y, base: Baseline, cands: list[Candidate], cv: CV, groups, alpha: float = ALPHA,
            max_findings: int = 16, longer: list[Candidate] | None = None) -> Selection:
    """Forward selection (see the module docstring); ``longer``: the gear harmonics left out
    for too little travel, which a named harmonic must fit better than (``resolved``)."""
    n_rows = y.size
    sel = Selection()
    yard = Longer(longer)
    cur_cv = cv.heldout_rms(y, base.B)
    X_all = np.hstack([normalise(c.columns) for c in cands]) if cands else np.zeros((n_rows, 0))
    P = project_out(orth(base.B), X_all)   # kept projected out of the growing model
    ends = np.cumsum([c.columns.shape[1] for c in cands])
    blocks = [slice(int(e - c.columns.shape[1]), int(e)) for c, e in zip(cands, ends)]
    while len(sel.chosen) < max_findings:
        M = model(base, sel.chosen)
        Q = orth(M)
        y_perp = project_out(Q, y)
        rss0 = float(y_perp @ y_perp)
        sigma2 = rss0 / max(n_rows - Q.shape[1], 1)
        families = {c.family for c in sel.chosen}
        ratio, gains, ps, ks = batch_f_tests(Q, P, blocks, y_perp, n_rows, projected=True)
        tests = []
        for i, c in enumerate(cands):
            if c.family in families or ratio[i] < IDENT_TOL:
                continue
            tests.append((c, float(gains[i]), float(ps[i]), int(ks[i]), None))
        if not tests:
            break
        passed = holm_pass([t[2] for t in tests], alpha)
        # every tested candidate by its gain less its size's share of the noise; the step
        # takes from those passing its Holm test, the alternatives come from all of them
        ranked = sorted(zip(tests, passed), key=lambda tp: -(tp[0][1] - tp[0][3] * sigma2))
        order = [t for t, ok in ranked if ok]
        if not order:
            break
        gg = group_gains(y_perp, Q, groups, n_rows)
        sgain = max([g - k * sigma2 for _, g, _, k in gg], default=0.0)
        accepted, refused = None, []
        for t in order[:8]:
            c, gain, p, k, Xp = t
            cgain = gain - k * sigma2
            if sgain > 0 and cgain < GUARD_FRACTION * sgain:
                continue
            b, s = fitted(y, M, c)
            if not plausible(c, b):
                refused.append((c, b, s))
                continue
            d = _unresolved(t, Q, y_perp, n_rows, yard)
            if d is not None:
                sel.unresolved[c.key] = {"effect": c.effect, "joint": c.joint,
                                         "periods_per_turn": c.periods,
                                         "fits_as_well": d.periods,
                                         "reason": unresolved_reason(c, d)}
                continue
            new_cv = cv.heldout_rms(y, np.hstack([M, c.columns]))
            if new_cv < cur_cv * (1.0 - MIN_CV_GAIN):
                accepted = (c, gain, p, k, Xp, new_cv, cgain)
                break
        if refused and refused[0][0].key not in sel.refused:
            # the step's best-ranked refused candidate (ranked above what it accepts, if any;
            # those ranked below it fit the same structure less well)
            d, b, s = refused[0]
            sel.refused[d.key] = Refused(d, b, s, len(sel.chosen) + 1,
                                         accepted[0].key if accepted else None)
        if accepted is None:
            break
        c, gain, p, k, Xp, new_cv, cgain = accepted
        same = _indistinguishable(c, Q, tests)
        if same:
            # indistinguishable on these poses: name the one physics expects first
            group = sorted([c] + same, key=lambda d: (PRIORITY.index(d.effect), d.joint or 0))
            if group[0] is not c:
                c, same = group[0], [d for d in group if d is not group[0]]
        # other candidates that explain almost as much (likelihood-ratio difference < 4, i.e.
        # about two standard errors): this recording cannot tell them apart with confidence.
        # Any tested candidate, not only those passing the step's Holm test alone: one just
        # short of that (a touch recording of a UR10's a2 off by 0.08 mm, 3.3 sigma^2 below the
        # a1 it was named as) is as good an explanation as the margin says
        s2 = max(rss0 - gain, 1e-300) / max(n_rows - Q.shape[1] - k, 1)
        # (not one whose value is physically impossible: that is no explanation)
        alternatives = [t[0] for t, _ in ranked if t[0] is not c and t[0] not in same
                        and t[0].family != c.family and (gain - t[1]) / s2 < ALTERNATIVE_LR
                        and not _unresolved(t, Q, y_perp, n_rows, yard)
                        and plausible(t[0], fitted(y, M, t[0])[0])]
        periodogram = {}
        if c.effect == "gear_transmission_error":
            periodogram = {t[0].periods: round(t[1] / rss0, 4) for t in tests
                           if t[0].effect == c.effect and t[0].joint == c.joint and rss0 > 0}
        Qc = orth(project_out(Q, c.columns))
        P -= Qc @ (Qc.T @ P)
        sel.chosen.append(c)
        sel.unresolved.pop(c.key, None)
        sel.refused.pop(c.key, None)     # possible after all, with the model grown
        sel.steps.append(StepStats(
            p_value=float(p), family=len(tests), r=float(np.sqrt(gain / rss0)) if rss0 > 0 else 0.0,
            identifiability=residual_ratio(Q, c.columns),
            structure_share=(cgain / sgain) if sgain > 0 else 1.0,
            alternatives=alternatives, same=same, periodogram=periodogram))
        cur_cv = new_cv
    return sel


def significance_in(y, base: Baseline, chosen: list[Candidate], c: Candidate, extra: list,
                    n_rows: int) -> float:
    """p-value of ``c`` in the model of the other findings (and ``extra`` columns)."""
    others = model(base, [d for d in chosen if d is not c], extra)
    Qo = orth(others)
    _, p, _ = f_test(project_out(Qo, y), Qo.shape[1], project_out(Qo, normalise(c.columns)), n_rows)
    return p


def backward(y, base: Baseline, sel: Selection, alpha: float = ALPHA) -> Selection:
    """Drop findings no longer significant (alpha / #findings) in the full model, and refuse
    any whose value in the full model is no longer physically possible (``plausible``)."""
    chosen, steps, refused = list(sel.chosen), list(sel.steps), dict(sel.refused)
    while chosen:
        beta, cov, _, _ = fit_linear(y, model(base, chosen))
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        col, bad = base.B.shape[1], None
        for i, c in enumerate(chosen):
            k = c.columns.shape[1]
            if not plausible(c, beta[col:col + k]):
                bad = (i, beta[col:col + k], std[col:col + k])
            col += k
        if bad is not None:
            i, b, s = bad
            step = sel.chosen.index(chosen[i]) + 1  # its selection step (i: in the shrunk list)
            refused.setdefault(chosen[i].key, Refused(chosen[i], b, s, step, None, True))
            del chosen[i], steps[i]
            continue
        ps = [significance_in(y, base, chosen, c, [], y.size) for c in chosen]
        worst = int(np.argmax(ps))
        if ps[worst] * len(chosen) < alpha:
            break
        del chosen[worst], steps[worst]
    return Selection(chosen, steps, sel.unresolved, refused)
