"""Poses and frames in every controller's notation, all through SciPy's ``Rotation``.

Conventions (see docs/conventions.md):

- KUKA ``X, Y, Z, A, B, C``: ``R = Rz(A) @ Ry(B) @ Rx(C)`` (intrinsic Z, Y', X''), degrees, mm.
- ABB position + quaternion ``[q1, q2, q3, q4]`` with q1 the scalar, mm.
- FANUC ``X, Y, Z, W, P, R``: ``R = Rz(R) @ Ry(P) @ Rx(W)`` (fixed X, Y, Z), degrees, mm.
- Universal Robots ``p[x, y, z, rx, ry, rz]``: metres, rotation vector in radians.

A transform ``T_a_b`` maps b coordinates into a; compose by matching inner names:
``T_base_tcp = T_base_flange @ T_flange_tcp``.
"""

from __future__ import annotations

import inspect
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.validate import FloatArray, as_array

try:  # SciPy >= 1.15 (a Cython build may carry no signature: then it is not used)
    ASSUME_VALID = "assume_valid" in inspect.signature(Rotation.from_matrix).parameters
except (TypeError, ValueError):
    ASSUME_VALID = False

KUKA_EULER = "ZYX"  # intrinsic Z, Y', X'' with angles [A, B, C]
FANUC_EULER = "xyz"  # extrinsic x, y, z with angles [W, P, R]


@dataclass(frozen=True)
class Pose:
    """A frame as the KUKA pendant shows it: x, y, z in mm, a, b, c in degrees.

    Examples
    --------
    >>> p = Pose(100, 0, 50, 90, 0, 0)
    >>> np.round(p.as_matrix()[:3, 0], 6).tolist()
    [0.0, 1.0, 0.0]
    >>> Pose.from_matrix(p.as_matrix()) == p
    True
    """

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    a: float = 0.0
    b: float = 0.0
    c: float = 0.0

    def as_matrix(self) -> FloatArray:
        """4x4 T of this pose: ``R = Rz(a) @ Ry(b) @ Rx(c)``."""
        return matrix_from_kuka(self.as_array())

    def as_array(self) -> FloatArray:
        return np.array([self.x, self.y, self.z, self.a, self.b, self.c], dtype=float)

    @classmethod
    def from_matrix(cls, T: FloatArray, decimals: int = 9, orthonormal: bool = False) -> "Pose":
        """KUKA pose of a 4x4 transform (rounded to ``decimals`` to drop float dust).
        ``orthonormal``: T's rotation is one to float precision (a product of rotations, as
        forward kinematics gives), so SciPy may skip projecting it onto the nearest one."""
        v = np.round(kuka_from_matrix(T, orthonormal), decimals) + 0.0
        return cls(*(float(x) for x in v))

    @classmethod
    def from_array(cls, v: object) -> "Pose":
        return cls(*(float(x) for x in as_array(v, "pose", (6,))))


def _compose(R: Rotation, t: FloatArray) -> FloatArray:
    t = np.asarray(t, dtype=float)
    M = R.as_matrix()
    T = np.zeros(M.shape[:-2] + (4, 4))
    T[..., :3, :3] = M
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def _rotation(R: FloatArray, orthonormal: bool = False) -> Rotation:
    """SciPy's rotation of the 3x3 ``R``; ``orthonormal`` skips the projection onto the
    nearest rotation (``assume_valid``, SciPy >= 1.15; a third of the time of a touch-up's
    conversion) where ``R`` is one already."""
    if orthonormal and ASSUME_VALID:
        return Rotation.from_matrix(R, assume_valid=True)
    return Rotation.from_matrix(R)


