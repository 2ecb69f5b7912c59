"""Forward model selection on the linearised residual, held-out RMS and the structure test.

The baseline residual ``y = -g`` is (to first order in the small effects) ``y = B db + X beta +
noise``. Everything here is linear algebra on that stack, so a fit, a K-fold refit and an
F-test cost a QR each:

- ``heldout_rms``: K-fold cross-validation by sample (all rows of a sample leave together); the
  baseline parameters are refitted on each training set, as the rigid model would be.
- ``f_test``: the extra-sum-of-squares F-test of a column group against the current model
  (no noise level needed: the residual of the larger model estimates it).
- forward selection: at each step every identifiable candidate is F-tested; the family of
  candidates tried at that step is Holm-corrected; the best passing candidate is added if it
  also lowers the held-out RMS and explains a substantial part of the structure the generic
  smooth-function library finds at that step (the guard against naming an effect outside
  the library).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from solvers.validate import FloatArray


NOISE_FLOOR_MM = 1e-6
FOLD_IDENT_TOL = 3e-3   # identify.IDENT_TOL: a fold's training rows must determine a direction


def normalise(X: FloatArray) -> FloatArray:
    n = np.linalg.norm(X, axis=0)
    return X / np.where(n > 0, n, 1.0)


def orth(X: FloatArray, rtol: float = 1e-9) -> FloatArray:
    """Orthonormal basis of span(X) (columns normalised first; rank by relative tolerance)."""
    if X.shape[1] == 0:
        return np.zeros((X.shape[0], 0))
    Xn = normalise(X)
    if X.shape[1] == 1:
        return Xn if np.any(Xn) else np.zeros((X.shape[0], 0))
    # eigen-decomposition of the small Gram matrix, twice (CholQR2-like) for orthogonality
    w, V = np.linalg.eigh(Xn.T @ Xn)
    if w[-1] <= 0:
        return np.zeros((X.shape[0], 0))
    keep = w > (rtol ** 2) * w[-1]
    Q = Xn @ (V[:, keep] / np.sqrt(w[keep]))
    w2, V2 = np.linalg.eigh(Q.T @ Q)
    # directions the first pass lost to rounding (w2 ~ 0) are dropped, not blown up: dividing
    # by their tiny norms overflowed (the RuntimeWarning of issue 11)
    keep2 = w2 > max(rtol ** 2, 1e-14) * max(w2[-1], 1e-300)
    return Q @ (V2[:, keep2] / np.sqrt(w2[keep2]))


def project_out(Q: FloatArray, X: FloatArray) -> FloatArray:
    return X - Q @ (Q.T @ X)


def residual_ratio(Q: FloatArray, X: FloatArray) -> float:
    """How much of X (relative, worst column direction) is left outside span(Q)."""
    nx = np.linalg.norm(X, axis=0)
    if np.all(nx == 0):
        return 0.0
    Xn = normalise(X[:, nx > 0])
    P = project_out(Q, Xn)
    if P.shape[1] == 1:
        return float(np.linalg.norm(P))
    return float(np.linalg.svd(P, compute_uv=False)[-1])


def identifiable_part(Q: FloatArray, X: FloatArray, tol: float) -> FloatArray:
    """The directions of span(X) that stand out of span(Q) by at least ``tol``.

    Columns are normalised, projected out of span(Q) and split into principal directions;
    a direction whose projection is shorter than ``tol`` (relative to unit columns) is left
    out, as a candidate with ``residual_ratio < tol`` is. Such a direction is mostly what
    rounding or the noise in the regressors themselves makes of it: in a beam recording the
    joints are recorded where the trigger fired, so a trigger's jitter along the motion
    moves both the residual and every regressor computed from the joints, and a direction
    that is almost inside span(Q) is then mostly that jitter (errors in the variables).
    Returns (rows, k') columns (principal directions scaled by their length).

    Examples
    --------
    >>> Q = np.array([[1.0], [0.0], [0.0]])
    >>> X = np.array([[1.0, 1.0], [1e-6, 0.0], [0.0, 1.0]])
    >>> identifiable_part(Q, X, 3e-3).shape   # the first column is (almost) in span(Q)
    (3, 1)
    """
    Xp = project_out(Q, normalise(X))
    if Xp.shape[1] == 0:
        return Xp
    U, s, _ = np.linalg.svd(Xp, full_matrices=False)
    keep = s >= tol
    return U[:, keep] * s[keep]


SPLITS = ("blocked", "random")


def folds_of(n_samples: int, k: int, seed: int, split: str = "random") -> list[FloatArray]:
    """Sample index sets of the K folds: ``random`` (a seeded permutation dealt out) or
    ``blocked`` (K contiguous runs of samples, in the recorded order: neighbours on a path or
    repeated poses leave together, so a near-duplicate neighbour cannot flatter the fit).

    Examples
    --------
    >>> [f.tolist() for f in folds_of(7, 3, 0, "blocked")]
    [[0, 1, 2], [3, 4], [5, 6]]
    """
    k = max(2, min(k, n_samples))
    if split == "blocked":
        return [np.asarray(f, int) for f in np.array_split(np.arange(n_samples), k)]
    if split != "random":
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    rng = np.random.default_rng(seed)
    perm = rng.permutation(n_samples)
    return [np.sort(perm[i::k]) for i in range(k)]


def default_split(t_s, kind: str = "tracker") -> str:
    """``blocked`` where the samples are ordered in time along the robot's motion (a tracker
    recording whose times increase: a path, or poses visited one after the other), else
    ``random``. Touch and beam recordings are patterns (orientations about one point,
    passes through the beams) whose contiguous runs are whole parts of the pattern: leaving
    one out leaves the rigid fit of the others undetermined, so they keep the random split."""
    t = np.asarray(t_s, float)
    ordered = t.size > 1 and np.ptp(t) > 0 and np.all(np.diff(t) >= 0)
    return "blocked" if ordered and kind == "tracker" else "random"


@dataclass
class CV:
    """Row index sets of the folds."""
    test_rows: list[FloatArray]
    train_rows: list[FloatArray]
    m: int
    n_samples: int
    scale: FloatArray | None = None   # per-row factor turning a residual into mm
    split: str = "random"

    @classmethod
    def make(cls, n_samples: int, m: int, k: int, seed: int, split: str = "random") -> "CV":
        te, tr = [], []
        allr = np.arange(n_samples * m)
        for f in folds_of(n_samples, k, seed, split):
            rows = (f[:, None] * m + np.arange(m)).ravel()
            mask = np.ones(n_samples * m, bool)
            mask[rows] = False
            te.append(rows)
            tr.append(allr[mask])
        return cls(te, tr, m, n_samples, split=split)

    def heldout_rms(self, y: FloatArray, M: FloatArray, Q: FloatArray | None = None) -> float:
        """sqrt(mean over samples of |held-out residual|^2).

        The fit on the training rows only depends on span(M), so an orthonormal basis Q of
        it is used: the training Gram matrix is then ``I - Q_te^T Q_te``.
        """
        Q = orth(M) if Q is None else Q
        p = Q.shape[1]
        qty = Q.T @ y
        sse = 0.0
        for te in self.test_rows:
            Qt, yt = Q[te], y[te]
            if p:
                G = np.eye(p) - Qt.T @ Qt
                rhs = qty - Qt.T @ yt
                # w: each direction's share of its energy on the training rows; a direction
                # (almost) only on the left-out rows is not determined by the training fold
                # (identify.py's rule: relative singular value below IDENT_TOL) and is held
                # at the expansion point (the fit on all samples), as the nonlinear refit
                # holds what its training poses do not determine; solving for it blew the
                # held-out error up by orders of magnitude (a blocked fold of a path with a
                # constant tool orientation: the TCP)
                w, V = np.linalg.eigh(G)
                keep = w >= FOLD_IDENT_TOL ** 2
                beta = V[:, keep] @ ((V[:, keep].T @ rhs) / w[keep])
                e = yt - Qt @ beta
            else:
                e = yt
            if self.scale is not None:
                e = e * self.scale[te]
            sse += float(e @ e)
        return float(np.sqrt(sse / self.n_samples))


def fit_linear(y: FloatArray, M: FloatArray) -> tuple[FloatArray, FloatArray, float, int]:
    """beta, covariance (from J^T J and the residual variance), RSS, rank."""
    Mn = normalise(M)
    scale = np.linalg.norm(M, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    w, V = np.linalg.eigh(Mn.T @ Mn)
    keep = w > 1e-18 * w[-1]
    rank = int(np.sum(keep))
    G_pinv = (V[:, keep] / w[keep]) @ V[:, keep].T
    beta = (G_pinv @ (Mn.T @ y)) / scale
    r = y - M @ beta
    rss = float(r @ r)
    dof = max(len(y) - rank, 1)
    cov = G_pinv / np.outer(scale, scale) * rss / dof
    return beta, cov, rss, int(rank)


def f_test(y_perp: FloatArray, Qm_cols: int, Xp: FloatArray, n_rows: int) -> tuple[float, float, int]:
    """Extra-sum-of-squares F-test of the projected group Xp on the projected residual.

    Returns (gain = RSS reduction, p-value, k = group rank).
    """
    Qx = orth(Xp, 1e-6)
    k = Qx.shape[1]
    if k == 0:
        return 0.0, 1.0, 0
    rss0 = float(y_perp @ y_perp)
    gain = float(np.sum((Qx.T @ y_perp) ** 2))
    dof = n_rows - Qm_cols - k
    if dof <= 0:
        return gain, 1.0, k
    # a floor on the noise (1e-6 mm per row): exact data must not make rounding significant
    rss1 = max(rss0 - gain, dof * NOISE_FLOOR_MM ** 2)
    F = (gain / k) / (rss1 / dof)
    return gain, float(stats.f.sf(F, k, dof)), k


def batch_f_tests(Q: FloatArray, X_all: FloatArray, blocks: list[slice], y_perp: FloatArray,
                  n_rows: int, ident_tol: float | None = None, projected: bool = False
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """:func:`residual_ratio` and :func:`f_test` of many candidate groups at once.

    ``X_all`` holds every group's columns, each normalised (``normalise``); ``blocks`` the
    column slice of each group. One product projects them all out of span(Q); each group's
    test then needs only its small Gram matrix. Returns (ratio, gain, p, k) arrays, equal to
    the one-at-a-time functions (the rank tolerance of ``f_test``'s ``orth(., 1e-6)``); the
    ratio, a smallest singular value taken from the Gram matrix, to about 1e-8 absolute (it
    is only compared with the identifiability tolerance, 3e-3).
    With ``ident_tol`` each group is first cut to its :func:`identifiable_part` (directions
    standing out of span(Q) by at least ``ident_tol``), as the structure groups are tested.
    ``projected``: ``X_all`` is already projected out of span(Q) (kept up to date by the
    caller as the model grows; only ``Q.shape[1]`` is used).
    """
    P = X_all if projected or not Q.shape[1] else X_all - Q @ (Q.T @ X_all)
    c_all = P.T @ y_perp
    sq = np.einsum("rc,rc->c", P, P)                        # every column's squared norm
    rss0 = float(y_perp @ y_perp)
    nb = len(blocks)
    ratio, gain, kk = np.zeros(nb), np.zeros(nb), np.zeros(nb, dtype=int)
    widths = np.array([b.stop - b.start for b in blocks])
    for wdt in np.unique(widths):
        which = np.flatnonzero(widths == wdt)
        idx = np.array([np.arange(blocks[i].start, blocks[i].stop) for i in which])  # (b, w)
        # the groups' small Gram matrices, one (rows, b) product per entry (faster than an
        # einsum over a (rows, b, w) copy)
        G = np.empty((len(which), wdt, wdt))
        if wdt > 3:       # wide groups (the structure test's): one matrix product each
            for b, ix in enumerate(idx):
                Pb = P[:, ix]
                G[b] = Pb.T @ Pb
        else:
            cols = [P[:, idx[:, i]] for i in range(wdt)] if wdt > 1 else []
            for i in range(wdt):
                G[:, i, i] = sq[idx[:, i]]
                for j in range(i + 1, wdt):
                    G[:, i, j] = G[:, j, i] = np.einsum("rb,rb->b", cols[i], cols[j])
        c = c_all[idx]                                          # (b, w)
        d = np.einsum("bii->bi", G)
        if ident_tol is not None:
            w, V = np.linalg.eigh(G)
            keep = w >= ident_tol ** 2
            proj = np.einsum("bij,bi->bj", V, c)
            kk[which] = keep.sum(1)
            gain[which] = np.sum(np.where(keep, proj ** 2 / np.where(keep, w, 1.0), 0.0), 1)
            continue
        ratio[which] = np.sqrt(np.maximum(np.linalg.eigvalsh(G)[:, 0], 0.0))
        nz = d > 0
        dn = np.sqrt(np.where(nz, d, 1.0))
        Gn = G / (dn[:, :, None] * dn[:, None, :])
        b = c / dn
        w, V = np.linalg.eigh(Gn)
        keep = (w > 1e-12 * w[:, -1:]) & (w[:, -1:] > 0) & np.any(nz, 1)[:, None]
        proj = np.einsum("bij,bi->bj", V, b)
        kk[which] = keep.sum(1)
        gain[which] = np.sum(np.where(keep, proj ** 2 / np.where(keep, w, 1.0), 0.0), 1)
    dof = n_rows - Q.shape[1] - kk
    ok = (kk > 0) & (dof > 0)
    p = np.ones(nb)
    if np.any(ok):
        rss1 = np.maximum(rss0 - gain[ok], dof[ok] * NOISE_FLOOR_MM ** 2)
        F = (gain[ok] / kk[ok]) / (rss1 / dof[ok])
        p[ok] = stats.f.sf(F, kk[ok], dof[ok])
    return ratio, gain, p, kk


def holm_pass(pvals: list[float], alpha: float) -> list[bool]:
    """Holm step-down: which hypotheses are rejected at family-wise level alpha.

    Examples
    --------
    >>> holm_pass([0.0001, 0.04, 0.0004], 0.0005)
    [True, False, False]
    >>> holm_pass([0.0001, 0.04, 0.0004], 0.01)
    [True, False, True]
    """
    order = np.argsort(pvals)
    m = len(pvals)
    ok = [False] * m
    for i, idx in enumerate(order):
        if pvals[idx] * (m - i) < alpha:
            ok[idx] = True
        else:
            break
    return ok
