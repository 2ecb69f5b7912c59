"""Denavit–Hartenberg kinematics: forward kinematics, geometric Jacobian, numeric IK.

Both conventions exactly as the ``robot-recording/1`` format defines them:

- standard (distal):  ``T(i-1 -> i) = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``
- modified (Craig):   ``T(i-1 -> i) = Rx(alpha_i) Tx(a_i) Rz(theta_i) Tz(d_i)``

with ``theta_i = direction_i * q_dh_i + offset_i`` and ``q_dh = C @ q`` where ``C`` is the
joint coupling (identity but for FANUC's J2/J3, whose controller measures J3 from the
horizontal). ``T_base_flange(q) = base_pose @ T(0->1) @ ... @ T(n-1->n) @ flange_pose``.

The DH link matrix is the one piece of rotation code written by hand here, once:
J. Denavit and R. S. Hartenberg, "A kinematic notation for lower-pair mechanisms based on
matrices", J. Appl. Mech. 22 (1955); J. J. Craig, "Introduction to Robotics", 3rd ed.,
ch. 3 (modified form).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from solvers.errors import KinematicsError
from solvers.frames import Pose, invert
from solvers.validate import FloatArray, as_array

Convention = Literal["standard", "modified"]


@dataclass(frozen=True)
class DHJoint:
    """One DH row: lengths in mm, angles in degrees, and the controller's joint limits."""

    a_mm: float
    alpha_deg: float
    d_mm: float
    offset_deg: float = 0.0
    direction: int = 1
    q_min_deg: float = -360.0
    q_max_deg: float = 360.0


@dataclass(frozen=True)
class RobotModel:
    """A serial arm: its DH table, mounting, coupling, and where the numbers come from."""

    name: str
    dh_convention: Convention
    joints: tuple[DHJoint, ...]
    base_pose: Pose = Pose()
    flange_pose: Pose = Pose()
    coupling: tuple[tuple[float, ...], ...] | None = None  # q_dh = C @ q, None = identity
    source: str = ""
    payload_kg: float = 0.0
    reach_mm: float = 0.0
    meta: dict = field(default_factory=dict, compare=False, hash=False)

    @property
    def dof(self) -> int:
        return len(self.joints)

    def params(self) -> dict[str, FloatArray]:
        """The DH table as arrays: ``a_mm, alpha_deg, d_mm, offset_deg, direction``.

        Built once per model (the model is frozen) and shared: the arrays are read-only.
        """
        cached = self.__dict__.get("_params")
        if cached is None:
            cols = ("a_mm", "alpha_deg", "d_mm", "offset_deg", "direction")
            cached = {c: np.array([getattr(j, c) for j in self.joints], dtype=float)
                      for c in cols}
            for v in cached.values():
                v.setflags(write=False)
            self.__dict__["_params"] = cached  # frozen: the cache bypasses __setattr__
        return dict(cached)

    def mount_matrices(self) -> tuple[FloatArray, FloatArray]:
        """(T_world_base, T_dhn_flange) of ``base_pose`` and ``flange_pose``, read-only, cached."""
        cached = self.__dict__.get("_mount")
        if cached is None:
            cached = (self.base_pose.as_matrix(), self.flange_pose.as_matrix())
            for v in cached:
                v.setflags(write=False)
            self.__dict__["_mount"] = cached
        return cached

    def coupling_matrix(self) -> FloatArray:
        return np.eye(self.dof) if self.coupling is None else np.array(self.coupling, dtype=float)

    def limits_deg(self) -> FloatArray:
        """(n, 2) array of [min, max] per joint."""
        return np.array([[j.q_min_deg, j.q_max_deg] for j in self.joints], dtype=float)

    def with_joint(self, i: int, **changes: float) -> "RobotModel":
        """A copy with DH row ``i`` (0-based) changed, e.g. ``with_joint(1, a_mm=455.3)``."""
        joints = list(self.joints)
        joints[i] = replace(joints[i], **changes)
        return replace(self, joints=tuple(joints))


