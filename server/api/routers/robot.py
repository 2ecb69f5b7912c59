"""Robot: the emulated arm's joints, jogging, active tool and base, and the approach motion.

Every motion moves the commanded joints (what the controller shows), turns the backlash
flanks of the joints that moved and advances the emulated clock (emulator)."""

from __future__ import annotations

import numpy as np
from fastapi import APIRouter, Response
from scipy.spatial.transform import Rotation

import emulator
from db import crud
from db.models import Controller
from emulator import external as ext_emu
from server.service import external as ext
from server.api.deps import SessionDep
from server.api.preconditions import IfMatch, check, set_etag
from server.api.routers.common import active_frames, cell_of, robot_of, state_of, store_state
from server.api.schemas import (ActiveIn, ApproachIn, ExternalAxesIn, JogIn, JointsIn, PoseOut,
                            RobotStateOut)
from solvers.dh import check_joint_limits, forward_kinematics
from solvers.errors import CalibrationError
from solvers.physics import Imperfections

router = APIRouter(prefix="/controllers/{controller_id}/robot", tags=["Robot"])
AIM_STREAM = 7  # the aim's random stream, apart from the emulator's own draws of noise_seed


def state_out(db: SessionDep, c: Controller) -> RobotStateOut:
    robot = robot_of(c)
    tool, base = active_frames(db, c)
    T_base_tcp = emulator.tcp_pose(robot, c.joints_deg, tool, base)
    return RobotStateOut(joints_deg=[round(q, 9) for q in c.joints_deg],
                         limits_deg=robot.limits_deg().tolist(),
                         active_tool_no=c.active_tool_no, active_base_no=c.active_base_no,
                         flange_pose=PoseOut.of_matrix(forward_kinematics(robot, c.joints_deg)),
                         tcp_pose=PoseOut.of_matrix(T_base_tcp),
                         external_axes=c.external_axes or None,
                         external_limits={k: list(v) for k, v in ext_emu.LIMITS.items()}
                         if c.external_axes else None)


def physics_of(db: SessionDep, c: Controller) -> emulator.RobotPhysics:
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


def _controller(db: SessionDep, controller_id: int, if_match: str | None) -> Controller:
    """The controller a command moves; 412 (with the robot's state) when ``If-Match`` (the
    controller's ETag) is stale. Jogs are relative, so they usually go without it."""
    c = crud.get_controller(db, controller_id)
    check(if_match, c.version, lambda: state_out(db, c), f"controller {c.id}")
    return c


def _answer(db: SessionDep, c: Controller, response: Response) -> RobotStateOut:
    set_etag(response, db, c)
    return state_out(db, c)


@router.get("")
def get_robot(controller_id: int, db: SessionDep, response: Response) -> RobotStateOut:
    """Joints, limits, active tool/base, flange pose (world) and TCP pose (active base); the
    ``ETag`` is the controller's version."""
    return _answer(db, crud.get_controller(db, controller_id), response)


@router.put("/joints")
def set_joints(controller_id: int, body: JointsIn, db: SessionDep, response: Response,
        if_match: IfMatch = None) -> RobotStateOut:
    """Move to joint values (deg); refused naming joint, value and limit outside the limits."""
    c = _controller(db, controller_id, if_match)
    robot = robot_of(c)
    if len(body.joints_deg) != robot.dof:
        raise CalibrationError(("joints_deg",), f"has {len(body.joints_deg)} values; the robot has "
                               f"{robot.dof} joints")
    check_joint_limits(robot, body.joints_deg)
    move_to(c, body.joints_deg)
    return _answer(db, c, response)


@router.post("/home")
def home(controller_id: int, db: SessionDep, response: Response,
        if_match: IfMatch = None) -> RobotStateOut:
    """Move to HOME (flange pointing down in front of the arm)."""
    c = _controller(db, controller_id, if_match)
    move_to(c, emulator.home_joints(robot_of(c)))
    return _answer(db, c, response)


@router.post("/jog")
def jog(controller_id: int, body: JogIn, db: SessionDep, response: Response,
        if_match: IfMatch = None) -> RobotStateOut:
    """One increment in joint, world, base or tool coordinates (active tool and base)."""
    c = _controller(db, controller_id, if_match)
    robot = robot_of(c)
    if body.axis.startswith("E"):  # an external axis (joint mode): E1..E4 of the cell
        if body.mode != "joint":
            raise CalibrationError(("mode",), f"external axes jog in joint mode, got {body.mode}")
        move_external(c, ext_emu.jog(ext.values_of(c), body.axis, body.increment))
        return _answer(db, c, response)
    if body.mode == "joint" and (not body.axis.startswith("A") or len(body.axis) != 2):
        raise CalibrationError(("axis",), f"joint mode jogs A1..A{robot.dof}, got {body.axis!r}")
    if body.mode == "joint" and int(body.axis[1]) > robot.dof:
        raise CalibrationError(("axis",), f"the robot has {robot.dof} joints, got {body.axis!r}")
    if body.mode != "joint" and body.axis not in emulator.CARTESIAN_AXES:
        raise CalibrationError(("axis",),
                               f"{body.mode} mode jogs X, Y, Z, A, B, C, got {body.axis!r}")
    tool, base = active_frames(db, c)
    move_to(c, emulator.jog(robot, c.joints_deg, body.mode, body.axis, body.increment, tool, base))
    return _answer(db, c, response)


def move_external(c: Controller, values: dict[str, float]) -> None:
    """Move the external axes: the clock advances by the slowest axis' travel."""
    c.clock_s = float(c.clock_s or 0.0) + ext_emu.motion_s(ext.values_of(c), values)
    c.external_axes = values
    c.motion_count = int(c.motion_count or 0) + 1


@router.put("/external")
def set_external(controller_id: int, body: ExternalAxesIn, db: SessionDep, response: Response,
                 if_match: IfMatch = None) -> RobotStateOut:
    """Move external axes to values (E1..E3 deg, the rail E4 mm); omitted axes stay. Refused
    naming the axis, its value and its limit outside the limits."""
    c = _controller(db, controller_id, if_match)
    values = ext.values_of(c, "values")
    values.update(ext_emu.check_values(dict(body.values), ("values",)))
    move_external(c, values)
    return _answer(db, c, response)


@router.put("/active")
def set_active(controller_id: int, body: ActiveIn, db: SessionDep, response: Response,
        if_match: IfMatch = None) -> RobotStateOut:
    """Select the active tool (0 = flange) and base (0 = world)."""
    c = _controller(db, controller_id, if_match)
    if body.tool_no is not None:
        c.active_tool_no = body.tool_no
    if body.base_no is not None:
        c.active_base_no = body.base_no
    return _answer(db, c, response)


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


@router.post("/approach")
def approach(controller_id: int, body: ApproachIn, db: SessionDep, response: Response,
        if_match: IfMatch = None) -> RobotStateOut:
    """Careful jogging, done for you: the physical tip (true tool, or a mark of the held
    workpiece) onto a cell target from tilt/around; ``fixed_tool_align`` aligns the flange
    with the fixed tool. Refused (422) when the pose is out of reach or limits. On an
    imperfect arm (``.../cell/physics``) the TRUE tip goes onto the target, so the joints
    shown differ from the nominal solution. The tip stops off the mark like a person's does
    (``noise_mm``, default 0.1 mm per axis, seeded: the same walk-through gives the same
    report); ``noise_mm: 0`` is the ideal aim."""
    c = _controller(db, controller_id, if_match)
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
    return _answer(db, c, response)
