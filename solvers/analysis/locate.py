"""Locate the mismatch: which samples, which direction, and what the residual grows with.

Each *feature* is a per-sample scalar the physics could scale with (the gravity torque on a
joint, a joint's angle as sin/cos, the direction a joint last moved in, time, speed, the tool
axis's angle to gravity). Its regressor group is the feature times a TCP displacement along
base x, y and z (through the kind's sensitivity); the correlation ``r`` is the square root of
the fraction of the residual (outside the baseline's span) that the group explains.

The *structure groups* used by the verdict's structure test are smooth functions of each
joint's angle (Fourier terms, as a rotation of that joint and as TCP displacements) and of
time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solvers.analysis.baseline import Baseline, per_sample_rms
from solvers.analysis.selection import f_test, normalise, project_out
from solvers.validate import FloatArray

DEG = np.pi / 180.0


@dataclass
class Feature:
    name: str          # plain words
    values: FloatArray  # (N,)


def _translations(base: Baseline, f: FloatArray) -> FloatArray:
    """Columns S_k e_d f_k for d = x, y, z: (rows, 3)."""
    X = base.S[:, :, :3] * f[:, None, None]
    return X.reshape(-1, 3)


def features(rec, base: Baseline, torques_nm: FloatArray, signs: FloatArray) -> list[Feature]:
    q = rec.joints_deg * DEG
    n = q.shape[1]
    out: list[Feature] = []
    for j in range(n):
        if np.ptp(torques_nm[:, j]) > 1e-9:
            out.append(Feature(f"the gravity torque on joint {j + 1}", torques_nm[:, j]))
    for j in range(n):
        if np.ptp(q[:, j]) > 1e-9:
            out.append(Feature(f"sin(q{j + 1})", np.sin(q[:, j])))
            out.append(Feature(f"cos(q{j + 1})", np.cos(q[:, j])))
    for j in range(n):
        if np.ptp(signs[:, j]) > 0:
            out.append(Feature(f"the direction joint {j + 1} last moved in", signs[:, j]))
    t = np.asarray(rec.t_s, float)
    if np.ptp(t) > 0:
        out.append(Feature("time", t))
    if rec.tcp_velocity_mm_s is not None:
        out.append(Feature("the TCP speed", np.linalg.norm(rec.tcp_velocity_mm_s, axis=1)))
    cosg = -base.sens.axis[:, 2]
    if np.ptp(cosg) > 1e-6:
        out.append(Feature("the tool axis's angle to gravity", np.degrees(np.arccos(np.clip(cosg, -1, 1)))))
    return out


def structure_groups(rec, base: Baseline, harmonics: int = 3, high: int = 12
                     ) -> list[tuple[str, FloatArray]]:
    """(name, columns) groups of smooth functions for the structure test.

    Per joint j: a low-order group (the joint turning by sin/cos(k q_j), k = 1..3, and the TCP
    moving along base x/y/z by sin/cos q_j) and a high-order group (the joint turning by
    sin/cos(k q_j), k = 4..12: periodic errors such as a gear's); plus time (x/y/z by t, t^2).
    """
    q = rec.joints_deg * DEG
    rows = base.S.shape[0] * base.S.shape[1]
    high = int(min(high, max(harmonics, (rows // 8 - 2) // 2)))
    groups: list[tuple[str, FloatArray]] = []

    def turn(j, f):
        return np.einsum("nmi,ni->nm", base.S, base.sens.theta[:, :, j] * f[:, None]).reshape(-1, 1)

    for j in range(q.shape[1]):
        if np.ptp(q[:, j]) < 1e-6:
            continue
        cols = []
        for k in range(1, harmonics + 1):
            cols += [turn(j, np.sin(k * q[:, j])), turn(j, np.cos(k * q[:, j]))]
        for f in (np.sin(q[:, j]), np.cos(q[:, j])):
            cols.append(_translations(base, f))
        groups.append((f"joint {j + 1}'s angle", np.hstack(cols)))
        if high > harmonics:
            cols = []
            for k in range(harmonics + 1, high + 1):
                cols += [turn(j, np.sin(k * q[:, j])), turn(j, np.cos(k * q[:, j]))]
            groups.append((f"joint {j + 1}'s angle (periodic, {harmonics + 1}-{high} per turn)",
                           np.hstack(cols)))
    t = np.asarray(rec.t_s, float)
    if np.ptp(t) > 0:
        f = (t - t.min()) / np.ptp(t)
        groups.append(("time", np.hstack([_translations(base, f), _translations(base, f ** 2)])))
    return groups


def joint_angle_terms(rec, base: Baseline, j: int, harmonics: int = 2) -> FloatArray:
    """Columns of joint j (0-based) turning by sin/cos(k q_j), k = 1..harmonics."""
    q = rec.joints_deg[:, j] * DEG
    if np.ptp(q) < 1e-6:
        return np.zeros((base.g.size, 0))
    tw = base.sens.theta[:, :, j]
    cols = [np.einsum("nmi,ni->nm", base.S, tw * f(k * q)[:, None]).reshape(-1, 1)
            for k in range(1, harmonics + 1) for f in (np.sin, np.cos)]
    return np.hstack(cols)


def correlations(y_perp: FloatArray, Q: FloatArray, base: Baseline, feats: list[Feature]
                 ) -> list[tuple[str, float]]:
    """(feature, r) sorted by r, r = sqrt(explained fraction of the residual outside Q)."""
    tot = float(y_perp @ y_perp)
    out = []
    if tot <= 0:
        return out
    for f in feats:
        v = f.values - f.values.mean()
        if np.ptp(v) == 0:
            continue
        X = project_out(Q, normalise(_translations(base, v)))
        gain, _, _ = f_test(y_perp, Q.shape[1], X, len(y_perp))
        out.append((f.name, float(np.sqrt(max(gain, 0.0) / tot))))
    out.sort(key=lambda t: -t[1])
    return out


def directions(base: Baseline, y: FloatArray) -> list[tuple[str, float]]:
    """Share of the squared residual along base x/y/z and along / across the tool axis."""
    if base.m == 1:
        return []
    r = y.reshape(-1, 3) @ base.R_instrument_base  # instrument -> base (R^T r, row form)
    tot = float(np.sum(r ** 2)) or 1.0
    out = [(f"base {a}", float(np.sum(r[:, i] ** 2) / tot)) for i, a in enumerate("xyz")]
    along = float(np.sum(np.sum(r * base.sens.axis, axis=1) ** 2) / tot)
    out += [("along the tool axis", along), ("across the tool axis", 1.0 - along)]
    return out


def locate(rec, base: Baseline, y: FloatArray, Q: FloatArray, feats: list[Feature],
           n_worst: int = 5) -> dict:
    """The report's ``locate`` block (+ the correlations behind it)."""
    e = per_sample_rms(y * base.row_scale, base.m)
    worst = [int(i) for i in np.argsort(-e)[:n_worst]]
    yp = project_out(Q, y)
    corr = correlations(yp, Q, base, feats)
    dirs = directions(base, y)
    med = float(np.median(e)) if len(e) else 0.0
    words = [f"the largest mismatches are at samples {', '.join(str(i) for i in worst[:3])} "
             f"({e[worst[0]]:.3f} mm; median {med:.3f} mm)"]
    if dirs:
        axes = max(dirs[:3], key=lambda t: t[1])
        tool = max(dirs[3:], key=lambda t: t[1])
        words.append(f"mostly along {axes[0]} ({100 * axes[1]:.0f}% of the squared residual; "
                     f"{100 * tool[1]:.0f}% {tool[0]})")
    else:
        words.append("measured across the beams (a distance per trigger)")
    strong = [c for c in corr if c[1] >= 0.3][:3]
    if strong:
        words.append("it grows with " + ", ".join(f"{n} (r = {r:.2f})" for n, r in strong))
    elif corr:
        words.append(f"it correlates with nothing tried (strongest {corr[0][0]}, r = {corr[0][1]:.2f})")
    summary = "; ".join(words) + "."
    return {"summary": summary[0].upper() + summary[1:], "worst_samples": worst,
            "correlations": [{"feature": n, "r": round(r, 4)} for n, r in corr[:8]],
            "directions": {n: round(v, 4) for n, v in dirs}}
