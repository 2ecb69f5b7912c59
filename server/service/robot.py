"""The emulated controller's arm: its robot and cell, its typed state, its frames, and the
operations that move it (set joints, home, jog, the external axes, the active tool and base,
the approach).

Every motion moves the commanded joints (what the controller shows), turns the backlash
flanks of the joints that moved and advances the emulated clock (emulator). An operation takes
the request's session (the controller's row is locked: the face's transaction), checks the
caller's ``If-Match`` against the controller's version and returns the changed controller for
the face to present.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation
from sqlalchemy.orm import Session

import emulator
from db import crud
from db.models import Controller, FrameEntry
from emulator import Cell, ControllerState, cell_for, robot_from_custom
from emulator import external as ext_emu
from server.api.schemas import ApproachIn
from server.service import external as ext
from server.service.preconditions import Present, check_row
from solvers.dh import RobotModel, check_joint_limits, forward_kinematics
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.physics import Imperfections
from solvers.robots import ROBOTS

AIM_STREAM = 7  # the aim's random stream, apart from the emulator's own draws of noise_seed


# ------------------------------------------------------------------ the controller's arm

def robot_of(c: Controller) -> RobotModel:
    if c.custom_robot:
        return robot_from_custom(c.custom_robot)
    return ROBOTS[c.robot_key or "kuka_kr6_r900_sixx"]


def cell_of(c: Controller) -> Cell:
    return cell_for(robot_of(c), c.cell_seed)


def state_of(c: Controller) -> ControllerState:
    """The emulated controller's typed state, loaded from its row (the request holds the row
    lock: server.api.deps)."""
    sign = None if c.motion_sign is None else tuple(float(v) for v in c.motion_sign)
    return ControllerState(tuple(float(q) for q in c.joints_deg), float(c.clock_s or 0.0), sign,
                           int(c.motion_count or 0))


def store_state(c: Controller, s: ControllerState) -> None:
    """Save the state into the row (committed with the request)."""
    c.joints_deg = list(s.joints_deg)
    c.clock_s = s.clock_s
    c.motion_sign = None if s.motion_sign is None else list(s.motion_sign)
    c.motion_count = s.motion_count


def entry_matrix(e: FrameEntry | None) -> np.ndarray:
    """T of a slot (identity for slot 0 = flange / world)."""
    return np.eye(4) if e is None else Pose(*e.pose_values()).as_matrix()


def active_frames(db: Session, c: Controller) -> tuple[np.ndarray, np.ndarray]:
    """(T_flange_tool, T_world_base) of the active tool and base, from the controller's tables."""
    tool = crud.get_entry(db, c.id, "tool", c.active_tool_no) if c.active_tool_no else None
    base = crud.get_entry(db, c.id, "base", c.active_base_no) if c.active_base_no else None
    return entry_matrix(tool), entry_matrix(base)


def flange_pose_of(c: Controller, joints_deg: list[float]) -> Pose:
    """T_base_flange of joint values on this controller's arm (checked: count, limits)."""
    return flange_pose_on(robot_of(c), joints_deg)


def flange_pose_on(robot: RobotModel, joints_deg: list[float]) -> Pose:
    """T_base_flange of joint values on ``robot`` (checked: count, limits)."""
    if len(joints_deg) != robot.dof:
        raise CalibrationError(("joints_deg",),
                               f"has {len(joints_deg)} values; the robot has {robot.dof} joints")
    check_joint_limits(robot, joints_deg)  # joints beyond the limits: wrong robot or a typo
    return Pose.from_matrix(forward_kinematics(robot, joints_deg), orthonormal=True)


def physics_of(db: Session, c: Controller) -> emulator.RobotPhysics:
    """The arm's hidden state: stored imperfections (None = rigid), clock, backlash flanks,
    the active tool's load as the payload, the operator's noise seed."""
    robot = robot_of(c)
    imp = (emulator.imperfections_from_document(c.physics, robot.dof) if c.physics
           else Imperfections())
    mass, com = 0.0, np.zeros(3)
    if c.active_tool_no:
        e = crud.get_entry(db, c.id, "tool", c.active_tool_no)
        if e.mass_kg:
            mass, com = float(e.mass_kg), np.array([e.com_x_mm or 0.0, e.com_y_mm or 0.0,
                                                    e.com_z_mm or 0.0])
    signs = np.zeros(robot.dof) if c.motion_sign is None else np.array(c.motion_sign, float)
    return emulator.RobotPhysics(imp, float(c.clock_s or 0.0), signs, mass, com,
                                 (int(c.cell_seed), int(c.id), int(c.motion_count or 0)))


