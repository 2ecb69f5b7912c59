"""``analyze``: the pipeline from a recording to the ``analysis-report/1`` document.

Returns the document as a dict ready for JSON; see docs/analysis.md. Each step is a module
with its own reference:

0. Fit the kind's rigid baseline (``baseline.py``); its residual ``y = -g`` is, to first
   order, ``B db + sum_e X_e beta_e + noise``; ``locate.py`` says where the mismatch is.
1. *Candidates* (``effects.py``, ``screen.py``): every effect's regressor ``X_e``; a
   candidate invisible in the recording or (almost) inside span(B) is listed as not
   identifiable, with what data would reveal it.
2. *Selection* (``forward.py``): forward selection by the extra-sum-of-squares F-test with
   Holm's control over each step's candidates and a held-out (K-fold) gain, then a backward
   check; re-linearised at the fitted effects until it is stable (``_relinearise``), and a
   thermal finding's time constant profiled (``thermal.py``).
3. *Stand-ins* (``verdict.py``): findings that may only stand in for structure no candidate
   explains are named as such and kept (their held-out gain is real).
4. *Verdict* (``verdict.py``): a Holm-controlled structure test of the final residual.
"""

from __future__ import annotations

import numpy as np

from solvers.analysis.baseline import Baseline, fit_baseline, per_sample_rms, rms_mm
from solvers.analysis.blas import single_thread
from solvers.analysis.effects import Candidate, Library, build_library
from solvers.analysis.forward import ALPHA, Selection, StepStats, backward, forward, model
from solvers.analysis.kinematics import State
from solvers.analysis.locate import (correlations, features, joint_angle_terms, locate,
                                     structure_groups)
from solvers.analysis.screen import screen
from solvers.analysis.selection import CV, fit_linear, orth, project_out, residual_ratio
from solvers.analysis.text import explanation
from solvers.analysis.thermal import TauProfile, profile_tau
from solvers.analysis.verdict import StandIn, stand_ins, structure_test, verdict_of
from solvers.errors import CalibrationError
from solvers.recording import MIN_SAMPLES

FORMAT = "analysis-report/1"
MAX_RELINEARISE = 3     # re-linearisations at the fitted effects (nonlinear refinement)


def analyze(rec, *, folds: int = 5, seed: int = 0, alpha: float = ALPHA,
            max_findings: int = 16, include_twist: bool = True) -> dict:
    """Compare a recording with the rigid model and name the physics it leaves out.

    See :func:`_analyze` (this wrapper runs it on one BLAS thread: faster here).
    """
    with single_thread():
        return _analyze(rec, folds=folds, seed=seed, alpha=alpha, max_findings=max_findings,
                        include_twist=include_twist)


