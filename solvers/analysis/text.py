"""Plain words: finding explanations, why an effect cannot be seen, and ``render_text``."""

from __future__ import annotations

WHAT = {
    "joint_offset": "the zero of joint {j} is off",
    "link_length": "the DH length {p}{j} differs from the nominal table",
    "link_twist": "axis {j} is tilted against the nominal table (DH alpha{j})",
    "joint_compliance": "joint {j} yields under gravity",
    "backlash": "joint {j} has lost motion (backlash)",
    "thermal_drift": "the arm or the cell drifts over time (a warm-up)",
    "gear_transmission_error": "joint {j}'s gear carries a periodic transmission error",
    "trigger_latency": "the trigger is recorded late, along the motion",
    "tool_deflection": "the tool bends under the payload's weight",
}


# parameter -> (its std's key, format of "value (± std)") for the plain-words value
_VALUE_FORMATS = (
    ("offset_deg", "offset_deg_std", "{v:+.4f} deg (± {s:.4f})"),
    ("delta_mm", "delta_mm_std", "{v:+.3f} mm (± {s:.3f})"),
    ("delta_alpha_deg", "delta_alpha_deg_std", "{v:+.4f} deg (± {s:.4f})"),
    ("compliance_deg_per_Nm", "compliance_deg_per_Nm_std", "{v:.3g} deg/Nm (± {s:.2g})"),
    ("backlash_deg", "backlash_std_deg", "{v:.4f} deg (± {s:.4f})"),
    ("drift_mm", "drift_std_mm", "{v:.3f} mm over the recording (± {s:.3f})"),
    ("amplitude_deg", "amplitude_std_deg", "{v:.4f} deg (± {s:.4f})"),
    ("latency_ms", "latency_ms_std", "{v:+.2f} ms (± {s:.2f})"),
    ("deflection_mm_per_N", "deflection_mm_per_N_std", "{v:.4g} mm/N (± {s:.2g})"),
)


def _value(f: dict) -> str:
    p = f["parameters"]
    for key, std, fmt in _VALUE_FORMATS:
        if key in p:
            return fmt.format(v=p[key], s=p[std])
    return ""


def _minutes(s: float) -> str:
    return f"{s / 60:.0f} min" if s >= 600 else f"{s:.0f} s"


def _warmup(p: dict, ev: dict) -> str:
    """How the drift goes over time, and whether the recording separates its tau."""
    lo, hi = ev.get("tau_range_s", [None, None])
    span = _minutes(ev.get("span_s", 0.0))
    direction = ", ".join(f"{v:+.2f}" for v in p["direction"])
    text = f" Direction ({direction}) in the instrument's frame;"
    if p.get("tau_s") is None:
        text += " the drift is linear in time"
    else:
        text += f" a first-order warm-up with tau = {_minutes(p['tau_s'])}"
    if ev.get("tau_separable"):
        return text + f" (95% interval {_minutes(lo)}..{_minutes(hi)})."
    if hi is None and lo is not None:
        return text + (f"; the recording's span ({span}) cannot separate tau from a slower "
                       f"warm-up or a linear drift: any tau above {_minutes(lo)} fits as well.")
    if lo is None and hi is not None:
        return text + (f"; the recording's span ({span}) cannot resolve tau below "
                       f"{_minutes(hi)}: the warm-up is as good as a step between samples.")
    return text + f"; the recording's span ({span}) cannot separate tau at all."