def move_to(c: Controller, q: object, extra_s: float = 0.0) -> None:
    """Command joints ``q``: the joints that moved turn their flank, the clock advances by the
    move's time plus ``extra_s`` (:func:`emulator.moved` on the typed state)."""
    store_state(c, emulator.moved(robot_of(c), state_of(c), q, extra_s))


def move_external(c: Controller, values: dict[str, float]) -> None:
    """Move the external axes: the clock advances by the slowest axis' travel."""
    c.clock_s = float(c.clock_s or 0.0) + ext_emu.motion_s(ext.values_of(c), values)
    c.external_axes = values
    c.motion_count = int(c.motion_count or 0) + 1


# ------------------------------------------------------------------------------ operations

def controller(db: Session, controller_id: int, if_match: str | None = None,
               present: Present | None = None) -> Controller:
    """The controller a command changes; PreconditionFailed (with ``present(c)``) when
    ``if_match`` (the controller's ETag) is stale. Jogs are relative, so they usually go
    without it."""
    return check_row(if_match, crud.get_controller(db, controller_id), present,
                     f"controller {controller_id}")


def set_joints(db: Session, controller_id: int, joints_deg: list[float],
               if_match: str | None = None, present: Present | None = None) -> Controller:
    """Move to joint values (deg); refused naming joint, value and limit outside the limits."""
    c = controller(db, controller_id, if_match, present)
    robot = robot_of(c)
    if len(joints_deg) != robot.dof:
        raise CalibrationError(("joints_deg",), f"has {len(joints_deg)} values; the robot has "
                               f"{robot.dof} joints")
    check_joint_limits(robot, joints_deg)
    move_to(c, joints_deg)
    return c


def home(db: Session, controller_id: int, if_match: str | None = None,
         present: Present | None = None) -> Controller:
    """Move to HOME (flange pointing down in front of the arm)."""
    c = controller(db, controller_id, if_match, present)
    move_to(c, emulator.home_joints(robot_of(c)))
    return c


def jog(db: Session, controller_id: int, mode: str, axis: str, increment: float,
        if_match: str | None = None, present: Present | None = None) -> Controller:
    """One increment in joint, world, base or tool coordinates (active tool and base)."""
    c = controller(db, controller_id, if_match, present)
    robot = robot_of(c)
    if axis.startswith("E"):  # an external axis (joint mode): E1..E4 of the cell
        if mode != "joint":
            raise CalibrationError(("mode",), f"external axes jog in joint mode, got {mode}")
        move_external(c, ext_emu.jog(ext.values_of(c), axis, increment))
        return c
    if mode == "joint" and (not axis.startswith("A") or len(axis) != 2):
        raise CalibrationError(("axis",), f"joint mode jogs A1..A{robot.dof}, got {axis!r}")
    if mode == "joint" and int(axis[1]) > robot.dof:
        raise CalibrationError(("axis",), f"the robot has {robot.dof} joints, got {axis!r}")
    if mode != "joint" and axis not in emulator.CARTESIAN_AXES:
        raise CalibrationError(("axis",), f"{mode} mode jogs X, Y, Z, A, B, C, got {axis!r}")
    tool, base = active_frames(db, c)
    move_to(c, emulator.jog(robot, c.joints_deg, mode, axis, increment, tool, base))
    return c


def set_external(db: Session, controller_id: int, values: dict[str, float],
                 if_match: str | None = None, present: Present | None = None) -> Controller:
    """Move external axes to values (E1..E3 deg, the rail E4 mm); omitted axes stay. Refused
    naming the axis, its value and its limit outside the limits."""
    c = controller(db, controller_id, if_match, present)
    moved = ext.values_of(c, "values")
    moved.update(ext_emu.check_values(dict(values), ("values",)))
    move_external(c, moved)
    return c


