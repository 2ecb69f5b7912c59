"""``analyze``: rigid baseline, locate, candidate effects, forward selection, verdict.

Returns the ``analysis-report/1`` document (a dict ready for JSON); see docs/analysis.md.

Steps:

1. Fit the kind's rigid baseline (``baseline.py``); its residual ``y = -g`` is, to first
   order, ``B db + sum_e X_e beta_e + noise``.
2. Build every candidate's regressor ``X_e`` (``effects.py``); a candidate whose regressor is
   (almost) inside span(B) is *not identifiable* from this recording and is listed with what
   data would reveal it.
3. Forward selection: at each step every identifiable candidate is F-tested against the
   current model (Holm over the candidates of the step); the strongest that passes is added
   if it also lowers the K-fold held-out RMS and explains at least a share of what the
   generic smooth-function groups (``locate.structure_groups``) could explain.
4. Backward check: a finding no longer significant in the final model is dropped.
5. Structure test of the final residual (Holm over the structure groups). If structure
   remains, findings that only stand in for it (lose significance, or change by more than
   half, when the significant groups are added) are withheld; the verdict is
   ``unexplained_structure`` and ``locate`` says what the structure varies with.
"""

from __future__ import annotations

import numpy as np

from solvers.analysis.baseline import Baseline, fit_baseline, per_sample_rms, rms_mm
from solvers.analysis.blas import single_thread
from solvers.analysis.effects import Candidate, build_library
from solvers.analysis.kinematics import State
from solvers.analysis.locate import (correlations, features, joint_angle_terms, locate,
                                     structure_groups)
from solvers.analysis.selection import (CV, f_test, fit_linear, holm_pass, identifiable_part,
                                        normalise, orth, project_out, residual_ratio)
from solvers.analysis.text import explanation, not_identifiable_reason
from solvers.errors import CalibrationError
from solvers.recording import MIN_SAMPLES

FORMAT = "analysis-report/1"
IDENT_TOL = 3e-3        # relative residual of a regressor outside the model's span
ALPHA = 1e-3            # family-wise level of each selection step (Holm)
ALPHA_STRUCTURE = 1e-4  # family-wise level of the final structure test (Holm)
GUARD_FRACTION = 0.05  # a named effect must explain this share of the structure found
MIN_CV_GAIN = 0.002     # relative held-out RMS improvement an effect must bring
SAME_COS = 0.999        # |cos| between projected regressors: indistinguishable effects
# a large but possible value of each effect's parameter; an effect that would change the
# samples by less than VISIBLE_MM RMS even at this value is invisible in the recording
PLAUSIBLE = {"joint_offset": 1.0, "link_length": 2.0, "link_twist": 1.0,
             "joint_compliance": 5e-3, "backlash": 0.5, "thermal_drift": 1.0,
             "trigger_latency": 20.0, "tool_deflection": 0.01}
VISIBLE_MM = 1e-3
PRIORITY = ("joint_offset", "joint_compliance", "backlash", "link_length", "link_twist",
            "thermal_drift", "trigger_latency", "tool_deflection")
ALTERNATIVE_LR = 4.0    # RSS difference / sigma^2 under which another candidate is as good
MAX_RELINEARISE = 3     # re-linearisations at the fitted effects (nonlinear refinement)


def _model(base: Baseline, chosen: list[Candidate], extra: list | None = None) -> np.ndarray:
    return np.hstack([base.B] + [c.columns for c in chosen] + (extra or []))


def _group_gains(y_perp, Q, groups, n_rows):
    """(name, gain, p, k) of each structure group; only its identifiable directions count."""
    out = []
    for name, cols in groups:
        Xp = identifiable_part(Q, cols, IDENT_TOL)
        gain, p, k = f_test(y_perp, Q.shape[1], Xp, n_rows)
        out.append((name, gain, p, k))
    return out


def structure_test(y, Q, groups, n_rows, alpha=ALPHA_STRUCTURE):
    """Holm test of every structure group on the residual outside span(Q): (name, p, gain)."""
    res = _group_gains(project_out(Q, y), Q, groups, n_rows)
    ok = holm_pass([r[2] for r in res], alpha) if res else []
    return sorted([(r[0], r[2], r[1]) for r, o in zip(res, ok) if o], key=lambda t: t[1])