def link_matrices(convention: Convention, theta_rad: FloatArray, d_mm: FloatArray,
                  a_mm: FloatArray, alpha_rad: FloatArray) -> FloatArray:
    """Link transforms (..., n, 4, 4) for broadcastable DH arrays (..., n).

    This is the only hand-written rotation code in the project (the DH link matrix).
    """
    theta, d, a, alpha = np.broadcast_arrays(theta_rad, d_mm, a_mm, alpha_rad)
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    T = np.zeros(theta.shape + (4, 4))
    if convention == "standard":  # Rz(theta) Tz(d) Tx(a) Rx(alpha)
        T[..., 0, 0], T[..., 0, 1], T[..., 0, 2], T[..., 0, 3] = ct, -st * ca, st * sa, a * ct
        T[..., 1, 0], T[..., 1, 1], T[..., 1, 2], T[..., 1, 3] = st, ct * ca, -ct * sa, a * st
        T[..., 2, 1], T[..., 2, 2], T[..., 2, 3] = sa, ca, d
    elif convention == "modified":  # Rx(alpha) Tx(a) Rz(theta) Tz(d)
        T[..., 0, 0], T[..., 0, 1], T[..., 0, 3] = ct, -st, a
        T[..., 1, 0], T[..., 1, 1], T[..., 1, 2], T[..., 1, 3] = st * ca, ct * ca, -sa, -sa * d
        T[..., 2, 0], T[..., 2, 1], T[..., 2, 2], T[..., 2, 3] = st * sa, ct * sa, ca, ca * d
    else:
        raise KinematicsError(("dh_convention",), f"must be 'standard' or 'modified', got {convention!r}")
    T[..., 3, 3] = 1.0
    return T


def joint_values(robot: RobotModel, q_deg: object) -> FloatArray:
    """Check and shape joint values: (n,) or (N, n) degrees, finite."""
    q = np.asarray(q_deg, dtype=float)
    shape = (robot.dof,) if q.ndim <= 1 else (None, robot.dof)
    return as_array(q, "joints_deg", shape)


def dh_angles_rad(robot: RobotModel, q_deg: FloatArray) -> FloatArray:
    """theta_i (rad) = direction_i * (C q)_i + offset_i."""
    p = robot.params()
    q_dh = q_deg @ robot.coupling_matrix().T
    return np.radians(p["direction"] * q_dh + p["offset_deg"])


def joint_frames(robot: RobotModel, q_deg: object) -> FloatArray:
    """Frames 0..n in base, (..., n+1, 4, 4): frame 0 is ``base_pose``, frame n the DH frame n.

    ``T_base_flange = joint_frames(...)[..., -1, :, :] @ flange_pose``.
    """
    q = joint_values(robot, q_deg)
    p = robot.params()
    links = link_matrices(robot.dh_convention, dh_angles_rad(robot, q), p["d_mm"], p["a_mm"],
                          np.radians(p["alpha_deg"]))
    frames = np.empty(q.shape[:-1] + (robot.dof + 1, 4, 4))
    frames[..., 0, :, :] = robot.mount_matrices()[0]
    for i in range(robot.dof):
        frames[..., i + 1, :, :] = frames[..., i, :, :] @ links[..., i, :, :]
    return frames


def forward_kinematics(robot: RobotModel, q_deg: object, tool: FloatArray | None = None) -> FloatArray:
    """``T_base_flange(q)`` (or ``T_base_tcp`` with ``tool`` = T_flange_tcp), (4, 4) or (N, 4, 4).

    Examples
    --------
    >>> from solvers.robots import ROBOTS
    >>> T = forward_kinematics(ROBOTS["kuka_kr6_r900_sixx"], [0, 0, 0, 0, 0, 0])
    >>> np.round(T[:3, 3], 3).tolist()  # KR 6 R900 sixx, all axes zero
    [980.0, 0.0, 435.0]
    """
    T = joint_frames(robot, q_deg)[..., -1, :, :] @ robot.mount_matrices()[1]
    return T if tool is None else T @ tool


