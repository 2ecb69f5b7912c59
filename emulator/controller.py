"""The emulated robot and cell: what the pendant drives, and the hidden truth calibration finds.

A controller knows its arm (DH table) and its tool and base tables. The *cell* holds what
the controller does not know: the physical pointer on the flange (its true TCP), a reference
tip, a base plate with marked points, an external fixed tool, a robot-held workpiece and a
crossed-beam light barrier. The cell is built from the controller's ``cell_seed`` (so it
survives a restart without being stored) and scaled to the arm's reach.

Motion is what a person does on the pendant: joint and Cartesian jogs with increments, and
:func:`approach`, the careful jogging that puts a point of the true tool (or workpiece) onto a
cell target from a chosen orientation. Kinematics go through :mod:`solvers.dh`.

The arm itself can be imperfect too (:class:`RobotPhysics`, the controller's hidden
:class:`solvers.physics.Imperfections`, its emulated clock and the direction each joint last
moved). The controller always moves on its nominal model and shows the commanded joints;
the TRUE pose is :func:`solvers.physics.true_tcp_poses` of them. :func:`approach` puts the
true tip on the target (Newton on the true pose, as :mod:`solvers.simulate` does), and
:func:`run_beam_cycle` switches the beams with the true tool and records the pose the
trigger latency later. With the default (rigid, no noise) nothing changes. See
docs/emulator.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.dh import (DHJoint, RobotModel, check_joint_limits, forward_kinematics,
                        geometric_jacobian, inverse_kinematics)
from solvers.errors import CalibrationError, KinematicsError
from solvers.frames import Pose, invert, rotation_matrix
from solvers.physics import Imperfections, tool_deflection_mm, true_flange_poses
from solvers.robots import ROBOTS
from solvers.simulate import solve_pose_newton
from solvers.validate import FloatArray

JogMode = Literal["joint", "world", "base", "tool"]
CARTESIAN_AXES = ("X", "Y", "Z", "A", "B", "C")  # A about Z, B about Y, C about X (KUKA)
DEMO_ROBOT = "kuka_kr6_r900_sixx"

HOME_DEG: dict[str, tuple[float, ...]] = {
    "kuka_kr6_r900_sixx": (0.0, -90.0, 90.0, 0.0, 90.0, 0.0),
}


def robot_from_custom(doc: dict) -> RobotModel:
    """A RobotModel from a custom DH document (the API's ``RobotIn``, already validated)."""
    joints = tuple(DHJoint(a_mm=j["a_mm"], alpha_deg=j["alpha_deg"], d_mm=j["d_mm"],
                           offset_deg=j.get("offset_deg", 0.0),
                           direction=int(j.get("direction", 1)),
                           q_min_deg=j.get("q_min_deg", -360.0),
                           q_max_deg=j.get("q_max_deg", 360.0))
                   for j in doc["joints"])
    reach = doc.get("reach_mm") or sum(abs(j.a_mm) + abs(j.d_mm) for j in joints[1:])
    return RobotModel(name=doc.get("name") or "custom", dh_convention=doc["dh_convention"],
                      joints=joints,
                      base_pose=Pose(**doc.get("base_pose") or {}),
                      flange_pose=Pose(**doc.get("flange_pose") or {}),
                      source="custom DH table", reach_mm=float(reach))


def rot(seq: str, angles_deg: object) -> FloatArray:
    """3x3 rotation of intrinsic Euler angles ``seq`` (upper case = intrinsic), degrees."""
    return Rotation.from_euler(seq, angles_deg, degrees=True).as_matrix()


def approach_rotation(tilt_deg: float, around_deg: float, spin_deg: float = 0.0) -> FloatArray:
    """Orientation of the held frame relative to a target frame when touching it.

    ``R = Rz(around) @ Ry(tilt) @ Rx(180) @ Rz(spin)``: with tilt 0 the held frame's +z
    (the tool axis) points along the target's -z (straight into it); ``tilt_deg`` leans the
    axis away from that by tilt, towards azimuth ``around_deg``; ``spin_deg`` turns the tool
    about its own axis.
    """
    return rot("Z", around_deg) @ rot("Y", tilt_deg) @ rot("X", 180.0) @ rot("Z", spin_deg)


@dataclass(frozen=True)
class Target:
    """Where a held point must go: ``point_mm`` in world, the target frame ``R_world_target``.

    ``held`` says which body carries the point (``tool`` = the pointer, ``workpiece`` = the
    robot-held workpiece, ``flange`` = the bare flange, for alignment steps) and
    ``held_point_mm`` where on it (in that body's frame). ``align`` targets fix the full
    orientation (``R_world_held``) instead of an approach direction.
    """

    name: str
    point_mm: FloatArray
    R_world_target: FloatArray
    held: Literal["tool", "workpiece", "flange"] = "tool"
    held_point_mm: FloatArray = field(default_factory=lambda: np.zeros(3))
    align: bool = False


@dataclass(frozen=True)
class Beam:
    id: str
    point_mm: FloatArray
    direction: FloatArray


@dataclass(frozen=True)
class Cell:
    """The hidden truth of one emulated cell (mm, world = robot base)."""

    T_flange_tool: FloatArray  # the pointer actually mounted (true TCP)
    tool_diameter_mm: float
    reference_tip_mm: FloatArray
    T_world_plate: FloatArray  # the base plate
    plate_points_mm: dict[str, FloatArray]  # marked points in plate coordinates (drawing)
    T_world_fixedtool: FloatArray
    T_flange_workpiece: FloatArray
    workpiece_points_mm: dict[str, FloatArray]  # marked points in workpiece coordinates
    beams: tuple[Beam, ...]
    fixed_tool_standoff_mm: float = 250.0

    def target_names(self) -> list[str]:
        names = ["reference_tip", "fixed_tool", "fixed_tool_align", "world_axes"]
        names += [f"base_{k}" for k in self.plate_points_mm]
        names += [f"workpiece_{k}" for k in self.workpiece_points_mm]
        return names

    def target(self, name: str) -> Target:
        """The target called ``name``; raises KinematicsError(("target",)) for an unknown one."""
        I3 = np.eye(3)
        if name == "reference_tip" or name == "world_axes":
            return Target(name, self.reference_tip_mm, I3)
        if name == "fixed_tool":
            return Target(name, self.T_world_fixedtool[:3, 3], self.T_world_fixedtool[:3, :3])
        if name == "fixed_tool_align":  # flange axes parallel to the fixed tool: R_E_F = Rx(180)
            R = self.T_world_fixedtool[:3, :3] @ rot("X", 180.0)
            E = self.T_world_fixedtool
            p = E[:3, :3] @ [0.0, 0.0, self.fixed_tool_standoff_mm] + E[:3, 3]
            return Target(name, p, R, held="flange", align=True)
        if name.startswith("base_") and name[5:] in self.plate_points_mm:
            P = self.T_world_plate
            p = P[:3, :3] @ self.plate_points_mm[name[5:]] + P[:3, 3]
            return Target(name, p, self.T_world_plate[:3, :3])
        if name.startswith("workpiece_") and name[10:] in self.workpiece_points_mm:
            # a marked point of the held workpiece brushed onto the fixed tool's tip; the
            # workpiece's surface normal (+z) faces the fixed tool's axis
            return Target(name, self.T_world_fixedtool[:3, 3], self.T_world_fixedtool[:3, :3],
                          held="workpiece", held_point_mm=self.workpiece_points_mm[name[10:]])
        raise KinematicsError(("target",), f"unknown target {name!r}; the cell has: "
                              f"{', '.join(self.target_names())}")

    def public(self) -> dict:
        """What the person at the cell knows from drawings: target names, the plate's and the
        workpiece's marked points in their own coordinates, the light barrier's beams."""
        return {"targets": self.target_names(),
                "base_points_mm": {k: v.tolist() for k, v in self.plate_points_mm.items()},
                "workpiece_points_mm": {k: v.tolist() for k, v in self.workpiece_points_mm.items()},
                "beams": [{"id": b.id, "point_mm": b.point_mm.tolist(),
                           "direction": b.direction.tolist()} for b in self.beams],
                "tool_diameter_mm": self.tool_diameter_mm}


@lru_cache(maxsize=64)
def build_cell(robot_name: str, reach_mm: float, seed: int) -> Cell:
    """The cell of a controller: fixed layout scaled to the reach, small seeded variations."""
    rng = np.random.default_rng(seed)
    s = (reach_mm or 901.0) / 901.0  # layout drawn for the KR 6 R900 sixx
    T_flange_tool = rotation_matrix(Rotation.from_euler("ZYX", [12.0, 1.2, -0.8], degrees=True),
                                    [2.5 + rng.uniform(-1, 1), -1.5 + rng.uniform(-1, 1),
                                     181.0 + rng.uniform(-1, 1)])
    plate_abc = [20.0 + rng.uniform(-5, 5), 1.5, -1.0]
    plate = rotation_matrix(Rotation.from_euler("ZYX", plate_abc, degrees=True),
                            np.array([430.0, 120.0, 60.0]) * s)
    plate_points = {"origin": [0, 0, 0], "x": [200, 0, 0], "xy": [60, 150, 0],
                    "point_1": [30, 30, 0], "point_2": [220, 20, 0], "point_3": [190, 160, 0],
                    "point_4": [20, 170, 0], "point_5": [110, 90, 25]}
    fixed = rotation_matrix(Rotation.from_euler("ZYX", [35.0, 15.0, -10.0], degrees=True),
                            np.array([520.0, -300.0, 180.0]) * s)
    workpiece = rotation_matrix(Rotation.from_euler("ZYX", [30.0, 2.0, -1.5], degrees=True),
                                [60.0, -40.0, 90.0])
    wp_points = {"origin": [0, 0, 0], "x": [120, 0, 0], "xy": [40, 80, 0],
                 "point_1": [10, 10, 0], "point_2": [110, 15, 0], "point_3": [100, 70, 0],
                 "point_4": [15, 75, 0]}
    cross = np.array([450.0, 0.0, 200.0]) * s + [0.0, -150.0 * s, 0.0]
    beams = (Beam("bx", cross, np.array([1.0, 0.0, 0.0])),
             Beam("by", cross, np.array([0.0, 1.0, 0.0])))
    return Cell(T_flange_tool=T_flange_tool, tool_diameter_mm=6.0,
                reference_tip_mm=np.array([480.0, -120.0, 120.0]) * s,
                T_world_plate=plate,
                plate_points_mm={k: np.array(v, float) for k, v in plate_points.items()},
                T_world_fixedtool=fixed, T_flange_workpiece=workpiece,
                workpiece_points_mm={k: np.array(v, float) for k, v in wp_points.items()},
                beams=beams)


def cell_for(robot: RobotModel, seed: int) -> Cell:
    return build_cell(robot.name, float(robot.reach_mm), int(seed))


@lru_cache(maxsize=64)
def _home(robot: RobotModel) -> tuple[float, ...]:
    """Joint values with the flange pointing down in front of the arm (a pendant's HOME)."""
    key = next((k for k, r in ROBOTS.items() if r == robot), None)
    if key in HOME_DEG:
        return HOME_DEG[key]
    reach = robot.reach_mm or 900.0
    goal = rotation_matrix(rot("X", 180.0), [0.5 * reach, 0.0, 0.45 * reach])
    rng = np.random.default_rng(0)
    lim = robot.limits_deg()
    lo, hi = np.maximum(lim[:, 0], -180.0), np.minimum(lim[:, 1], 180.0)
    beyond = lo > hi  # a joint whose whole range lies beyond +-180 deg: start inside its range
    lo[beyond], hi[beyond] = lim[beyond, 0], lim[beyond, 1]
    zero = np.clip(np.zeros(robot.dof), lim[:, 0], lim[:, 1])  # 0, or the limit nearest to it
    starts = [zero] + [rng.uniform(lo, hi) for _ in range(30)]
    for q0 in starts:
        try:
            return tuple(float(x) for x in inverse_kinematics(robot, goal, q0))
        except KinematicsError:
            continue
    return tuple(float(x) for x in zero)


def home_joints(robot: RobotModel) -> list[float]:
    return list(_home(robot))


def solve_ik(robot: RobotModel, T_goal: FloatArray, q_now: FloatArray,
             tool: FloatArray | None) -> FloatArray:
    """Joint values reaching ``T_goal`` nearest to ``q_now``; tries the current joints, HOME and
    HOME turned towards the goal. Raises KinematicsError naming the target."""
    home = np.array(_home(robot))
    starts = [np.asarray(q_now, float), home]
    az = np.degrees(np.arctan2(T_goal[1, 3], T_goal[0, 3]))
    for a1 in (az, -az):  # HOME turned towards the goal (either sense of A1)
        h = home.copy()
        h[0] = np.clip(a1, *robot.limits_deg()[0])
        starts.append(h)
    best: FloatArray | None = None
    last: KinematicsError | None = None
    for q0 in starts:
        try:
            q = inverse_kinematics(robot, T_goal, q0, tool=tool)
        except KinematicsError as err:
            last = err
            continue
        if best is None or np.linalg.norm(q - q_now) < np.linalg.norm(best - q_now):
            best = q
        if best is not None and q0 is starts[0]:
            break
    if best is None:
        raise last or KinematicsError(("target",), "not reachable")
    return best


# ---------------------------------------------------------------- the arm's hidden physics

#: Thermal drift: ``thermal_drift_mm`` is the base shift reached after this much emulated time
#: since power-on (the warm-up); it grows linearly until then and stays afterwards.
THERMAL_WARMUP_S = 3600.0
#: The emulated clock's motion times (deterministic, no wall time): a move takes
#: ``MOVE_OVERHEAD_S + max(joint travel / JOINT_SPEED_DEG_S, TCP travel / CART_SPEED_MM_S)``;
#: an approach (a person jogging carefully onto a mark) adds ``APPROACH_S``; a touch-up
#: (press, confirm) takes ``TOUCH_UP_S``.
JOINT_SPEED_DEG_S = 30.0
CART_SPEED_MM_S = 250.0
MOVE_OVERHEAD_S = 0.5
APPROACH_S = 20.0
TOUCH_UP_S = 2.0
#: The light-barrier cycle: pause between passes (positioning to the next pass start).
CYCLE_PASS_GAP_S = 2.0
SIGN_EPS_DEG = 1e-9  # a joint that moved less than this did not move (keeps its gear flank)
PER_JOINT = ("joint_offset_deg", "compliance_deg_per_Nm", "backlash_deg")


@dataclass(frozen=True)
class RobotPhysics:
    """The emulated arm's hidden state: how it differs from its model, and where it stands.

    ``imperfections`` the hidden physics; ``clock_s`` emulated seconds since the cell was
    powered (thermal drift); ``motion_sign`` (n,) the direction each joint last moved
    (+1, -1, 0 = unknown: backlash); the payload the controller's active tool carries
    (compliance, tool bending); ``noise_seed`` seeds the operator's aim (``noise_mm``).
    """

    imperfections: Imperfections
    clock_s: float
    motion_sign: FloatArray
    payload_mass_kg: float = 0.0
    payload_com_mm: FloatArray = field(default_factory=lambda: np.zeros(3))
    noise_seed: tuple[int, ...] = (0,)

    @property
    def rigid(self) -> bool:
        """No effect and no noise: the emulator is the controller's model exactly."""
        return self.imperfections.is_rigid() and self.imperfections.noise_mm == 0

    def rng(self, *extra: int) -> np.random.Generator:
        return np.random.default_rng([*self.noise_seed, *extra])

    def thermal_t_s(self, t_s: float) -> float:
        return float(min(max(t_s, 0.0), THERMAL_WARMUP_S))


def rigid_physics(dof: int) -> RobotPhysics:
    return RobotPhysics(Imperfections(), 0.0, np.zeros(dof))


def imperfections_from_document(doc: dict, dof: int) -> Imperfections:
    """Checked :class:`Imperfections` of the API's physics document (JSON keys as
    :meth:`Imperfections.from_dict`; ``None`` values = not set) for an arm of ``dof`` joints.

    Raises CalibrationError naming the field: an unknown field, a per-joint list of the wrong
    length, a non-finite number, an unknown DH parameter or joint, a negative backlash,
    compliance, latency, bending or noise, a zero thermal direction.
    """
    d = {k: v for k, v in doc.items() if v is not None}
    imp = Imperfections.from_dict(d)
    for name in PER_JOINT:
        value = getattr(imp, name)
        if value is not None and len(value) != dof:
            raise CalibrationError((name,), f"has {len(value)} values; the robot has {dof} joints")
    imp.check(dof)
    if np.any(imp.per_joint("compliance_deg_per_Nm", dof) < 0):
        raise CalibrationError(("compliance_deg_per_Nm",), "a joint's compliance must be >= 0")
    for name in ("trigger_latency_ms", "tool_deflection_mm_per_N"):
        if getattr(imp, name) < 0:
            raise CalibrationError((name,), "must be >= 0")
    return imp


def imperfections_document(imp: Imperfections) -> dict:
    """The JSON document of :class:`Imperfections` (every field; ``dh_delta`` keys
    ``"a_mm:2"``, ``cyclic_error`` keys ``"3"``): what ``GET .../cell/physics`` returns."""
    def per_joint(v: object) -> list[float] | None:
        return None if v is None else [float(x) for x in v]  # type: ignore[union-attr]

    return {"joint_offset_deg": per_joint(imp.joint_offset_deg),
            "dh_delta": {f"{p}:{j}": float(v) for (p, j), v in imp.dh_delta.items()},
            "compliance_deg_per_Nm": per_joint(imp.compliance_deg_per_Nm),
            "backlash_deg": per_joint(imp.backlash_deg),
            "thermal_drift_mm": float(imp.thermal_drift_mm),
            "thermal_direction": [float(x) for x in imp.thermal_direction],
            "trigger_latency_ms": float(imp.trigger_latency_ms),
            "tool_deflection_mm_per_N": float(imp.tool_deflection_mm_per_N),
            "cyclic_error": {str(j): [float(a), float(k)]
                             for j, (a, k) in imp.cyclic_error.items()},
            "noise_mm": float(imp.noise_mm)}



def updated_signs(motion_sign: object, q_from: object, q_to: object) -> FloatArray:
    """Direction each joint last moved after moving from ``q_from`` to ``q_to``: the sign of
    the move, or the old sign for a joint that did not move (its gear stays on its flank)."""
    dq = np.asarray(q_to, float) - np.asarray(q_from, float)
    old = np.asarray(motion_sign, float)
    return np.where(np.abs(dq) > SIGN_EPS_DEG, np.sign(dq), old)


def motion_duration_s(robot: RobotModel, q_from: object, q_to: object) -> float:
    """Emulated time of a move (see :data:`JOINT_SPEED_DEG_S`, :data:`CART_SPEED_MM_S`)."""
    a, b = np.asarray(q_from, float), np.asarray(q_to, float)
    if np.allclose(a, b, atol=SIGN_EPS_DEG, rtol=0):
        return 0.0
    travel_mm = float(np.linalg.norm(forward_kinematics(robot, b)[:3, 3]
                                     - forward_kinematics(robot, a)[:3, 3]))
    return MOVE_OVERHEAD_S + max(float(np.abs(b - a).max()) / JOINT_SPEED_DEG_S,
                                 travel_mm / CART_SPEED_MM_S)


def true_pose(robot: RobotModel, physics: RobotPhysics, q_from: object, q: object,
              T_flange_held: FloatArray | None = None, bends: bool = False,
              t_s: float | None = None) -> FloatArray:
    """TRUE ``T_world_held`` (4, 4) when the controller shows ``q``, having come from ``q_from``.

    The real flange (:func:`solvers.physics.true_flange_poses`: backlash on the flank of this
    move, cyclic error, compliance under the arm's weight and the payload, joint offsets, DH
    errors, thermal drift at the clock ``t_s``, default ``physics.clock_s``), then the held
    body ``T_flange_held`` (default: the bare flange); ``bends`` = the held body is the tool,
    whose tip bends under the payload (:func:`solvers.physics.tool_deflection_mm`).
    """
    q = np.asarray(q, float)
    signs = updated_signs(physics.motion_sign, q_from, q)
    t = physics.thermal_t_s(physics.clock_s if t_s is None else t_s)
    T = true_flange_poses(robot, q[None], [t], physics.imperfections, q - signs,
                          physics.payload_mass_kg, physics.payload_com_mm,
                          time_span_s=(0.0, THERMAL_WARMUP_S))[0]
    if T_flange_held is not None:
        T = T @ T_flange_held
    if bends:
        T[:3, 3] += tool_deflection_mm(T[None], physics.imperfections, physics.payload_mass_kg)[0]
    return T


def approach(robot: RobotModel, cell: Cell, q_now: FloatArray, target: str | Target,
             tilt_deg: float = 0.0, around_deg: float = 0.0, spin_deg: float = 0.0,
             tool_point_mm: FloatArray | None = None,
             miss_mm: FloatArray | None = None,
             physics: RobotPhysics | None = None) -> FloatArray:
    """Joint values that put the held point onto ``target`` from the given orientation.

    The true tool (or workpiece) is used: this is what a person sees when jogging the
    physical tip onto the mark. ``tool_point_mm`` picks another point of the held body
    (in its own frame; default its origin, the tip). ``miss_mm`` deliberately misses the
    target by that vector (world), like a sloppy touch-up.

    With ``physics`` (an imperfect arm), the TRUE held point goes onto the target: inverse
    kinematics on the nominal model, then Newton steps on the true pose (the nominal
    Jacobian, :func:`solvers.simulate.solve_pose_newton`), the move's backlash flank taken from
    ``q_now``, the thermal drift at the clock when the approach ends (``physics.clock_s`` +
    the move + :data:`APPROACH_S`, as the route advances it). The operator stops
    ``noise_mm`` (per axis, seeded by ``physics.noise_seed``) off the mark. The joints
    returned are the commanded ones, what the controller shows. ``target`` is a cell target's
    name or a :class:`Target` (an external axis' mark: :func:`emulator.external.target`).
    """
    t = target if isinstance(target, Target) else cell.target(target)
    if t.align:
        T_goal = rotation_matrix(t.R_world_target @ rot("Z", spin_deg), t.point_mm)
        q = solve_ik(robot, T_goal, q_now, tool=None)
        return q if physics is None or physics.rigid else _true_newton(
            robot, physics, q_now, q, T_goal, np.eye(4), False)
    T_flange_held = cell.T_flange_tool if t.held == "tool" else cell.T_flange_workpiece
    held_point = t.held_point_mm if tool_point_mm is None else np.asarray(tool_point_mm, float)
    R = t.R_world_target @ approach_rotation(tilt_deg, around_deg, spin_deg)
    point = t.point_mm + (np.zeros(3) if miss_mm is None else np.asarray(miss_mm, float))
    if physics is not None and physics.imperfections.noise_mm > 0:
        point = point + physics.rng().normal(0.0, physics.imperfections.noise_mm, 3)
    T_goal = rotation_matrix(R, point - R @ held_point)
    q = solve_ik(robot, T_goal, q_now, tool=T_flange_held)
    if physics is None or physics.imperfections.is_rigid():
        return q
    return _true_newton(robot, physics, q_now, q, T_goal, T_flange_held, t.held == "tool")


def _true_newton(robot: RobotModel, physics: RobotPhysics, q_now: FloatArray, q_nominal: FloatArray,
                 T_goal: FloatArray, T_flange_held: FloatArray, bends: bool) -> FloatArray:
    """Commanded joints whose TRUE held pose is ``T_goal``, from the nominal solution; the
    arm as it is when the approach ends (clock + move time + :data:`APPROACH_S`)."""
    arrival = physics.clock_s + motion_duration_s(robot, q_now, q_nominal) + APPROACH_S
    physics = replace(physics, clock_s=arrival)
    q = solve_pose_newton(lambda x: true_pose(robot, physics, q_now, x, T_flange_held, bends),
                lambda x: geometric_jacobian(robot, x, T_flange_held), T_goal, q_nominal,
                tol_mm=1e-7)
    check_joint_limits(robot, q)
    return q

def jog(robot: RobotModel, q_now: FloatArray, mode: JogMode, axis: str, increment: float,
        T_flange_tool: FloatArray, T_world_base: FloatArray) -> FloatArray:
    """One jog increment: ``axis`` 'A1'..'A6' in joint mode (deg), else 'X','Y','Z' (mm) or
    'A','B','C' (deg, about Z, Y, X) in world, base or tool coordinates of the active tool."""
    q = np.asarray(q_now, float).copy()
    if mode == "joint":
        i = int(axis[1:]) - 1
        q[i] += increment
        check_joint_limits(robot, q)
        return q
    T = forward_kinematics(robot, q, T_flange_tool)  # T_world_tcp
    k = CARTESIAN_AXES.index(axis)
    R_frame = {"world": np.eye(3), "base": T_world_base[:3, :3], "tool": T[:3, :3]}[mode]
    goal = T.copy()
    if k < 3:
        goal[:3, 3] += R_frame[:, k] * increment
    else:
        u = R_frame[:, {"A": 2, "B": 1, "C": 0}[axis]]
        goal[:3, :3] = Rotation.from_rotvec(u * np.radians(increment)).as_matrix() @ T[:3, :3]
    try:
        return inverse_kinematics(robot, goal, q, tool=T_flange_tool)
    except KinematicsError as err:
        # name the joint that would leave its range: a linear step predicts which
        J = geometric_jacobian(robot, q, T_flange_tool)
        dx = np.concatenate([goal[:3, 3] - T[:3, 3],
                             Rotation.from_matrix(goal[:3, :3] @ T[:3, :3].T).as_rotvec()])
        dq = np.degrees(np.linalg.lstsq(J, dx, rcond=None)[0])
        check_joint_limits(robot, q + dq)
        raise KinematicsError(("increment",),
                              f"{mode} {axis} {increment:+g}: {err.reason}") from None


def tcp_pose(robot: RobotModel, q: FloatArray, T_flange_tool: FloatArray,
             T_world_base: FloatArray) -> FloatArray:
    """T_base_tcp: the active TCP in the active base, as the pendant's Cartesian display."""
    return invert(T_world_base) @ forward_kinematics(robot, q, T_flange_tool)


@dataclass(frozen=True)
class CycleRun:
    """The light-barrier cycle as the emulated robot ran it: every beam trigger in order.

    ``triggers[k].T_base_flange`` is the pose the controller recorded (the commanded pose the
    trigger latency after the true trigger), ``trigger_joints_deg[k]`` its joints,
    ``trigger_t_s[k]`` the emulated clock then and ``trigger_signs[k]`` the direction each
    joint last moved. ``joints_deg``, ``motion_sign`` and ``clock_s``: the robot afterwards.
    """

    triggers: list  # solvers.beam_cycle.BeamTrigger
    passes: int
    joints_deg: FloatArray  # where the robot stopped
    trigger_joints_deg: FloatArray
    trigger_t_s: FloatArray
    trigger_signs: FloatArray
    motion_sign: FloatArray
    clock_s: float


CYCLE_NODES = 7  # true-pose samples per pass (the error between them is interpolated)


@dataclass
class _CycleRobot:
    """The emulated robot while it runs the cycle: joints, flank signs, clock, recordings."""

    robot: RobotModel
    cell: Cell
    physics: RobotPhysics
    beams: dict
    tool_diameter_mm: float
    q: FloatArray
    signs: FloatArray
    clock_s: float
    rng: np.random.Generator
    records: list = field(default_factory=list)  # (BeamTrigger, q, t_s, signs)

    def run(self, p) -> list:  # noqa: ANN001  (a solvers.beam_cycle.PlannedPass)
        """Move to the pass start, run the pass; the triggers as the controller records them."""
        from solvers.beam_cycle import BeamTrigger, jittered_s, refine_trigger, trigger_events

        robot, imp = self.robot, self.physics.imperfections
        q_start = solve_ik(robot, p.start_flange, self.q, tool=None)
        self.clock_s += motion_duration_s(robot, self.q, q_start) + CYCLE_PASS_GAP_S
        self.signs = updated_signs(self.signs, self.q, q_start)
        q_end = solve_ik(robot, p.end_flange, q_start, tool=None)
        pass_signs = updated_signs(self.signs, q_start, q_end)
        t0, duration = self.clock_s, p.duration_s
        # the one trigger simulator (solvers.beam_cycle): bracketed on the true flange path
        # interpolated, each trigger then moved onto the exact true arm; latency and jitter there
        exact = guide = None
        if not replace(imp, trigger_latency_ms=0.0).is_rigid():
            exact, guide = self._true_flange_along(p, q_start, pass_signs, t0)
        tool = self.cell.T_flange_tool
        truth = (tool[:3, 3], tool[:3, 2], self.beams, self.tool_diameter_mm)
        events = trigger_events(guide, p, *truth, latency_ms=imp.trigger_latency_ms)
        if p.kind == "tip":
            events = events[:1]
        out = []
        q_rec = q_start
        for ev in events:
            if exact is not None:
                ev = refine_trigger(ev, exact, p, *truth, latency_ms=imp.trigger_latency_ms)
            s_rec = jittered_s(ev.s, p, imp.noise_mm, self.rng)
            T_rec = p.pose_at(s_rec)  # the controller records its commanded pose
            q_rec = solve_ik(robot, T_rec, q_rec, tool=None)
            rec = BeamTrigger(s_rec, ev.beam_id, ev.edge, T_rec, ev.tcp_velocity_mm_s)
            self.records.append((rec, q_rec, t0 + s_rec * duration,
                                 updated_signs(self.signs, q_start, q_rec)))
            out.append(rec)
        if p.kind == "tip" and out:  # the search stops at the trigger
            self.q, self.clock_s = q_rec, t0 + out[-1].s * duration
            self.signs = updated_signs(self.signs, q_start, q_rec)
        else:
            self.q, self.clock_s, self.signs = q_end, t0 + duration, pass_signs
        return out

    def _true_flange_along(self, p, q_start: FloatArray, signs: FloatArray,  # noqa: ANN001
                           t0: float):  # noqa: ANN202
        """Two functions s -> TRUE T_base_flange (the tip's bending folded in) while the
        controller moves the flange along ``p``: the exact one (an IK and the physics per
        call) and a cheap guide, exact at CYCLE_NODES points with the small error transform
        between them interpolated linearly."""
        robot, phys = self.robot, replace(self.physics, motion_sign=signs)
        tool = self.cell.T_flange_tool
        seed = [q_start]

        def exact(s: float) -> FloatArray:
            seed[0] = solve_ik(robot, p.pose_at(float(s)), seed[0], tool=None)
            T = true_pose(robot, phys, seed[0], seed[0], t_s=t0 + float(s) * p.duration_s)
            T[:3, 3] += tool_deflection_mm((T @ tool)[None], phys.imperfections,
                                           phys.payload_mass_kg)[0]
            return T

        nodes = np.linspace(0.0, 1.0, CYCLE_NODES)
        err = []
        for s in nodes:
            E = exact(float(s)) @ invert(p.pose_at(float(s)))
            err.append(np.concatenate([Rotation.from_matrix(E[:3, :3]).as_rotvec(), E[:3, 3]]))
        table = np.array(err)

        def guide(s: float) -> FloatArray:
            e = np.array([np.interp(s, nodes, table[:, i]) for i in range(6)])
            E = rotation_matrix(Rotation.from_rotvec(e[:3]), e[3:])
            return E @ p.pose_at(s)

        return exact, guide


def run_beam_cycle(robot: RobotModel, cell: Cell, q_now: FloatArray, nominal_tool: FloatArray,
                   beams: dict[str, tuple[FloatArray, FloatArray]], tool_diameter_mm: float,
                   heights_mm: tuple[float, ...] = (10.0, 40.0),
                   physics: RobotPhysics | None = None) -> CycleRun:
    """Run the measuring cycle on the emulated robot with the emulated sensor.

    Sweeps planned for the nominal tool (solvers.beam_cycle.plan_cycle), beams switched by
    the TRUE tool (trigger_events), then the tip search aimed with the shaft axis the sweeps
    measured (solvers.light_barrier.shaft_axis_from_sweeps), as the paper's cycle does.
    Every pass start is checked reachable inside the joint limits.

    With ``physics`` the flange follows the TRUE arm (trigger_events on the true flange path
    interpolated, refine_trigger on the exact one, while the controller moves the nominal
    one), the controller records the pose ``trigger_latency_ms`` after the trigger (the
    format's latency: the true pose of the recorded joints, moved back by ``v L``, meets the
    trigger condition), jittered along the motion by ``noise_mm``, and the clock advances by
    each pass's duration (plan speed) plus :data:`CYCLE_PASS_GAP_S`.
    """
    from solvers.beam_cycle import plan_cycle
    from solvers.light_barrier import shaft_axis_from_sweeps

    phys = physics or rigid_physics(robot.dof)
    center = next(iter(beams.values()))[0]
    plan = plan_cycle(beams, tool_diameter_mm, center, list(heights_mm), nominal_tool=nominal_tool)
    arm = _CycleRobot(robot, cell, phys, beams, tool_diameter_mm, np.asarray(q_now, float),
                      np.asarray(phys.motion_sign, float), float(phys.clock_s), phys.rng(1))
    events = []
    sweeps = [p for p in plan if p.kind == "sweep"]
    for p in sweeps:
        events += arm.run(p)
    if not events:
        raise KinematicsError(("params", "nominal_tool"), "no beam was cut during the sweeps: is "
                              "the nominal TCP near the true one and the sensor where the beams "
                              "say?")
    axis = shaft_axis_from_sweeps([e.T_base_flange for e in events], [e.beam_id for e in events],
                                  [e.edge for e in events], beams,
                                  np.array([e.tcp_velocity_mm_s for e in events]))
    tip = plan_cycle(beams, tool_diameter_mm, center, list(heights_mm), nominal_tool=nominal_tool,
                     tip_axis_flange=(axis.base_point_mm, axis.axis_flange))[-1]
    arm.run(tip)
    rec = arm.records
    return CycleRun([r[0] for r in rec], len(sweeps) + 1, arm.q,
                    np.array([r[1] for r in rec]), np.array([r[2] for r in rec]),
                    np.array([r[3] for r in rec]), arm.signs, arm.clock_s)