def _forward(y, base, cands, cv, groups, alpha, max_findings):
    """Forward selection; returns chosen candidates and per-step statistics."""
    n_rows = y.size
    chosen: list[Candidate] = []
    steps: list[dict] = []
    cur_cv = cv.heldout_rms(y, base.B)
    while len(chosen) < max_findings:
        M = _model(base, chosen)
        Q = orth(M)
        y_perp = project_out(Q, y)
        rss0 = float(y_perp @ y_perp)
        sigma2 = rss0 / max(n_rows - Q.shape[1], 1)
        tests = []
        for c in cands:
            if c in chosen or residual_ratio(Q, c.columns) < IDENT_TOL:
                continue
            Xp = project_out(Q, normalise(c.columns))
            gain, p, k = f_test(y_perp, Q.shape[1], Xp, n_rows)
            tests.append((c, gain, p, k, Xp))
        if not tests:
            break
        passed = holm_pass([t[2] for t in tests], alpha)
        order = sorted([t for t, ok in zip(tests, passed) if ok], key=lambda t: -t[1])
        if not order:
            break
        gg = _group_gains(y_perp, Q, groups, n_rows)
        sgain = max([g - k * sigma2 for _, g, _, k in gg], default=0.0)
        accepted = None
        for c, gain, p, k, Xp in order[:8]:
            cgain = gain - k * sigma2
            if sgain > 0 and cgain < GUARD_FRACTION * sgain:
                continue
            new_cv = cv.heldout_rms(y, np.hstack([M, c.columns]))
            if new_cv < cur_cv * (1.0 - MIN_CV_GAIN):
                accepted = (c, gain, p, k, Xp, new_cv, cgain)
                break
        if accepted is None:
            break
        c, gain, p, k, Xp, new_cv, cgain = accepted
        same = []
        if k == 1:
            xa = Xp[:, 0] / max(np.linalg.norm(Xp[:, 0]), 1e-300)
            for t in tests:
                if t[0] is not c and t[4].shape[1] == 1:
                    xb = t[4][:, 0] / max(np.linalg.norm(t[4][:, 0]), 1e-300)
                    if abs(float(xa @ xb)) > SAME_COS:
                        same.append(t[0])
        if same:
            # indistinguishable on these poses: name the one physics expects first
            group = sorted([c] + same, key=lambda d: (PRIORITY.index(d.effect), d.joint or 0))
            if group[0] is not c:
                c, same = group[0], [d for d in group if d is not group[0]]
        # other candidates that explain almost as much (likelihood-ratio difference < 4, i.e.
        # about two standard errors): this recording cannot tell them apart with confidence
        s2 = max(rss0 - gain, 1e-300) / max(n_rows - Q.shape[1] - k, 1)
        alternatives = [t[0] for t in order if t[0] is not c and t[0] not in same
                        and (gain - t[1]) / s2 < ALTERNATIVE_LR]
        chosen.append(c)
        steps.append({"p_value": p, "family": len(tests), "alternatives": alternatives,
                      "r": float(np.sqrt(gain / rss0)) if rss0 > 0 else 0.0,
                      "identifiability": residual_ratio(Q, c.columns),
                      "structure_share": (cgain / sgain) if sgain > 0 else 1.0,
                      "same": same})
        cur_cv = new_cv
    return chosen, steps


def _backward(y, base, chosen, steps, alpha):
    """Drop findings no longer significant (Holm-style, alpha / #findings) in the full model."""
    chosen, steps = list(chosen), list(steps)
    while chosen:
        ps = [_significance_in(y, base, chosen, c, [], y.size) for c in chosen]
        worst = int(np.argmax(ps))
        if ps[worst] * len(chosen) < alpha:
            break
        del chosen[worst], steps[worst]
    return chosen, steps