def joint_axes(robot: RobotModel, frames: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Base-frame unit axis and a point on it for each joint, signed by ``direction``.

    Returns (axes, origins), each (..., n, 3). Standard DH turns joint i about z of frame i-1;
    modified DH about z of frame i.
    """
    sel = frames[..., :-1, :, :] if robot.dh_convention == "standard" else frames[..., 1:, :, :]
    sign = robot.params()["direction"][:, None]
    return sel[..., :3, 2] * sign, sel[..., :3, 3]


def geometric_jacobian(robot: RobotModel, q_deg: object, tool: FloatArray | None = None) -> FloatArray:
    """Geometric Jacobian (6, n) at the TCP: rows vx, vy, vz (mm/rad), wx, wy, wz (rad/rad).

    Column j for a revolute joint: ``[z_j x (p_tcp - o_j); z_j]`` in base coordinates, times
    the coupling so that columns are per controller joint. (..., 6, n) for a stack of q.
    """
    frames = joint_frames(robot, q_deg)
    T = frames[..., -1, :, :] @ robot.mount_matrices()[1]
    if tool is not None:
        T = T @ tool
    z, o = joint_axes(robot, frames)
    lin = np.cross(z, T[..., None, :3, 3] - o)
    J = np.concatenate([np.swapaxes(lin, -1, -2), np.swapaxes(z, -1, -2)], axis=-2)
    return J @ robot.coupling_matrix()


def check_joint_limits(robot: RobotModel, q_deg: object) -> None:
    """Raise :class:`KinematicsError` naming the joint, its value and its limit."""
    q = joint_values(robot, q_deg)
    lim = robot.limits_deg()
    for i, v in enumerate(np.atleast_2d(q)[0] if q.ndim == 1 else q[0]):
        if not lim[i, 0] <= v <= lim[i, 1]:
            raise KinematicsError(("joints_deg", i),
                                  f"A{i + 1} (joint {i + 1}) at {v:.3f} deg is outside its "
                                  f"software limit "
                                  f"[{lim[i, 0]:g}, {lim[i, 1]:g}] deg")


def pose_error(T_is: FloatArray, T_goal: FloatArray) -> FloatArray:
    """6-vector [position error mm, rotation error as rotation vector rad] of ``T_goal`` vs ``T_is``."""
    dp = T_goal[:3, 3] - T_is[:3, 3]
    dr = Rotation.from_matrix(T_goal[:3, :3] @ T_is[:3, :3].T).as_rotvec()
    return np.concatenate([dp, dr])


def inverse_kinematics(robot: RobotModel, T_goal: FloatArray, q_start_deg: object,
                       tool: FloatArray | None = None, position_only: bool = False,
                       tol_mm: float = 1e-6, tol_deg: float = 1e-6) -> FloatArray:
    """Joint values (deg) that put the TCP at ``T_goal``, starting from ``q_start_deg``.

    Bounded Levenberg–Marquardt (trust-region reflective) on the pose error with the analytic
    geometric Jacobian, inside the software limits; the nearest solution to the start is
    found, as a jogging pendant expects. Orientation error is weighted as 1 rad = 1000 mm.

    Raises
    ------
    KinematicsError
        When no joint values inside the limits reach the goal within the tolerances.
    """
    q0 = joint_values(robot, q_start_deg)
    lim = robot.limits_deg()
    goal = as_array(T_goal, "target", (4, 4))
    w = np.array([1, 1, 1, 1000, 1000, 1000.0])
    if position_only:
        w[3:] = 0.0
    deg = np.pi / 180.0

    def residual(q: FloatArray) -> FloatArray:
        return w * pose_error(forward_kinematics(robot, q, tool), goal)

    def jac(q: FloatArray) -> FloatArray:
        return -(w[:, None] * geometric_jacobian(robot, q, tool)) * deg

    lo, hi = lim[:, 0], lim[:, 1]
    q_init = np.clip(q0, lo + 1e-9, hi - 1e-9)
    sol = least_squares(residual, q_init, jac=jac, bounds=(lo, hi), method="trf",
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=200)
    err = pose_error(forward_kinematics(robot, sol.x, tool), goal)
    pos_mm = float(np.linalg.norm(err[:3]))
    rot_deg = float(np.degrees(np.linalg.norm(err[3:])))
    if pos_mm > max(tol_mm, 1e-4) or (not position_only and rot_deg > max(tol_deg, 1e-5)):
        raise KinematicsError(("target",), f"not reachable inside the joint limits: best solution "
                              f"misses by {pos_mm:.3f} mm and {rot_deg:.3f} deg")
    return sol.x


def tcp_of(T_base_flange: FloatArray, tcp_mm: FloatArray) -> FloatArray:
    """TCP position(s) in base of flange pose(s) and a TCP (3,) in the flange frame."""
    return (T_base_flange[..., :3, :3] @ np.asarray(tcp_mm, dtype=float)) + T_base_flange[..., :3, 3]


__all__ = ["DHJoint", "RobotModel", "link_matrices", "joint_frames", "forward_kinematics",
           "geometric_jacobian", "inverse_kinematics", "check_joint_limits", "joint_axes",
           "dh_angles_rad", "joint_values", "tcp_of", "invert"]