def _euler(T: FloatArray, seq: str, orthonormal: bool = False) -> FloatArray:
    """Euler angles (deg); at gimbal lock SciPy sets the third angle to 0, which still
    reproduces the same rotation, so its warning is not passed on to the user."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Gimbal lock detected")
        return _rotation(T[..., :3, :3], orthonormal).as_euler(seq, degrees=True)


def matrix_from_kuka(xyzabc: FloatArray) -> FloatArray:
    """4x4 T (or a stack (N, 4, 4)) from KUKA ``[x, y, z, a, b, c]`` (mm, deg).

    ``R = Rz(a) @ Ry(b) @ Rx(c)``, intrinsic Z, Y', X''.

    Examples
    --------
    >>> T = matrix_from_kuka([0, 0, 0, 0, 90, 0])
    >>> np.round(T[:3, 2], 6).tolist()  # tool z now points along base x
    [1.0, 0.0, 0.0]
    """
    v = np.asarray(xyzabc, dtype=float)
    return _compose(Rotation.from_euler(KUKA_EULER, v[..., 3:6], degrees=True), v[..., :3])


def kuka_from_matrix(T: FloatArray, orthonormal: bool = False) -> FloatArray:
    """KUKA ``[x, y, z, a, b, c]`` (mm, deg) of a 4x4 T or a stack of them (``orthonormal``:
    see :func:`_rotation`)."""
    T = np.asarray(T, dtype=float)
    abc = _euler(T, KUKA_EULER, orthonormal)
    return np.concatenate([T[..., :3, 3], abc], axis=-1)


def matrix_from_abb(pos_mm: FloatArray, quat_wxyz: FloatArray) -> FloatArray:
    """4x4 T from ABB ``[x, y, z]`` (mm) and ``[q1, q2, q3, q4]`` (q1 scalar; normalised here)."""
    q = np.asarray(quat_wxyz, dtype=float)
    return _compose(Rotation.from_quat(q, scalar_first=True), pos_mm)


def abb_from_matrix(T: FloatArray) -> tuple[FloatArray, FloatArray]:
    """ABB position (mm) and quaternion ``[q1..q4]``, scalar first and q1 >= 0."""
    T = np.asarray(T, dtype=float)
    q = Rotation.from_matrix(T[..., :3, :3]).as_quat(canonical=True, scalar_first=True)
    return T[..., :3, 3].copy(), q


def matrix_from_fanuc(xyzwpr: FloatArray) -> FloatArray:
    """4x4 T from FANUC ``[x, y, z, w, p, r]``: ``R = Rz(r) @ Ry(p) @ Rx(w)`` (fixed X, Y, Z).

    Examples
    --------
    >>> bool(np.allclose(matrix_from_fanuc([1, 2, 3, 10, 20, 30]),
    ...                  matrix_from_kuka([1, 2, 3, 30, 20, 10])))
    True
    """
    v = np.asarray(xyzwpr, dtype=float)
    return _compose(Rotation.from_euler(FANUC_EULER, v[..., 3:6], degrees=True), v[..., :3])


def fanuc_from_matrix(T: FloatArray) -> FloatArray:
    """FANUC ``[x, y, z, w, p, r]`` (mm, deg) of a 4x4 T."""
    T = np.asarray(T, dtype=float)
    wpr = _euler(T, FANUC_EULER)
    return np.concatenate([T[..., :3, 3], wpr], axis=-1)


def matrix_from_ur(p: FloatArray) -> FloatArray:
    """4x4 T (mm) from a Universal Robots ``p[x, y, z, rx, ry, rz]`` (metres, rotation vector)."""
    v = np.asarray(p, dtype=float)
    return _compose(Rotation.from_rotvec(v[..., 3:6]), 1000.0 * v[..., :3])


def ur_from_matrix(T: FloatArray) -> FloatArray:
    """Universal Robots ``p[x, y, z, rx, ry, rz]`` (metres, rad) of a 4x4 T in mm."""
    T = np.asarray(T, dtype=float)
    rv = Rotation.from_matrix(T[..., :3, :3]).as_rotvec()
    return np.concatenate([T[..., :3, 3] / 1000.0, rv], axis=-1)


def invert(T: FloatArray) -> FloatArray:
    """Inverse of a rigid transform (or a stack): ``[R^T, -R^T t]``."""
    T = np.asarray(T, dtype=float)
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3:4])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def translation(xyz: FloatArray) -> FloatArray:
    """Pure translation 4x4."""
    return _compose(Rotation.identity(), xyz)


def rotation_matrix(R: FloatArray | Rotation, t: FloatArray | None = None) -> FloatArray:
    """4x4 T from a 3x3 rotation (or ``Rotation``) and an optional translation."""
    rot = R if isinstance(R, Rotation) else Rotation.from_matrix(np.asarray(R, dtype=float))
    return _compose(rot, np.zeros(3) if t is None else t)


def angle_between_deg(R1: FloatArray, R2: FloatArray) -> FloatArray:
    """Angle (deg) of the relative rotation ``R1^T R2`` (broadcasts over stacks)."""
    rel = np.swapaxes(np.asarray(R1), -1, -2) @ np.asarray(R2)
    return np.degrees(Rotation.from_matrix(rel).magnitude())


def axis_angle_deg(u: FloatArray, v: FloatArray) -> float:
    """Angle (deg) between two direction vectors."""
    u = np.asarray(u, dtype=float)
    v = np.asarray(v, dtype=float)
    c = np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def apply(T: FloatArray, points: FloatArray) -> FloatArray:
    """Map points (..., 3) through T (or a matching stack of T)."""
    T = np.asarray(T, dtype=float)
    p = np.asarray(points, dtype=float)
    return (T[..., :3, :3] @ p[..., None])[..., 0] + T[..., :3, 3]