def set_active(db: Session, controller_id: int, tool_no: int | None = None,
               base_no: int | None = None, if_match: str | None = None,
               present: Present | None = None) -> Controller:
    """Select the active tool (0 = flange) and base (0 = world); None keeps it."""
    c = controller(db, controller_id, if_match, present)
    if tool_no is not None:
        c.active_tool_no = tool_no
    if base_no is not None:
        c.active_base_no = base_no
    return c


def approach_angles(cell: emulator.Cell, target: str,
                    flange_orientation: list[list[float]]) -> tuple[float, float, float]:
    """(tilt, around, spin) in deg of :func:`emulator.approach_rotation` that puts the
    flange at ``flange_orientation`` (R_world_flange) while the true tool touches ``target``.

    The held tool's frame is ``R_world_tool = R_world_flange @ R_flange_tool`` and
    ``R_target_tool = Rz(around) Ry(tilt) Rx(180) Rz(spin)``; since ``Rx(180) Rz(s) =
    Rz(-s) Rx(180)``, ``R_target_tool @ Rx(180) = Rz(around) Ry(tilt) Rz(-spin)``: intrinsic
    Z-Y-Z Euler angles (scipy ``Rotation.as_euler("ZYZ")``, tilt in [0, 180] deg).
    Raises CalibrationError(("flange_orientation",)) for a matrix that is not a rotation or a
    tilt beyond the approach's 80 deg."""
    R = np.asarray(flange_orientation, float)
    if not (np.all(np.isfinite(R)) and np.allclose(R @ R.T, np.eye(3), atol=1e-6)
            and np.linalg.det(R) > 0):
        raise CalibrationError(("flange_orientation",), "is not a rotation matrix (orthonormal, "
                               "det +1, rows as in a report's next_orientation)")
    t = cell.target(target)
    if t.align or t.held != "tool":
        raise CalibrationError(("flange_orientation",), f"target {target!r} sets its own "
                               "orientation; give tilt_deg/around_deg/spin_deg instead")
    R_target_tool = t.R_world_target.T @ R @ cell.T_flange_tool[:3, :3]
    around, tilt, minus_spin = Rotation.from_matrix(
        R_target_tool @ emulator.rot("X", 180.0)).as_euler("ZYZ", degrees=True)
    if tilt > 80.0:
        raise CalibrationError(("flange_orientation",), f"tilts the tool {tilt:.0f} deg from "
                               f"the {target} normal; the approach reaches at most 80 deg")
    return float(tilt), float(around), float(-minus_spin)


def approach(db: Session, controller_id: int, body: ApproachIn, if_match: str | None = None,
             present: Present | None = None) -> Controller:
    """Careful jogging, done for you: the physical tip (true tool, or a mark of the held
    workpiece) onto a cell target from tilt/around, off the mark by the operator's seeded aim
    (``body.noise_mm``) plus ``body.miss_mm``; on an imperfect arm the TRUE tip goes onto the
    target. CalibrationError when the pose is out of reach or limits."""
    c = controller(db, controller_id, if_match, present)
    physics = physics_of(db, c)
    miss = None if body.miss_mm is None else np.asarray(body.miss_mm, float)
    if body.noise_mm > 0:  # the operator's aim: seeded by cell and motion count (own stream)
        aim = physics.rng(AIM_STREAM).normal(0.0, body.noise_mm, 3)
        miss = aim if miss is None else miss + aim
    cell = cell_of(c)
    tilt, around, spin = body.tilt_deg, body.around_deg, body.spin_deg
    if body.flange_orientation is not None:
        tilt, around, spin = approach_angles(cell, body.target, body.flange_orientation)
    target: str | emulator.Target = body.target
    if c.external_axes:  # the marks on the external axes; the cell seen from the rail
        target = ext_emu.target(ext.cell_of(c, robot_of(c).reach_mm), cell, body.target,
                                ext.values_of(c))
    q = emulator.approach(robot_of(c), cell, c.joints_deg, target, tilt, around, spin,
                          body.tool_point_mm, miss, physics=physics)
    move_to(c, q, emulator.APPROACH_S)
    return c