def explanation(c, f: dict, same: list[str] | None = None,
                alternatives: list[str] | None = None) -> str:
    ev = f["evidence"]
    j = c.joint if c.joint is not None else ""
    what = WHAT.get(c.effect, c.effect).format(j=j, p=c.dh_parameter or "")
    if c.periods:
        what += f", {c.periods} period{'s' if c.periods > 1 else ''} per turn"
    grows = (f"the residual grows with {c.regressor} (r = {ev['correlation_r']:.2f})"
             if c.regressor != "a constant" else
             f"the residual follows this parameter's pose signature (r = {ev['correlation_r']:.2f})")
    text = (f"{what}: {grows}; modelled as {_value(f)}; held-out RMS "
            f"{ev['heldout_rms_before_mm']:.3f} → {f['heldout_rms_mm']:.3f} mm "
            f"(p = {ev['p_value']:.1e} among {ev['candidates_tested']} candidates).")
    p = f["parameters"]
    if c.effect == "gear_transmission_error":
        text += f" Phase {p['phase_deg']:+.0f} deg (amplitude · sin({c.periods} q{j} + phase))."
    if c.effect == "thermal_drift":
        text += _warmup(p, ev)
    masses = ev.get("gravity_masses") or ""
    if c.effect == "joint_compliance" and masses and not masses.startswith(("Universal Robots",)):
        text += (f" The gravity torque uses {'a generic' if 'generic' in masses else 'an estimated'}"
                 f" mass model of the arm ({masses}): the compliance's scale is only as good "
                 f"as that; give the arm's masses in the recording for a value that carries "
                 f"over.")
    share = ev.get("angle_term_share", 0.0)
    if share > 0.9:
        text += (f" Caution: {100 * share:.0f}% of this signature is also that of a smooth error of "
                 f"joint {j}'s own angle (a cos q{j}-like term, e.g. a gear error); a second "
                 "payload separates the two.")
    if same:
        text += (" This recording cannot tell it from " + ", ".join(same)
                 + ": their effects on these poses are the same.")
    if alternatives:
        text += (" Almost as good an explanation here: " + ", ".join(alternatives)
                 + " (more varied poses would separate them).")
    if "stands_in_for" in ev:
        text += (f" It may partly stand in for structure no candidate explains "
                 f"({ev['stands_in_for']}); kept, since it lowers the held-out error.")
    return text


# the unit of each effect's parameter (its size, ``forward.Refused.size``, and its limit,
# ``screen.PLAUSIBLE``)
UNIT = {"joint_offset": "deg", "link_length": "mm", "link_twist": "deg",
        "joint_compliance": "deg/Nm", "backlash": "deg", "thermal_drift": "mm",
        "gear_transmission_error": "deg", "trigger_latency": "ms", "tool_deflection": "mm/N"}
GROSS = "a wrong robot model, a wrong unit, a broken sensor"


def refused_structure(c, size: float, limit: float) -> str:
    """A refused candidate's name as structure (``locate.unexplained``, ``stands_in_for``)."""
    u = UNIT.get(c.effect, "")
    return f"{c.label}'s signature [best fit {size:.3g} {u}, beyond the possible {limit:g} {u}]"


def refused_reason(c, e: dict) -> str:
    """Why a candidate that fitted best is not named, and what became of its structure."""
    u = UNIT.get(c.effect, "")
    if e.get("dropped"):
        text = (f"chosen at step {e['step']}, but with the later findings its value, "
                f"{e['size']:.3g} {u}, is beyond what it can physically be ({e['limit']:g} {u}): "
                f"dropped")
    else:
        text = (f"fitted the residual best at step {e['step']}"
                + (f" (ahead of {e['preferred_over']}, which was accepted there)"
                   if e.get("preferred_over") else "")
                + f", but at {e['size']:.3g} {u}, beyond what it can physically be "
                  f"({e['limit']:g} {u}): not named")
    if e["remains"]:
        text += (f"; the structure it fits remains after the findings (p = {e['p_value']:.1e}), "
                 f"so it is unexplained: a best fit beyond the possible points at a gross error "
                 f"({GROSS})")
        if e["stood_in_by"]:
            text += "; " + ", ".join(e["stood_in_by"]) + " may only stand in for it"
    else:
        text += (f"; the findings explain what it fitted: what remains of it is not significant "
                 f"(p = {e['p_value']:.1e}, in the final structure test)")
    return text


