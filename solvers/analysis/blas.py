"""Run the analysis on one BLAS thread, through threadpoolctl.

The analysis does hundreds of small products of tall, thin matrices; a threaded BLAS costs
more than it gains there (5x slower on a loaded 2-core machine). ``single_thread()`` limits
every BLAS library loaded in the process (OpenBLAS, MKL, BLIS, whichever numpy and scipy
use) to one thread for the duration and restores the previous counts on exit.
threadpoolctl [1]_ finds the libraries among those loaded, so nothing is searched on disk.

References
----------
.. [1] threadpoolctl, https://github.com/joblib/threadpoolctl
"""

from __future__ import annotations

from contextlib import contextmanager
from collections.abc import Iterator

from threadpoolctl import threadpool_limits


@contextmanager
def single_thread() -> Iterator[None]:
    """Context manager: every BLAS on one thread inside.

    Example
    -------
    >>> from threadpoolctl import threadpool_info
    >>> with single_thread():
    ...     all(p["num_threads"] == 1 for p in threadpool_info() if p["user_api"] == "blas")
    True
    """
    with threadpool_limits(limits=1, user_api="blas"):
        yield