def _analyze(rec, *, folds: int = 5, seed: int = 0, alpha: float = ALPHA,
             max_findings: int = 16, include_twist: bool = True) -> dict:
    """Compare a recording with the rigid model and name the physics it leaves out.

    Parameters
    ----------
    rec : RecordingData
        A parsed ``robot-recording/1`` (``server.recording.parse_recording``).
    folds : int
        K of the K-fold cross-validation by sample.
    seed : int
        Seed of the fold assignment.
    alpha : float
        Family-wise error level of each selection step (Holm).
    max_findings : int
        Stop after this many findings.
    include_twist : bool
        Offer ``link_twist`` (a DH alpha error) as a candidate.

    Returns
    -------
    dict
        The ``analysis-report/1`` document (plus ``not_identifiable`` and ``stand_ins``).

    Raises
    ------
    CalibrationError
        Too few samples for the kind's baseline and a cross-validation.
    """
    N = rec.n_samples
    need = MIN_SAMPLES.get(rec.kind, 4)
    if N < need:
        raise CalibrationError(("samples",), f"{N} samples are too few to analyse; "
                               f"record at least {need}")
    base = fit_baseline(rec)
    m = base.m
    y = -base.g
    n_rows = y.size
    lib = build_library(rec, base, include_twist=include_twist)
    cv = CV.make(N, m, folds, seed)
    groups = structure_groups(rec, base)
    feats = features(rec, base, lib.torques_nm, lib.signs)
    QB = orth(base.B)
    base_rms = rms_mm(base.g_mm, m)
    base_residuals = per_sample_rms(base.g_mm, m)
    cv.scale = base.row_scale
    base_cv = cv.heldout_rms(y, base.B, QB)
    locate_block = locate(rec, base, y, QB, feats)
    rigid_parameters = dict(base.parameters)

    # 1. candidates
    screened = screen(rec, base, QB, lib.candidates)
    # 2. selection, re-linearised at the fitted effects, thermal time constants profiled
    sel = backward(y, base, forward(y, base, screened.candidates, cv, groups, alpha,
                                    max_findings), alpha)
    base, y, lib, sel, groups = _relinearise(rec, base, y, lib, screened.candidates, sel, cv,
                                             alpha, max_findings, include_twist)
    profiles: dict[str, TauProfile] = {}
    for i, c in enumerate(sel.chosen):
        if c.effect == "thermal_drift":
            sel.chosen[i], prof = profile_tau(rec, base, y, sel.chosen, i)
            profiles[sel.chosen[i].key] = prof
    feats = features(rec, base, lib.torques_nm, lib.signs)
    # 3. stand-ins (kept, named)
    standing = {s.key: s for s in stand_ins(y, base, sel.chosen, groups, n_rows, alpha)}
    findings, M, beta, rank = _findings(rec, base, y, cv, sel, base_cv, standing, profiles)

    # 4. verdict
    rss_mm = float(np.sum(((y - M @ beta) * base.row_scale) ** 2))
    Q = orth(M)
    final_cv = cv.heldout_rms(y, M, Q)
    resid = y - M @ beta
    final_residuals = per_sample_rms(resid * base.row_scale, m)
    sig = structure_test(y, Q, groups, n_rows)
    if sig:
        corr = correlations(project_out(Q, resid), Q, base, feats)
        what = ", ".join(n for n, _, _ in sig[:3])
        strong = ", ".join(f"{n} (r = {r:.2f})" for n, r in corr[:3])
        lead = "After the findings, s" if findings else "S"
        locate_block["summary"] += (f" {lead}tructure remains that no candidate effect "
                                    f"explains: it varies with {what}"
                                    + (f"; it correlates most with {strong}." if strong else "."))
        locate_block["unexplained"] = [{"varies_with": n, "p_value": float(p)} for n, p, _ in sig]
    sigma_row = float(np.sqrt(rss_mm / max(n_rows - rank, 1)))
    return {
        "format": FORMAT,
        "kind": rec.kind,
        "n_samples": int(N),
        "verdict": verdict_of(sig, len(findings)),
        "baseline": {"rms_mm": round(base_rms, 5), "heldout_rms_mm": round(base_cv, 5),
                     "parameters": {k: round(v, 6) for k, v in rigid_parameters.items()},
                     "residuals_mm": [round(float(v), 6) for v in base_residuals]},
        "locate": locate_block,
        "findings": findings,
        "final": {"rms_mm": round(float(np.sqrt(rss_mm / N)), 5),
                  "heldout_rms_mm": round(final_cv, 5),
                  "noise_mm": round(sigma_row * float(np.sqrt(m)), 5),
                  "n_parameters": int(M.shape[1]),
                  "residuals_mm": [round(float(v), 6) for v in final_residuals]},
        "not_identifiable": screened.not_identifiable,
        "stand_ins": [{"effect": c.effect, "joint": c.joint, "key": c.key,
                       "stands_in_for": standing[c.key].structure}
                      for c in sel.chosen if c.key in standing],
    }