def refused_summary(entries: list[dict]) -> str:
    """The locate summary's sentence on refused candidates whose structure remains."""
    left = [e for e in entries if e["remains"]]
    u = [UNIT.get(e["effect"], "") for e in left]
    what = "; ".join(f"{e['label']} at {e['size']:.3g} {v}, possible up to {e['limit']:g} {v}"
                     for e, v in zip(left, u))
    those = "those effects" if len(left) > 1 else "that effect"
    return (f"Its best fit is beyond what is physically possible ({what}): rather than "
            f"{those}, a gross error ({GROSS}) is likely, and findings fitted after it may only "
            f"stand in for it.")


def unresolved_reason(c, longer) -> str:
    """Why a gear harmonic that passed its tests is not named (``forward.resolved``)."""
    j, k, kl = c.joint, c.periods, longer.periods
    return (f"explains nothing of joint {j}'s residual beyond what {kl} per turn explains, "
            f"whose period ({360.0 / kl:.3g} deg) is longer than the joint's travel: over the "
            f"travel the data "
            f"show a smooth trend, not a period of {360.0 / k:.3g} deg, so no harmonic is named "
            f"for it; spread joint {j} over more of a turn to tell the periods apart")


def absorber_of(base, c) -> str:
    """Which of the baseline's parameter blocks soaks up the candidate's regressor."""
    from solvers.analysis.selection import orth, residual_ratio

    B = base.B if getattr(base, "B_full", None) is None else base.B_full
    alone = [name for name, sl in base.blocks.items()
             if residual_ratio(orth(B[:, sl]), c.columns) < 3e-3]
    if alone:
        return " or ".join(alone)
    names = list(base.blocks)
    return " and ".join(names) if names else "the rigid model's parameters"


def not_identifiable_reason(rec, c, base=None) -> str:
    """What the rigid model absorbs the effect into, and what data would reveal it."""
    kind = rec.kind
    absorber = absorber_of(base, c) if base is not None else "the rigid model's parameters"
    e, j = c.effect, c.joint
    if e == "trigger_latency":
        return (f"absorbed by {absorber}: the passes ran in one direction at one speed, so a late "
                "trigger looks like a shifted TCP: add reverse passes (and a second speed) to "
                "separate latency from the TCP and beam positions")
    if e == "gear_transmission_error":
        return (f"absorbed by {absorber}: joint {j}'s angle hardly varies over these poses at "
                f"{c.periods} periods per turn: spread joint {j} over at least one period")
    if e == "thermal_drift":
        return (f"absorbed by {absorber}: a static thermal growth is indistinguishable from "
                "link lengths and frames; only its change over time shows it — record longer, "
                "revisiting poses early and late")
    if e == "tool_deflection":
        return (f"absorbed by {absorber}: the payload's weight across the tool axis hardly "
                "changes between the samples: tilt the tool axis through several angles to gravity")
    if e == "backlash":
        return (f"absorbed by {absorber}: joint {j} approached (nearly) every sample from the same "
                "side: approach the poses from both directions")
    if e == "joint_compliance":
        return (f"absorbed by {absorber}: the gravity torque on joint {j} hardly varies over these "
                f"poses: use poses with different loads on joint {j}, or a second payload")
    if e in ("joint_offset", "link_length", "link_twist"):
        what = {"joint_offset": f"joint {j}'s zero", "link_length": f"DH {c.dh_parameter}{j}",
                "link_twist": f"DH alpha{j}"}[e]
        if " or " in absorber:
            hint = ("each of them alone takes it up; only a known tool and a reference on the "
                    "robot's own base show it")
        elif kind == "tracker" and "instrument" in absorber and "TCP" not in absorber:
            hint = ("it moves every measured point rigidly; only a reference on the robot's own "
                    "base (not a free instrument frame) shows it")
        elif absorber == "the fixed point":
            hint = ("it only moves where the touched point seems to be; touching several points "
                    "known in base shows it")
        elif "TCP" in absorber and " and " not in absorber:
            hint = ("it moves the TCP by the same amount in the flange for every pose; only a "
                    "known tool (or a tool measured off the robot) shows it")
        else:
            hint = "measure with more spread in the joint angles to separate it"
        return f"{what} is absorbed by {absorber}: {hint}"
    return f"absorbed by {absorber}"


