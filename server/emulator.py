"""The emulated robot and cell: what the pendant drives, and the hidden truth calibration finds.

A controller knows its arm (DH table) and its tool and base tables. The *cell* holds what
the controller does not know: the physical pointer on the flange (its true TCP), a reference
tip, a base plate with marked points, an external fixed tool, a robot-held workpiece and a
crossed-beam light barrier. The cell is built from the controller's ``cell_seed`` (so it
survives a restart without being stored) and scaled to the arm's reach.

Motion is what a person does on the pendant: joint and Cartesian jogs with increments, and
:func:`approach`, the careful jogging that puts a point of the true tool (or workpiece) onto a
cell target from a chosen orientation. Kinematics go through :mod:`solvers.dh`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.dh import (DHJoint, RobotModel, check_joint_limits, forward_kinematics,
                        geometric_jacobian, inverse_kinematics)
from solvers.errors import KinematicsError
from solvers.frames import Pose, invert, rotation_matrix
from solvers.robots import ROBOTS
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
    starts = [np.zeros(robot.dof)] + [rng.uniform(lo, hi) for _ in range(30)]
    for q0 in starts:
        try:
            return tuple(float(x) for x in inverse_kinematics(robot, goal, q0))
        except KinematicsError:
            continue
    return tuple(0.0 for _ in range(robot.dof))


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


def approach(robot: RobotModel, cell: Cell, q_now: FloatArray, target: str,
             tilt_deg: float = 0.0, around_deg: float = 0.0, spin_deg: float = 0.0,
             tool_point_mm: FloatArray | None = None,
             miss_mm: FloatArray | None = None) -> FloatArray:
    """Joint values that put the held point onto ``target`` from the given orientation.

    The true tool (or workpiece) is used: this is what a person sees when jogging the
    physical tip onto the mark. ``tool_point_mm`` picks another point of the held body
    (in its own frame; default its origin, the tip). ``miss_mm`` deliberately misses the
    target by that vector (world), like a sloppy touch-up.
    """
    t = cell.target(target)
    if t.align:
        T_goal = rotation_matrix(t.R_world_target @ rot("Z", spin_deg), t.point_mm)
        return solve_ik(robot, T_goal, q_now, tool=None)
    T_flange_held = cell.T_flange_tool if t.held == "tool" else cell.T_flange_workpiece
    held_point = t.held_point_mm if tool_point_mm is None else np.asarray(tool_point_mm, float)
    R = t.R_world_target @ approach_rotation(tilt_deg, around_deg, spin_deg)
    point = t.point_mm + (np.zeros(3) if miss_mm is None else np.asarray(miss_mm, float))
    T_goal = rotation_matrix(R, point - R @ held_point)
    return solve_ik(robot, T_goal, q_now, tool=T_flange_held)


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
    """The light-barrier cycle as the emulated robot ran it: every beam trigger in order."""

    triggers: list  # solvers.beam_cycle.BeamTrigger
    passes: int
    joints_deg: FloatArray  # where the robot stopped


def run_beam_cycle(robot: RobotModel, cell: Cell, q_now: FloatArray, nominal_tool: FloatArray,
                   beams: dict[str, tuple[FloatArray, FloatArray]], tool_diameter_mm: float,
                   heights_mm: tuple[float, ...] = (10.0, 40.0)) -> CycleRun:
    """Run the measuring cycle on the emulated robot with the emulated sensor.

    Sweeps planned for the nominal tool (solvers.beam_cycle.plan_cycle), beams switched by
    the TRUE tool (trigger_events), then the tip search aimed with the shaft axis the sweeps
    measured (solvers.light_barrier.shaft_axis_from_sweeps), as the paper's cycle does.
    Every pass start is checked reachable inside the joint limits.
    """
    from solvers.beam_cycle import plan_cycle, trigger_events
    from solvers.light_barrier import shaft_axis_from_sweeps

    center = next(iter(beams.values()))[0]
    true_tcp, true_axis = cell.T_flange_tool[:3, 3], cell.T_flange_tool[:3, 2]
    plan = plan_cycle(beams, tool_diameter_mm, center, list(heights_mm), nominal_tool=nominal_tool)
    q = np.asarray(q_now, float)
    events = []
    sweeps = [p for p in plan if p.kind == "sweep"]
    for p in sweeps:
        q = solve_ik(robot, p.start_flange, q, tool=None)
        events += trigger_events(None, p, true_tcp, true_axis, beams, tool_diameter_mm)
    if not events:
        raise KinematicsError(("params", "nominal_tool"), "no beam was cut during the sweeps: is "
                              "the nominal TCP near the true one and the sensor where the beams "
                              "say?")
    axis = shaft_axis_from_sweeps([e.T_base_flange for e in events], [e.beam_id for e in events],
                                  [e.edge for e in events], beams,
                                  np.array([e.tcp_velocity_mm_s for e in events]))
    tip = plan_cycle(beams, tool_diameter_mm, center, list(heights_mm), nominal_tool=nominal_tool,
                     tip_axis_flange=(axis.base_point_mm, axis.axis_flange))[-1]
    q = solve_ik(robot, tip.start_flange, q, tool=None)
    tip_events = trigger_events(None, tip, true_tcp, true_axis, beams, tool_diameter_mm)
    if tip_events:
        q = solve_ik(robot, tip_events[0].T_base_flange, q, tool=None)
    return CycleRun(events + tip_events, len(sweeps) + 1, q)
