"""Input checks shared by every solver: shape, finiteness, proper rigid transforms.

Each check raises :class:`~solvers.errors.CalibrationError` naming the field and the reason,
so a NaN or a wrong shape never reaches the math as a silent NaN result.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from solvers.errors import CalibrationError

FloatArray = npt.NDArray[np.float64]

try:  # the LAPACK gufunc behind np.linalg.det, without its per-call Python checks (~1.5 µs)
    from numpy.linalg import _umath_linalg

    _det = _umath_linalg.det
except (ImportError, AttributeError):  # pragma: no cover - other numpy layouts
    _det = np.linalg.det

_EYE3 = np.eye(3)
_LAST_ROW_BYTES = np.array([0.0, 0.0, 0.0, 1.0]).tobytes()


def as_array(value: object, loc: str | tuple[str | int, ...], shape: Sequence[int | None]) -> FloatArray:
    """Float array of the given shape (``None`` = any length), all values finite.

    Examples
    --------
    >>> as_array([[1, 2, 3]], "points_mm", (None, 3)).shape
    (1, 3)
    >>> as_array([1, float("nan"), 3], "tcp_mm", (3,))
    Traceback (most recent call last):
    ...
    solvers.errors.CalibrationError: tcp_mm.1: is not a finite number (nan)
    >>> as_array(float("inf"), "sigma_mm", ())
    Traceback (most recent call last):
    ...
    solvers.errors.CalibrationError: sigma_mm: is not a finite number (inf)
    """
    base = (loc,) if isinstance(loc, str) else tuple(loc)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(base, f"must be numbers: {exc}") from None
    if arr.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, arr.shape)):
        want = "x".join("N" if s is None else str(s) for s in shape)
        raise CalibrationError(base, f"must have shape ({want}), got {arr.shape}")
    if not np.isfinite(arr).all():
        idx = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0]) if arr.ndim else ()
        raise CalibrationError(base + idx, f"is not a finite number ({arr[idx]})")
    return arr


def as_transforms(value: object, loc: str, min_count: int = 1, tol: float = 1e-6) -> FloatArray:
    """Stack of 4x4 rigid transforms (N, 4, 4), rotation orthonormal within ``tol``."""
    T = as_array(value, loc, (None, 4, 4))
    if len(T) < min_count:
        raise CalibrationError((loc,), f"needs at least {min_count} poses, got {len(T)}")
    if is_rigid_stack(T, tol):
        return T
    R = T[:, :3, :3]
    err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2))
    bad_rot = (err > tol) | (np.linalg.det(R) < 0)
    bad_row = np.abs(T[:, 3] - [0, 0, 0, 1]).max(axis=1) > tol
    if bad_rot.any() or bad_row.any():
        k = int(np.argmax(bad_rot | bad_row))
        if bad_rot[k]:
            raise CalibrationError((loc, k), "rotation part is not a proper rotation matrix")
        raise CalibrationError((loc, k), "last row must be [0, 0, 0, 1]")
    return T


def is_rigid_stack(T: FloatArray, tol: float = 1e-6) -> bool:
    """True when a float (N, 4, 4) array is certainly what :func:`as_transforms` accepts:
    N >= 1, all finite, last rows exactly ``[0, 0, 0, 1]``, ``R Rᵀ - I`` within ``tol``
    (Frobenius norm over all poses, so each entry is) and ``det R > 0``. A handful of
    vectorised operations for the common case; False means "look closer"
    (:func:`as_transforms` finds the pose and the reason).

    Examples
    --------
    >>> T = np.tile(np.eye(4), (2, 1, 1))
    >>> is_rigid_stack(T)
    True
    >>> T[1, 3, 3] = 1.0 + 1e-9  # accepted by as_transforms, but not exact: look closer
    >>> is_rigid_stack(T)
    False
    """
    n = len(T)
    # Σ T² by BLAS: finite iff every entry is (and nothing below can overflow); no FP warnings
    if not n or T[:, 3].tobytes() != _LAST_ROW_BYTES * n or not math.isfinite(np.vdot(T, T)):
        return False
    R = T[:, :3, :3]
    F = R @ R.transpose(0, 2, 1) - _EYE3
    return bool(np.vdot(F, F) <= tol * tol) and min(_det(R).tolist()) > 0.0


def as_points(value: object, loc: str, min_count: int = 1) -> FloatArray:
    """Point set (N, 3) in mm with at least ``min_count`` points."""
    P = as_array(value, loc, (None, 3))
    if len(P) < min_count:
        raise CalibrationError((loc,), f"needs at least {min_count} points, got {len(P)}")
    return P