def _significance_in(y, base, chosen, c, extra, n_rows):
    others = _model(base, [d for d in chosen if d is not c], extra)
    Qo = orth(others)
    _, p, _ = f_test(project_out(Qo, y), Qo.shape[1], project_out(Qo, normalise(c.columns)), n_rows)
    return p


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
        The ``analysis-report/1`` document (plus ``not_identifiable`` and ``withheld``).

    Raises
    ------
    CalibrationError
        Too few samples for the kind's baseline and a cross-validation.
    """
    N = rec.n_samples
    need = MIN_SAMPLES.get(rec.kind, 4) + 2
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

    cands: list[Candidate] = []
    not_ident: list[dict] = []
    for c in lib.candidates:
        if not np.any(c.columns):
            continue
        ratio = residual_ratio(QB, c.columns)
        size = float(np.sqrt(np.sum((c.columns * PLAUSIBLE[c.effect] * base.row_scale[:, None]) ** 2)
                             / N))
        if size < VISIBLE_MM:
            not_ident.append({"effect": c.effect, "joint": c.joint,
                              **({"dh_parameter": c.dh_parameter} if c.dh_parameter else {}),
                              "relative_residual": round(ratio, 6),
                              "reason": f"invisible in this recording: even {c.param} = "
                                        f"{PLAUSIBLE[c.effect]:g} would change the samples by "
                                        f"only {size:.2g} mm RMS"})
        elif ratio < IDENT_TOL:
            not_ident.append({"effect": c.effect, "joint": c.joint,
                              **({"dh_parameter": c.dh_parameter} if c.dh_parameter else {}),
                              "relative_residual": round(ratio, 6),
                              "reason": not_identifiable_reason(rec, c, base)})
        else:
            cands.append(c)

    chosen, steps = _forward(y, base, cands, cv, groups, alpha, max_findings)
    chosen, steps = _backward(y, base, chosen, steps, alpha)
    rigid_parameters = dict(base.parameters)

    # nonlinear refinement: re-linearise at the fitted effects (the effects applied to the
    # kinematics, the baseline refitted) and select again, until the selection is stable
    for _ in range(MAX_RELINEARISE):
        if not chosen:
            break
        keys = [c.key for c in chosen]
        beta = fit_linear(y, _model(base, chosen))[0]
        state = State.zero(N, rec.joints_deg.shape[1])
        col = base.B.shape[1]
        betas = {}
        for c in chosen:
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
        chosen, steps = _forward(y, base, cands, cv, groups, alpha, max_findings)
        chosen, steps = _backward(y, base, chosen, steps, alpha)
        if [c.key for c in chosen] == keys:
            break
    feats = features(rec, base, lib.torques_nm, lib.signs)

    # structure left over; withdraw findings that only stand in for it
    withheld: list[dict] = []
    for _ in range(3):
        Q = orth(_model(base, chosen))
        sig = structure_test(y, Q, groups, n_rows)
        if not (sig and chosen):
            break
        names = {sig[0][0]}    # the strongest unexplained structure
        S = [cols for name, cols in groups if name in names]
        b_old = fit_linear(y, _model(base, chosen))[0]
        b_new = fit_linear(y, _model(base, chosen, S))[0]
        keep, col = [], base.B.shape[1]
        for i, c in enumerate(chosen):
            k = c.columns.shape[1]
            bo, bn = b_old[col:col + k], b_new[col:col + k]
            col += k
            change = float(np.linalg.norm(bn - bo) / max(np.linalg.norm(bo), 1e-300))
            p = _significance_in(y, base, chosen, c, S, n_rows)
            if p * len(chosen) < alpha and change < 0.5:
                keep.append(i)
            else:
                withheld.append({"effect": c.effect, "joint": c.joint,
                                 **({"dh_parameter": c.dh_parameter} if c.dh_parameter else {}),
                                 "p_value_with_structure": float(p),
                                 "relative_change": round(change, 3),
                                 "reason": "it only stands in for structure that no candidate "
                                           "explains (" + ", ".join(sorted(names)) + ")"})
        if len(keep) == len(chosen):
            break
        chosen = [chosen[i] for i in keep]
        steps = [steps[i] for i in keep]

    # cumulative figures of the kept findings, in order, and the final fit
    findings = []
    prev_cv = base_cv
    for i, (c, st) in enumerate(zip(chosen, steps)):
        Mi = _model(base, chosen[:i + 1])
        bi = fit_linear(y, Mi)[0]
        rssi = float(np.sum(((y - Mi @ bi) * base.row_scale) ** 2))
        hi = cv.heldout_rms(y, Mi)
        findings.append({"c": c, "st": st, "rms": float(np.sqrt(rssi / N)), "heldout": hi,
                         "before": prev_cv})
        prev_cv = hi
    M = _model(base, chosen)
    beta, cov, _, rank = fit_linear(y, M)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    rss_mm = float(np.sum(((y - M @ beta) * base.row_scale) ** 2))
    Q = orth(M)
    final_cv = cv.heldout_rms(y, M, Q)
    out_findings = []
    col = base.B.shape[1]
    for f in findings:
        c, st = f["c"], f["st"]
        k = c.columns.shape[1]
        b, s = beta[col:col + k], std[col:col + k]
        col += k
        ev = {"p_value": float(st["p_value"]), "candidates_tested": int(st["family"]),
              "correlation_r": round(st["r"], 4),
              "identifiability": round(float(st["identifiability"]), 5),
              "t_value": round(float(np.linalg.norm(b) / max(np.linalg.norm(s), 1e-300)), 2),
              "heldout_rms_before_mm": round(f["before"], 5),
              "structure_share": round(float(min(st["structure_share"], 99.0)), 3)}
        if st["same"]:
            ev["indistinguishable_from"] = [d.key for d in st["same"]]
        if st["alternatives"]:
            ev["alternatives"] = [d.key for d in st["alternatives"]]
        if c.effect == "joint_compliance":
            # how much of its signature a smooth error of the joint's own angle would also give
            grp = [joint_angle_terms(rec, base, c.joint - 1)]
            if grp[0].shape[1]:
                others = orth(np.hstack([_model(base, [d for d in chosen if d is not c])] + grp))
                ev["angle_term_share"] = round(1.0 - residual_ratio(others, c.columns) ** 2, 3)
        entry = {"effect": c.effect, "joint": c.joint,
                 "parameters": c.report_parameters(b, s),
                 "rms_mm": round(f["rms"], 5), "heldout_rms_mm": round(f["heldout"], 5),
                 "evidence": ev}
        entry["explanation"] = explanation(c, entry, [d.label for d in st["same"]],
                                           [d.label for d in st["alternatives"]])
        out_findings.append(entry)

    resid = y - M @ beta
    final_residuals = per_sample_rms(resid * base.row_scale, m)
    sig = structure_test(y, Q, groups, n_rows)
    if sig:
        verdict = "unexplained_structure"
        corr = correlations(project_out(Q, resid), Q, base, feats)
        what = ", ".join(n for n, _, _ in sig[:3])
        strong = ", ".join(f"{n} (r = {r:.2f})" for n, r in corr[:3])
        lead = "After the findings, s" if out_findings else "S"
        locate_block["summary"] += (f" {lead}tructure remains that no candidate effect "
                                    f"explains: it varies with {what}"
                                    + (f"; it correlates most with {strong}." if strong else "."))
        locate_block["unexplained"] = [{"varies_with": n, "p_value": float(p)} for n, p, _ in sig]
    elif out_findings:
        verdict = "explained"
    else:
        verdict = "no_missing_physics"
    sigma_row = float(np.sqrt(rss_mm / max(n_rows - rank, 1)))
    return {
        "format": FORMAT,
        "kind": rec.kind,
        "n_samples": int(N),
        "verdict": verdict,
        "baseline": {"rms_mm": round(base_rms, 5), "heldout_rms_mm": round(base_cv, 5),
                     "parameters": {k: round(v, 6) for k, v in rigid_parameters.items()},
                     "residuals_mm": [round(float(v), 6) for v in base_residuals]},
        "locate": locate_block,
        "findings": out_findings,
        "final": {"rms_mm": round(float(np.sqrt(rss_mm / N)), 5),
                  "heldout_rms_mm": round(final_cv, 5),
                  "noise_mm": round(sigma_row * float(np.sqrt(m)), 5),
                  "n_parameters": int(M.shape[1]),
                  "residuals_mm": [round(float(v), 6) for v in final_residuals]},
        "not_identifiable": not_ident,
        "withheld": withheld,
    }
