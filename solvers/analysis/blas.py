"""Run the analysis on one BLAS thread.

The analysis does hundreds of small products of tall, thin matrices; OpenBLAS's threading
costs more than it gains there (5x slower on a loaded 2-core machine). ``single_thread()``
sets numpy's OpenBLAS to one thread for the duration and restores the previous count; where
the library is not found it does nothing.
"""

from __future__ import annotations

import ctypes
import glob
import os
from contextlib import contextmanager

import numpy as np

_SET = ("scipy_openblas_set_num_threads64_", "openblas_set_num_threads64_",
        "openblas_set_num_threads")
_GET = ("scipy_openblas_get_num_threads64_", "openblas_get_num_threads64_",
        "openblas_get_num_threads")


def _load() -> tuple | None:
    base = os.path.dirname(os.path.dirname(np.__file__))
    for path in glob.glob(os.path.join(base, "numpy.libs", "*openblas*")):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        setf = next((getattr(lib, n) for n in _SET if hasattr(lib, n)), None)
        getf = next((getattr(lib, n) for n in _GET if hasattr(lib, n)), None)
        if setf is not None and getf is not None:
            return setf, getf
    return None


_FUNCS = _load()


@contextmanager
def single_thread():
    """Context manager: numpy's BLAS on one thread inside."""
    if _FUNCS is None:
        yield
        return
    setf, getf = _FUNCS
    try:
        before = int(getf())
    except Exception:  # pragma: no cover - foreign BLAS builds
        yield
        return
    setf(1)
    try:
        yield
    finally:
        setf(max(before, 1))