def _relinearise(rec, base: Baseline, y, lib: Library, cands: list[Candidate], sel: Selection,
                 cv: CV, alpha: float, max_findings: int, include_twist: bool):
    """Nonlinear refinement: apply the fitted effects to the kinematics, refit the baseline,
    rebuild the regressors there and select again, until the selection is stable (a
    Gauss-Newton step on the effects' parameters between selections)."""
    groups = structure_groups(rec, base)
    for _ in range(MAX_RELINEARISE):
        if not sel.chosen:
            break
        keys = sel.keys()
        beta = fit_linear(y, model(base, sel.chosen))[0]
        state = State.zero(rec.n_samples, rec.joints_deg.shape[1])
        col = base.B.shape[1]
        betas = {}
        for c in sel.chosen:
            k = c.columns.shape[1]
            c.apply(state, beta[col:col + k])
            betas[c.key] = beta[col:col + k]
            col += k
        base = fit_baseline(rec, state)
        lib = build_library(rec, base, torques_nm=lib.torques_nm, include_twist=include_twist)
        by_key = {c.key: c for c in lib.candidates}
        # the rigid model's residual, linearised at the fitted effects
        y = -base.g + sum(by_key[k].columns @ b for k, b in betas.items())
        cands = [by_key[c.key] for c in cands]
        groups = structure_groups(rec, base)
        sel = backward(y, base, forward(y, base, cands, cv, groups, alpha, max_findings), alpha)
        if sel.keys() == keys:
            break
    return base, y, lib, sel, groups


def _evidence(rec, base, chosen, c: Candidate, st: StepStats, b, s, before: float,
              stand_in: StandIn | None, prof: TauProfile | None) -> dict:
    ev = {"p_value": float(st.p_value), "candidates_tested": int(st.family),
          "correlation_r": round(st.r, 4),
          "identifiability": round(float(st.identifiability), 5),
          "t_value": round(float(np.linalg.norm(b) / max(np.linalg.norm(s), 1e-300)), 2),
          "heldout_rms_before_mm": round(before, 5),
          "structure_share": round(float(min(st.structure_share, 99.0)), 3)}
    if st.same:
        ev["indistinguishable_from"] = [d.key for d in st.same]
    if st.alternatives:
        ev["alternatives"] = [d.key for d in st.alternatives]
    if st.periodogram:
        ev["periodogram"] = {str(k): v for k, v in sorted(st.periodogram.items())}
    if prof is not None:
        ev["tau_range_s"] = list(prof.range_s)
        ev["tau_separable"] = prof.separable
        ev["span_s"] = prof.span_s
    if stand_in is not None:
        ev["stands_in_for"] = stand_in.structure
        ev["p_value_with_structure"] = stand_in.p_value_with_structure
        ev["relative_change_with_structure"] = stand_in.relative_change
    if c.effect == "joint_compliance":
        # how much of its signature a smooth error of the joint's own angle would also give
        grp = [joint_angle_terms(rec, base, c.joint - 1)]
        if grp[0].shape[1]:
            others = orth(np.hstack([model(base, [d for d in chosen if d is not c])] + grp))
            ev["angle_term_share"] = round(1.0 - residual_ratio(others, c.columns) ** 2, 3)
    return ev


def _findings(rec, base: Baseline, y, cv: CV, sel: Selection, base_cv: float,
              standing: dict[str, StandIn], profiles: dict[str, TauProfile]):
    """The report's findings (cumulative figures, in order) and the final model's fit."""
    N = rec.n_samples
    chosen = sel.chosen
    cumulative, prev_cv = [], base_cv
    for i in range(len(chosen)):
        Mi = model(base, chosen[:i + 1])
        bi = fit_linear(y, Mi)[0]
        rssi = float(np.sum(((y - Mi @ bi) * base.row_scale) ** 2))
        hi = cv.heldout_rms(y, Mi)
        cumulative.append((float(np.sqrt(rssi / N)), hi, prev_cv))
        prev_cv = hi
    M = model(base, chosen)
    beta, cov, _, rank = fit_linear(y, M)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    out, col = [], base.B.shape[1]
    for c, st, (rms_i, held_i, before) in zip(chosen, sel.steps, cumulative):
        k = c.columns.shape[1]
        b, s = beta[col:col + k], std[col:col + k]
        col += k
        entry = {"effect": c.effect, "joint": c.joint,
                 "parameters": c.report_parameters(b, s),
                 "rms_mm": round(rms_i, 5), "heldout_rms_mm": round(held_i, 5),
                 "evidence": _evidence(rec, base, chosen, c, st, b, s, before,
                                       standing.get(c.key), profiles.get(c.key))}
        entry["explanation"] = explanation(c, entry, [d.label for d in st.same],
                                           [d.label for d in st.alternatives])
        out.append(entry)
    return out, M, beta, rank
