"""Identifiability of the rigid model's parameters, checked before anything is fitted.

The rigid fit of a recording (``baseline.py``) has free parameters in groups (a tracker's
instrument frame and TCP, a touch's TCP and fixed point, a beam's TCP and tool axis). The
Jacobian ``J`` of the residual with respect to them, evaluated at the nominal start, tells
which of them the poses determine at all: with unit columns, a right singular vector whose
singular value is below ``IDENT_TOL`` times the largest is a combination of parameters the
data cannot see (Khalil & Dombre, *Modeling, Identification and Control of Robots*, 2002,
ch. 11: the base parameters are those of the regular part of the identification Jacobian).

The classic case: a path that keeps the tool orientation constant. Every sample's TCP is then
``R (p_flange,k + R_flange p_tcp) + t`` with ``R_flange`` the same for every k, so only
``R R_flange p_tcp + t`` is measured: the TCP on the flange and the instrument's position trade
off exactly. A fit left free along such a combination settles anywhere (a tool point 320 m
from the flange); here those directions are pinned at the nominal values (the recording's
tool) and the parameters involved are named as not identifiable and left out of the report,
with the poses that would determine them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.validate import FloatArray

IDENT_TOL = 3e-3     # relative singular value below which a direction is not determined
INVOLVED = 0.1       # share of a parameter in the undetermined directions that drops it


@dataclass
class Identifiability:
    """The split of a rigid model's parameters into determined and undetermined directions.

    ``basis`` (p, r): the determined directions in parameter space (the fit moves only
    along them, from the nominal start); ``involved``: names of the parameters with a share
    above ``INVOLVED`` in an undetermined direction (not reported).
    """

    basis: FloatArray
    names: list[str]
    involved: list[str] = field(default_factory=list)
    groups: list[dict] = field(default_factory=list)
    null_vectors: list[dict] = field(default_factory=list)
    singular_ratio: float = 1.0

    @property
    def full(self) -> bool:
        return not self.null_vectors


def analyse(J: FloatArray, names: list[str], groups: dict[str, slice],
            tol: float = IDENT_TOL) -> Identifiability:
    """Rank and conditioning of ``J`` (rows, p), per group and as a whole (module docstring)."""
    p = J.shape[1]
    norms = np.linalg.norm(J, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    G = (J.T @ J) / np.outer(norms, norms)         # Gram matrix of the unit columns
    w, V = np.linalg.eigh(G)
    s, Vt = np.sqrt(np.maximum(w[::-1], 0.0)), V[:, ::-1].T
    rel = s / max(s[0], 1e-300)
    keep = rel >= tol
    basis = (Vt[keep].T) / norms[:, None]          # physical parameter directions
    null = Vt[~keep]
    share = np.sum(null ** 2, axis=0) if null.size else np.zeros(p)
    involved = [n for n, v in zip(names, share) if v > INVOLVED]
    out_groups = []
    for gname, sl in groups.items():
        g = np.arange(p)[sl]
        o = np.delete(np.arange(p), g)
        Ggg = G[np.ix_(g, g)]
        sg = np.sqrt(np.maximum(np.linalg.eigvalsh(Ggg)[::-1], 0.0))
        # the group's columns outside span(others): the Schur complement of the others
        if o.size:
            Goo, Ggo = G[np.ix_(o, o)], G[np.ix_(g, o)]
            S = Ggg - Ggo @ np.linalg.pinv(Goo, rcond=1e-12) @ Ggo.T
        else:
            S = Ggg
        sp = np.sqrt(np.maximum(np.linalg.eigvalsh(S)[::-1], 0.0))
        out_groups.append({
            "group": gname, "parameters": names[sl], "n": int(sg.size),
            "rank": int(np.sum(sg >= tol * max(sg[0], 1e-300))),
            "rank_given_others": int(np.sum(sp >= tol)),
            "condition": float(sg[0] / sg[-1]) if sg[-1] > 1e-12 else None,
            "smallest_relative_singular_value_given_others": round(float(sp[-1]), 6)})
    nulls = []
    for v in null:
        v = v / np.linalg.norm(v)
        big = np.argsort(-np.abs(v))
        nulls.append({"parameters": {names[i]: round(float(v[i]), 4) for i in big
                                     if abs(v[i]) > 0.05}})
    return Identifiability(basis, list(names), involved, out_groups, nulls,
                           float(rel[-1]))


def orientation_spread_deg(R: FloatArray) -> float:
    """Largest angle (deg) between any sample's tool orientation and their mean."""
    rot = Rotation.from_matrix(R)
    mean = rot.mean()
    return float(np.degrees(np.max((mean.inv() * rot).magnitude())))


def tcp_null_directions(ident: Identifiability, tcp_names: list[str]) -> list[list[float]]:
    """Unit directions (flange frame) of the TCP that the poses do not determine."""
    idx = [ident.names.index(n) for n in tcp_names if n in ident.names]
    out = []
    for nv in ident.null_vectors:
        v = np.array([nv["parameters"].get(ident.names[i], 0.0) for i in idx])
        if np.linalg.norm(v) > 0.2:
            out.append([round(float(x), 3) for x in v / np.linalg.norm(v)])
    return out


def report_block(ident: Identifiability, kind: str, R_flange: FloatArray | None) -> dict:
    """The report's ``identifiability`` block: per group, and what is not determined."""
    block: dict = {"tolerance": IDENT_TOL, "groups": ident.groups,
                   "smallest_relative_singular_value": round(ident.singular_ratio, 8),
                   "not_identifiable": []}
    if ident.full:
        return block
    spread = orientation_spread_deg(R_flange) if R_flange is not None else None
    tcp = [n for n in ident.names if n.startswith("tcp_")]
    dirs = tcp_null_directions(ident, tcp)
    what = ("the tool point on the flange" + (f" along {len(dirs)} direction(s) " + ", ".join(
        str(d) for d in dirs) + " of the flange frame" if dirs and len(dirs) < 3 else ""))
    if kind == "tracker":
        partner = "the instrument's position"
    elif kind == "touch":
        partner = "the touched point"
    else:
        partner = "the other rigid parameters"
    why = (f"the tool orientation varies by only {spread:.2g} deg over these poses, so only "
           f"where the TCP ends up is measured, not where it sits on the flange"
           if spread is not None and spread < 5.0 else
           "the poses do not turn the tool enough about the needed axes")
    poses = ("poses that turn the tool about at least two different axes by 20 deg or more "
             "(e.g. a few samples of the path repeated with the tool tilted), or a 6-DoF "
             "probe that also measures the orientation"
             if not dirs or len(dirs) > 1 else
             f"poses that turn the tool about an axis across {dirs[0]} (flange frame) by 20 "
             f"deg or more")
    block["not_identifiable"].append({
        "parameters": ident.involved,
        "combinations": ident.null_vectors,
        "reason": f"{what} and {partner} trade off exactly: {why}. These parameters are held "
                  f"at the recording's nominal values along the undetermined directions and "
                  f"not reported",
        "poses_that_would_determine_it": poses})
    return block
