"""Gravity torque on each joint from the links' masses and the payload.

Gravity acts along ``-z`` of the robot base (the frame ``base_pose`` is given in), g = 9.81.
The torque on joint i is what gravity exerts on everything the joint carries::

    tau_i = sum_{links j >= i} (z_i x (c_j - o_i)) . (m_j g)   +   payload term

with ``z_i`` the unit axis of joint i signed by its ``direction`` (so ``tau`` is signed in the
joint's positive sense), ``o_i`` a point on it, ``c_j`` link j's centre of mass, ``g`` the
gravity vector; all from :func:`solvers.dh.joint_frames` / :func:`solvers.dh.joint_axes`.
A coupled arm (FANUC J2/J3) gets the torque per controller joint, ``tau_q = C^T tau_dh``.
Hence ``tau = -dV/dq`` (V the potential energy, q in rad) and a joint of compliance c
(deg/Nm) yields ``dq = c * tau``.

Frame j of either DH convention is fixed to link j, so link j's centre of mass is given in
frame j.

Mass models (:func:`link_masses`):

- UR5e and UR10 (CB3): Universal Robots' published dynamics parameters ("Parameters for
  calculations of kinematics and dynamics"): masses and centres of mass per link, in the
  standard-DH frame of the link.
- The other library arms: an estimate. The arm's published weight (KR 6 R900 sixx 52 kg,
  IRB 120 25 kg, LR Mate 200iD 25 kg, TM5-900 22.6 kg) is split over the links in the
  fixed fractions :data:`GENERIC_FRACTIONS`, each link's mass at the middle of its DH link
  (the segment from the joint's origin to the next). An unknown arm weighs
  ``5 * payload + 10 kg`` (``payload_kg`` of the model; 30 kg when not given).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from solvers.dh import RobotModel, joint_axes, joint_frames, joint_values
from solvers.validate import FloatArray, as_array

G_M_S2 = 9.81

#: Share of the arm's weight carried by links 1..6 (generic estimate).
GENERIC_FRACTIONS = (0.30, 0.30, 0.18, 0.10, 0.07, 0.05)


@dataclass(frozen=True)
class LinkMasses:
    """Mass (kg) of each link and its centre of mass in the link's own DH frame (mm).

    ``com_mm`` None means "the middle of the DH link" (the generic estimate).
    """

    mass_kg: tuple[float, ...]
    com_mm: tuple[tuple[float, float, float], ...] | None
    source: str


_UR10 = LinkMasses(
    mass_kg=(7.1, 12.7, 4.27, 2.0, 2.0, 0.365),
    com_mm=((21.0, 0.0, 27.0), (380.0, 0.0, 158.0), (240.0, 0.0, 68.0), (0.0, 7.0, 18.0),
            (0.0, 7.0, 18.0), (0.0, 0.0, -26.0)),
    source="Universal Robots, dynamics parameters of the UR10 (CB3)")
_UR5E = LinkMasses(
    mass_kg=(3.761, 8.058, 2.846, 1.37, 1.3, 0.365),
    com_mm=((0.0, -25.61, 1.93), (212.5, 0.0, 113.36), (150.0, 0.0, 26.5), (0.0, -1.8, 16.34),
            (0.0, 1.8, 16.34), (0.0, 0.0, -1.159)),
    source="Universal Robots, dynamics parameters of the UR5e")

#: (name pattern, published weight kg) for the estimated arms.
_WEIGHTS_KG = ((r"kr\s*6\s*r900", 52.0), (r"irb\s*120\b", 25.0), (r"lr\s*mate\s*200\s*id", 25.0),
               (r"tm\s*5\s*-?\s*900", 22.6))


def link_masses(robot: RobotModel) -> LinkMasses:
    """The mass model of ``robot``, matched by its name (see the module docstring).

    Examples
    --------
    >>> from solvers.robots import ROBOTS
    >>> link_masses(ROBOTS["ur10"]).mass_kg[1]
    12.7
    >>> round(sum(link_masses(ROBOTS["abb_irb120"]).mass_kg), 6)
    25.0
    """
    name = robot.name.lower()
    if robot.dof == 6 and re.search(r"\bur\s*10\b(?!\s*e)", name):
        return _UR10
    if robot.dof == 6 and re.search(r"\bur\s*5\s*e\b", name):
        return _UR5E
    weight, source = None, ""
    for pattern, kg in _WEIGHTS_KG:
        if re.search(pattern, name):
            weight, source = kg, f"estimate from the published arm weight {kg:g} kg"
    if weight is None:
        weight = 5.0 * (robot.payload_kg or 4.0) + 10.0
        source = f"generic estimate {weight:g} kg = 5 x payload + 10 kg"
    fr = np.array(GENERIC_FRACTIONS[:robot.dof] if robot.dof <= 6 else
                  GENERIC_FRACTIONS + (0.05,) * (robot.dof - 6), dtype=float)
    fr = fr / fr.sum()
    return LinkMasses(mass_kg=tuple(float(m) for m in weight * fr), com_mm=None,
                      source=source + "; each link's mass at the middle of its DH link")


def link_centres_mm(robot: RobotModel, frames: FloatArray, masses: LinkMasses) -> FloatArray:
    """Centres of mass of links 1..n in base, (..., n, 3), from the frames 0..n."""
    if masses.com_mm is not None:
        com = np.asarray(masses.com_mm, dtype=float)
        R, t = frames[..., 1:, :3, :3], frames[..., 1:, :3, 3]
        return np.einsum("...ij,...j->...i", R, np.broadcast_to(com, t.shape)) + t
    o = frames[..., :, :3, 3]
    if robot.dh_convention == "standard":  # link j spans o_{j-1} .. o_j
        return 0.5 * (o[..., :-1, :] + o[..., 1:, :])
    # modified: link j spans o_j .. o_{j+1}; the last link ends at the flange
    flange = (frames[..., -1, :, :] @ robot.flange_pose.as_matrix())[..., :3, 3]
    nxt = np.concatenate([o[..., 2:, :], flange[..., None, :]], axis=-2)
    return 0.5 * (o[..., 1:, :] + nxt)


def gravity_torques(robot: RobotModel, joints_deg: object, payload_mass_kg: float = 0.0,
                    payload_com_mm: object = (0.0, 0.0, 0.0),
                    masses: LinkMasses | None = None) -> FloatArray:
    """Gravity torque (Nm) on each joint, signed in the joint's positive direction.

    ``tau_i = sum_{j >= i} (z_i x (c_j - o_i)) . (m_j g)`` over the links and the payload
    (mass ``payload_mass_kg`` at ``payload_com_mm`` in the flange frame), g = 9.81 m/s^2
    along ``-z`` of the robot base. ``tau = -dV/dq`` with q in radians.

    Parameters
    ----------
    robot : RobotModel
    joints_deg : array_like, shape (n,) or (N, n)
        Controller joint values.
    payload_mass_kg : float
    payload_com_mm : array_like, shape (3,)
    masses : LinkMasses, optional
        The arm's link masses (a recording's ``robot.link_masses``); default
        :func:`link_masses` of the robot (its catalogue entry or a generic estimate).

    Returns
    -------
    ndarray, shape (n,) or (N, n)
        Nm per joint.

    Examples
    --------
    A horizontal two-link arm of 1 m links, joint axes along -y (base turned by c = 90 deg):
    the generic model gives each link 15 kg at its middle; 2 kg payload at the tip. Joint 1
    carries 15 kg at 0.5 m, 15 kg at 1.5 m and 2 kg at 2 m: tau_1 = -9.81 (7.5 + 22.5 + 4);
    gravity turns the arm towards negative joint angles (down).

    >>> from solvers.dh import DHJoint
    >>> from solvers.frames import Pose
    >>> arm = RobotModel("two links", "standard", (DHJoint(1000, 0, 0), DHJoint(1000, 0, 0)),
    ...                  base_pose=Pose(c=90))
    >>> np.round(gravity_torques(arm, [0, 0], 2.0), 3).tolist()
    [-333.54, -93.195]
    """
    q = joint_values(robot, joints_deg)
    com_pay = as_array(payload_com_mm, "payload_com_mm", (3,))
    masses = link_masses(robot) if masses is None else masses
    frames = joint_frames(robot, q)
    axes, origins = joint_axes(robot, frames)                     # (..., n, 3)
    centres = link_centres_mm(robot, frames, masses)              # (..., n, 3)
    m = np.asarray(masses.mass_kg, dtype=float)
    flange = frames[..., -1, :, :] @ robot.flange_pose.as_matrix()
    c_pay = np.einsum("...ij,j->...i", flange[..., :3, :3], com_pay) + flange[..., :3, 3]
    g = np.array([0.0, 0.0, -G_M_S2])
    n = robot.dof
    tau = np.zeros(q.shape)
    for i in range(n):
        z, o = axes[..., i, :], origins[..., i, :]
        arm = centres[..., i:, :] - o[..., None, :]              # links j >= i
        lever = np.cross(z[..., None, :], arm)                   # (..., n-i, 3)
        tau[..., i] = np.einsum("...kj,j,k->...", lever, g, m[i:]) / 1000.0
        tau[..., i] += payload_mass_kg * (np.cross(z, c_pay - o) @ g) / 1000.0
    return tau @ robot.coupling_matrix()


def potential_energy_j(robot: RobotModel, joints_deg: object, payload_mass_kg: float = 0.0,
                       payload_com_mm: object = (0.0, 0.0, 0.0),
                       masses: LinkMasses | None = None) -> FloatArray:
    """Potential energy (J) of the links and payload, ``V = sum m g z``; ``tau = -dV/dq``
    (``masses`` as for :func:`gravity_torques`)."""
    q = joint_values(robot, joints_deg)
    com_pay = as_array(payload_com_mm, "payload_com_mm", (3,))
    masses = link_masses(robot) if masses is None else masses
    frames = joint_frames(robot, q)
    centres = link_centres_mm(robot, frames, masses)
    flange = frames[..., -1, :, :] @ robot.flange_pose.as_matrix()
    c_pay = np.einsum("...ij,j->...i", flange[..., :3, :3], com_pay) + flange[..., :3, 3]
    m = np.asarray(masses.mass_kg, dtype=float)
    return G_M_S2 * (centres[..., 2] @ m + payload_mass_kg * c_pay[..., 2]) / 1000.0


__all__ = ["G_M_S2", "GENERIC_FRACTIONS", "LinkMasses", "link_masses", "link_centres_mm",
           "gravity_torques", "potential_energy_j"]
