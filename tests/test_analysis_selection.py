"""The selection's batched F-tests equal the one-at-a-time ones (``selection.py``), and the
orthogonalisation stays finite and orthonormal on a rank-deficient model."""

from __future__ import annotations

import warnings

import numpy as np

from solvers.analysis.selection import (batch_f_tests, f_test, identifiable_part, normalise,
                                        orth, project_out, residual_ratio)


def _case(seed: int):
    rng = np.random.default_rng(seed)
    Q = orth(rng.normal(size=(300, 10)))
    X = rng.normal(size=(300, 9))
    X[:, 3] = Q @ rng.normal(size=10) + 1e-4 * rng.normal(size=300)   # almost inside span(Q)
    X[:, 8] = X[:, 6] + 1e-9 * rng.normal(size=300)                     # a repeated column
    y = project_out(Q, rng.normal(size=300) + 0.3 * X[:, 0])
    groups = [X[:, :3], X[:, 3:5], X[:, 5:6], X[:, 6:9]]
    blocks, start = [], 0
    for g in groups:
        blocks.append(slice(start, start + g.shape[1]))
        start += g.shape[1]
    return Q, groups, blocks, np.hstack([normalise(g) for g in groups]), y


def test_batched_tests_equal_the_single_ones() -> None:
    for seed in range(3):
        Q, groups, blocks, X_all, y = _case(seed)
        ratio, gain, p, k = batch_f_tests(Q, X_all, blocks, y, 300)
        for i, g in enumerate(groups):
            g1, p1, k1 = f_test(y, 10, project_out(Q, normalise(g)), 300)
            # the smallest singular value from the Gram matrix: good to ~1e-8 absolute, far
            # below the identifiability tolerance (3e-3) it is compared with
            assert np.isclose(ratio[i], residual_ratio(Q, g), rtol=1e-6, atol=1e-7)
            assert np.isclose(gain[i], g1, rtol=1e-6) and k[i] == k1
            assert np.isclose(p[i], p1, rtol=1e-6, atol=1e-300)
        _, gain, p, k = batch_f_tests(Q, X_all, blocks, y, 300, ident_tol=3e-3)
        for i, g in enumerate(groups):
            g1, p1, k1 = f_test(y, 10, identifiable_part(Q, g, 3e-3), 300)
            assert np.isclose(gain[i], g1, rtol=1e-6, atol=1e-12) and k[i] == k1
        assert k[1] == 1   # the direction inside span(Q) does not count as structure


def test_orth_of_a_rank_deficient_model_is_finite_and_orthonormal() -> None:
    """Exactly dependent columns (an effect inside the model plus a structure group): the
    rounding-level directions the first pass keeps must be dropped by the second, not
    divided by their ~1e-150 norms (values of 1e141 and the overflow warning of issue 11)."""
    for seed in range(5):
        rng = np.random.default_rng(seed)
        A = rng.normal(size=(400, 8))
        M = np.hstack([A, A[:, :4] @ rng.normal(size=(4, 6)), 3.0 * A[:, 2:3]])
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            Q = orth(M)
        assert Q.shape[1] == 8 and np.all(np.abs(Q) <= 1.0 + 1e-12)
        np.testing.assert_allclose(Q.T @ Q, np.eye(8), atol=1e-10)
        assert np.linalg.norm(project_out(Q, M)) < 1e-9 * np.linalg.norm(M)