def render_text(report: dict) -> str:
    """The human form of an analysis report (``pendant analyze`` without ``--json``)."""
    b, fin = report["baseline"], report["final"]
    sp = report.get("split") or {}
    how = (f"{sp.get('folds')}-fold, {sp.get('method')} split"
           + (" (contiguous runs of samples in recorded order)" if sp.get("method") == "blocked"
              else f" (seed {sp.get('seed')})" if "seed" in sp else "")) if sp else ""
    lines = [f"Analysis of a {report['kind']} recording, {report['n_samples']} samples",
             f"Verdict: {report['verdict'].replace('_', ' ')}",
             f"Rigid model: RMS {b['rms_mm']:.3f} mm, held-out {b['heldout_rms_mm']:.3f} mm"
             + (f" (held-out: {how})" if how else ""),
             f"Where: {report['locate']['summary']}"]
    for e in (report.get("identifiability") or {}).get("not_identifiable", []):
        lines.append(f"Not identifiable: {', '.join(e['parameters'])}: {e['reason']}. "
                     f"Would determine it: {e['poses_that_would_determine_it']}.")
    if report["findings"]:
        lines.append("Findings (strongest first):")
        for i, f in enumerate(report["findings"], 1):
            k = f["parameters"].get("periods_per_turn")
            name = (f["effect"] + (f" J{f['joint']}" if f.get("joint") else "")
                    + (f" ({k} per turn)" if k else ""))
            lines.append(f"  {i}. {name}: {f['explanation']}")
    elif report["verdict"] == "unexplained_structure":
        lines.append("Findings: none — structure remains that no candidate effect explains "
                     "(see Where).")
    else:
        lines.append("Findings: none — the residual is consistent with measurement noise.")
    lines.append(f"With the findings: RMS {fin['rms_mm']:.3f} mm, held-out "
                 f"{fin['heldout_rms_mm']:.3f} mm")
    for w in report.get("stand_ins") or []:
        name = w["effect"] + (f" J{w['joint']}" if w.get("joint") else "")
        lines.append(f"Stand-in: {name} may partly stand in for {w['stands_in_for']} "
                     "(kept: it lowers the held-out error).")
    for e in report.get("refused_as_implausible") or []:
        name = e["effect"] + (f" J{e['joint']}" if e.get("joint") else "") + (
            f" ({e['periods_per_turn']} per turn)" if e.get("periods_per_turn") else "")
        lines.append(f"Refused as physically impossible: {name}: {e['reason']}.")
    for c in report.get("checks") or []:
        if not c["passed"]:
            lines.append(f"DEFECT: {c['check']} failed (RMS {c['rms_mm']:.4f} mm, held-out "
                         f"{c['heldout_rms_mm']:.4f} mm): these figures are not to be trusted.")
    ni = report.get("not_identifiable") or []
    if ni:
        lines.append("Not identifiable from this recording:")
        seen = set()
        for e in ni:
            k = e.get("periods_per_turn")
            per = "" if k is None else (f", {k} per turn" if isinstance(k, int) else
                                        f", {min(k)}-{max(k)} per turn")
            name = e["effect"] + (f" J{e['joint']}" if e.get("joint") else "") + (
                f" ({e['dh_parameter']})" if e.get("dh_parameter") else "") + per
            if name in seen:
                continue
            seen.add(name)
            lines.append(f"  - {name}: {e['reason']}")
    return "\n".join(lines)
