"""Kinematic sensitivities the analysis needs: TCP pose and, per sample, the TCP twist that a
small change of each DH parameter (or joint angle) causes.

A *twist column* is ``(dc, dw)``: the TCP's displacement (mm) and the tool's small rotation
(rad, rotation vector) in the robot base frame, per unit of the parameter (rad or mm).

Standard DH (``Rz(theta) Tz(d) Tx(a) Rx(alpha)``): joint i turns about z of frame i-1,
``d_i`` slides along z of frame i-1, ``a_i`` along x of frame i, ``alpha_i`` turns about x of
frame i. Modified DH (``Rx(alpha) Tx(a) Rz(theta) Tz(d)``): ``alpha_i`` turns about x of frame
i-1, ``a_i`` slides along x of frame i-1, joint i turns about z of frame i and ``d_i`` slides
along it.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from solvers.dh import RobotModel, dh_angles_rad, link_matrices
from solvers.validate import FloatArray


@dataclass(frozen=True)
class Sensitivities:
    """TCP poses and twist columns of a stack of joint values.

    ``tcp_mm`` (N, 3) and ``axis`` (N, 3) (the tool z axis) in base; ``R_base_flange``
    (N, 3, 3); ``theta``, ``a``, ``d``, ``alpha`` (N, 6, n): twist columns per rad / mm / mm /
    rad of each DH row's parameter.
    """

    tcp_mm: FloatArray
    axis: FloatArray
    R_base_flange: FloatArray
    theta: FloatArray
    a: FloatArray
    d: FloatArray
    alpha: FloatArray


@lru_cache(maxsize=256)
def pose_matrix(pose) -> FloatArray:
    """``pose.as_matrix()`` of a (frozen, hashable) robot base or flange pose, computed once
    (read-only: the same array is handed out on every call)."""
    T = pose.as_matrix()
    T.setflags(write=False)
    return T


def _rot_twist(axis: FloatArray, origin: FloatArray, c: FloatArray) -> FloatArray:
    """Twist (N, 6) of a unit rotation about ``axis`` through ``origin`` seen at point c."""
    return np.concatenate([np.cross(axis, c - origin), axis], axis=-1)


def _trans_twist(axis: FloatArray) -> FloatArray:
    return np.concatenate([axis, np.zeros_like(axis)], axis=-1)


def frames_of(robot: RobotModel, q_deg: FloatArray, dtheta_rad: FloatArray | None = None,
              ddh: dict[str, FloatArray] | None = None) -> FloatArray:
    """Frames 0..n (N, n+1, 4, 4) with optional per-sample joint-angle and DH-row changes."""
    p = robot.params()
    theta = dh_angles_rad(robot, np.atleast_2d(q_deg))
    if dtheta_rad is not None:
        theta = theta + dtheta_rad
    ddh = ddh or {}
    d = p["d_mm"] + ddh.get("d", 0.0)
    a = p["a_mm"] + ddh.get("a", 0.0)
    al = np.radians(p["alpha_deg"]) + ddh.get("alpha", 0.0)
    N, n = theta.shape
    if robot.dh_convention not in ("standard", "modified"):
        link_matrices(robot.dh_convention, theta, d, a, al)   # raises its clear error
    F = np.zeros((N, n + 1, 4, 4))
    F[:, :, 3, 3] = 1.0
    T0 = pose_matrix(robot.base_pose)
    F[:, 0] = T0
    # the chain composed column by column (x, y, z axes and origin of each frame, (N, 3)):
    # the link matrices of solvers.dh.link_matrices applied as their elementary motions,
    # several times faster than (N, 4, 4) matrix products (checked against them in the tests)
    x, y, z, o = (np.broadcast_to(T0[:3, k], (N, 3)) for k in range(4))
    ct, st = np.cos(theta), np.sin(theta)
    d = np.broadcast_to(d, theta.shape)
    a = np.broadcast_to(a, theta.shape)
    ca, sa = np.broadcast_to(np.cos(al), theta.shape), np.broadcast_to(np.sin(al), theta.shape)
    standard = robot.dh_convention == "standard"
    for i in range(n):
        c, s_, cai, sai = ct[:, i:i + 1], st[:, i:i + 1], ca[:, i:i + 1], sa[:, i:i + 1]
        if standard:      # Rz(theta) Tz(d) Tx(a) Rx(alpha)
            x, y = c * x + s_ * y, c * y - s_ * x
            o = o + d[:, i:i + 1] * z + a[:, i:i + 1] * x
            y, z = cai * y + sai * z, cai * z - sai * y
        else:             # Rx(alpha) Tx(a) Rz(theta) Tz(d)
            y, z = cai * y + sai * z, cai * z - sai * y
            o = o + a[:, i:i + 1] * x
            x, y = c * x + s_ * y, c * y - s_ * x
            o = o + d[:, i:i + 1] * z
        F[:, i + 1, :3, 0], F[:, i + 1, :3, 1], F[:, i + 1, :3, 2] = x, y, z
        F[:, i + 1, :3, 3] = o
    return F


def sensitivities(robot: RobotModel, q_deg: FloatArray, tool: FloatArray,
                  dtheta_rad: FloatArray | None = None,
                  ddh: dict[str, FloatArray] | None = None,
                  frames: FloatArray | None = None) -> Sensitivities:
    """TCP pose and twist columns of every DH parameter at each sample (vectorised);
    ``frames``: :func:`frames_of` of the same arguments, if already computed."""
    F = frames_of(robot, q_deg, dtheta_rad, ddh) if frames is None else frames
    T = F[:, -1] @ pose_matrix(robot.flange_pose) @ tool
    c = T[:, :3, 3]
    n = F.shape[1] - 1
    z = F[:, :, :3, 2]
    x = F[:, :, :3, 0]
    o = F[:, :, :3, 3]
    if robot.dh_convention == "standard":
        jz, jo = z[:, :-1], o[:, :-1]           # joint i about z_{i-1}
        dz = z[:, :-1]                           # d_i along z_{i-1}
        ax, ao = x[:, 1:], o[:, 1:]              # a_i along x_i, alpha_i about x_i through o_i
    else:
        jz, jo = z[:, 1:], o[:, 1:]
        dz = z[:, 1:]
        ax, ao = x[:, :-1], o[:, :-1]
    cc = c[:, None, :]
    th = np.swapaxes(_rot_twist(jz, jo, cc), 1, 2)
    al = np.swapaxes(_rot_twist(ax, ao, cc), 1, 2)
    dd = np.swapaxes(_trans_twist(dz), 1, 2)
    aa = np.swapaxes(_trans_twist(ax), 1, 2)
    del n
    return Sensitivities(tcp_mm=c, axis=T[:, :3, 2], R_base_flange=F[:, -1, :3, :3]
                         @ pose_matrix(robot.flange_pose)[:3, :3],
                         theta=th, a=aa, d=dd, alpha=al)


@dataclass
class State:
    """Effects applied to the rigid model (the point the analysis linearises at).

    ``dtheta_rad`` (N, n) per-sample DH angle changes; ``ddh`` {'a', 'd', 'alpha'} -> (n,)
    DH row changes (mm, mm, rad); ``shift_mm`` (N, 3) TCP translations in base.
    """

    dtheta_rad: FloatArray
    shift_mm: FloatArray
    ddh: dict[str, FloatArray] = field(default_factory=dict)

    @classmethod
    def zero(cls, n_samples: int, n_joints: int) -> "State":
        return cls(np.zeros((n_samples, n_joints)), np.zeros((n_samples, 3)),
                   {k: np.zeros(n_joints) for k in ("a", "d", "alpha")})


def state_frames(robot: RobotModel, q_deg: FloatArray, state: State | None = None) -> FloatArray:
    """:func:`frames_of` with ``state``'s joint-angle and DH-row changes."""
    if state is None:
        return frames_of(robot, q_deg)
    return frames_of(robot, q_deg, state.dtheta_rad, state.ddh)


def flange_of(robot: RobotModel, F: FloatArray, state: State | None = None
              ) -> tuple[FloatArray, FloatArray]:
    """(R_base_flange (N, 3, 3), flange position (N, 3) plus ``state``'s shift) from frames."""
    T = F[:, -1] @ pose_matrix(robot.flange_pose)
    p = T[:, :3, 3] if state is None else T[:, :3, 3] + state.shift_mm
    return T[:, :3, :3], p


def state_sensitivities(robot: RobotModel, q_deg: FloatArray, tool: FloatArray,
                        state: State | None = None, frames: FloatArray | None = None
                        ) -> Sensitivities:
    """:func:`sensitivities` of the model with ``state``'s effects applied."""
    if state is None:
        return sensitivities(robot, q_deg, tool, frames=frames)
    s = sensitivities(robot, q_deg, tool, state.dtheta_rad, state.ddh, frames=frames)
    return replace(s, tcp_mm=s.tcp_mm + state.shift_mm)
