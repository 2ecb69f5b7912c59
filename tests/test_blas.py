"""solvers.analysis.blas: one BLAS thread inside single_thread(), the previous count after."""

import numpy as np  # noqa: F401  (loads numpy's BLAS so threadpoolctl sees it)
from threadpoolctl import threadpool_info, threadpool_limits

from solvers.analysis.blas import single_thread


def _blas_threads() -> list[int]:
    return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]


def test_single_thread_limits_and_restores():
    assert _blas_threads(), "numpy's BLAS is not visible to threadpoolctl"
    with threadpool_limits(limits=2, user_api="blas"):
        assert set(_blas_threads()) == {2}
        with single_thread():
            assert set(_blas_threads()) == {1}
        assert set(_blas_threads()) == {2}
