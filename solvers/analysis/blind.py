"""The yardstick: a blind recalibration of every identifiable DH parameter.

All four DH parameters of every row (a, d, alpha, joint offset) are offered at once; those
the baseline does not absorb and that are not combinations of the others (pivoted QR on
the regressors projected out of the baseline, relative tolerance 1e-3) are fitted together
with the baseline. Same linearisation and cross-validation as :func:`analyze`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from solvers.analysis.baseline import fit_baseline
from solvers.analysis.blas import single_thread
from solvers.analysis.effects import build_library
from solvers.analysis.selection import CV, fit_linear, normalise, orth, project_out

DH_EFFECTS = ("joint_offset", "link_length", "link_twist")


def blind_dh(rec, *, folds: int = 5, seed: int = 0, rtol: float = 1e-3) -> dict:
    """Fit every identifiable DH parameter blindly.

    Returns
    -------
    dict
        ``n_parameters`` (DH parameters kept + the baseline's), ``dh_parameters`` (names),
        ``rms_mm``, ``heldout_rms_mm``.
    """
    with single_thread():
        base = fit_baseline(rec)
        y = -base.g
        lib = build_library(rec, base, torques_nm=np.zeros(rec.joints_deg.shape))
        dh = [c for c in lib.candidates if c.effect in DH_EFFECTS]
        X = np.hstack([c.columns for c in dh])
        QB = orth(base.B)
        Xp = normalise(project_out(QB, normalise(X)))
        _, R, piv = sla.qr(Xp, mode="economic", pivoting=True)
        d = np.abs(np.diag(R))
        keep = piv[d > rtol * d[0]]
        M = np.hstack([base.B, X[:, keep]])
        cv = CV.make(rec.n_samples, base.m, folds, seed)
        cv.scale = base.row_scale
        beta = fit_linear(y, M)[0]
        rss = float(np.sum(((y - M @ beta) * base.row_scale) ** 2))
        return {"n_parameters": int(M.shape[1]), "dh_parameters": [dh[i].key for i in sorted(keep)],
                "rms_mm": float(np.sqrt(rss / rec.n_samples)),
                "heldout_rms_mm": cv.heldout_rms(y, M)}
