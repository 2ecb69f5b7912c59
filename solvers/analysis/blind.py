"""The yardstick: a blind recalibration of every identifiable DH parameter.

All four DH parameters of every row (a, d, alpha, joint offset) are offered at once. Those
the baseline absorbs, and those that are combinations of the others, are left out: pivoted
QR of the unit regressors projected out of the baseline's span, a column kept only where its
new direction is at least ``IDENT_TOL`` long (the analysis's identifiability tolerance; the
projected columns are not normalised again, which once counted the J1 offset, d1 and the J6
row, absorbed by the instrument frame and the TCP, as parameters). The kept parameters are
then fitted with the same nonlinear model fit and the same held-out refits per fold as the
analysis's findings (``model.py``), under the same split.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from solvers.analysis.baseline import fit_baseline
from solvers.analysis.blas import single_thread
from solvers.analysis.effects import build_library
from solvers.analysis.model import Effect, Fit, Prepared, fit, heldout
from solvers.analysis.screen import IDENT_TOL
from solvers.analysis.selection import CV, default_split, normalise, orth, project_out

DH_EFFECTS = ("joint_offset", "link_length", "link_twist")


def blind_dh(rec, *, folds: int = 5, seed: int = 0, split: str | None = None,
             rtol: float = IDENT_TOL) -> dict:
    """Fit every identifiable DH parameter blindly.

    Returns
    -------
    dict
        ``n_parameters`` (identifiable DH parameters kept + the baseline's identifiable
        ones), ``dh_parameters`` (names), ``rms_mm``, ``heldout_rms_mm``, ``split``, and
        ``beta`` / ``prepared`` / ``fit`` (the fitted model, for ``predict``).
    """
    with single_thread():
        base = fit_baseline(rec)
        lib = build_library(rec, base, torques_nm=np.zeros(rec.joints_deg.shape))
        dh = [c for c in lib.candidates if c.effect in DH_EFFECTS]
        X = np.hstack([c.columns for c in dh])
        QB = orth(base.B)
        Xp = project_out(QB, normalise(X))
        _, R, piv = sla.qr(Xp, mode="economic", pivoting=True)
        d = np.abs(np.diag(R))
        keep = sorted(piv[:len(d)][d > rtol])
        split = default_split(rec.t_s, rec.kind) if split is None else split
        cv = CV.make(rec.n_samples, base.m, folds, seed, split)
        prep = Prepared.make(rec, [Effect.of(dh[i]) for i in keep])
        f: Fit = fit(prep)
        n_base = base.ident.basis.shape[1] if base.ident is not None else base.B.shape[1]
        return {"n_parameters": int(n_base + len(keep)),
                "dh_parameters": [dh[i].key for i in keep],
                "rms_mm": f.rms_mm, "heldout_rms_mm": heldout(prep, cv, f), "split": split,
                "prepared": prep, "fit": f}
