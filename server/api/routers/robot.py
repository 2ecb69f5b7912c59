"""Robot: the emulated arm's joints, jogging, active tool and base, and the approach motion.

The operations are ``server.service.robot``'s; here the HTTP side: the body, ``If-Match``,
the answer (the robot's state) and its ``ETag``."""

from __future__ import annotations

from fastapi import APIRouter, Response

import emulator
from db import crud
from db.models import Controller
from emulator import external as ext_emu
from server.api.deps import SessionDep, quick_read
from server.api.preconditions import IfMatch, set_etag
from server.api.schemas import (ActiveIn, ApproachIn, ExternalAxesIn, JogIn, JointsIn, PoseOut,
                                RobotStateOut)
from server.service import robot as service
from server.service.robot import active_frames, robot_of
from solvers.dh import forward_kinematics

router = APIRouter(prefix="/controllers/{controller_id}/robot", tags=["Robot"])


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


def _answer(db: SessionDep, c: Controller, response: Response) -> RobotStateOut:
    set_etag(response, db, c)
    return state_out(db, c)


@router.get("")
@quick_read
def get_robot(controller_id: int, db: SessionDep, response: Response) -> RobotStateOut:
    """Joints, limits, active tool/base, flange pose (world) and TCP pose (active base); the
    ``ETag`` is the controller's version."""
    return _answer(db, crud.get_controller(db, controller_id), response)


def _present(db: SessionDep):  # noqa: ANN202
    """The robot's state, the current value a 412 carries."""
    return lambda c: state_out(db, c)


@router.put("/joints")
def set_joints(controller_id: int, body: JointsIn, db: SessionDep, response: Response,
               if_match: IfMatch = None) -> RobotStateOut:
    """Move to joint values (deg); refused naming joint, value and limit outside the limits."""
    c = service.set_joints(db, controller_id, body.joints_deg, if_match, _present(db))
    return _answer(db, c, response)


@router.post("/home")
def home(controller_id: int, db: SessionDep, response: Response,
         if_match: IfMatch = None) -> RobotStateOut:
    """Move to HOME (flange pointing down in front of the arm)."""
    return _answer(db, service.home(db, controller_id, if_match, _present(db)), response)


@router.post("/jog")
def jog(controller_id: int, body: JogIn, db: SessionDep, response: Response,
        if_match: IfMatch = None) -> RobotStateOut:
    """One increment in joint, world, base or tool coordinates (active tool and base)."""
    c = service.jog(db, controller_id, body.mode, body.axis, body.increment, if_match,
                    _present(db))
    return _answer(db, c, response)


@router.put("/external")
def set_external(controller_id: int, body: ExternalAxesIn, db: SessionDep, response: Response,
                 if_match: IfMatch = None) -> RobotStateOut:
    """Move external axes to values (E1..E3 deg, the rail E4 mm); omitted axes stay. Refused
    naming the axis, its value and its limit outside the limits."""
    c = service.set_external(db, controller_id, dict(body.values), if_match, _present(db))
    return _answer(db, c, response)


@router.put("/active")
def set_active(controller_id: int, body: ActiveIn, db: SessionDep, response: Response,
               if_match: IfMatch = None) -> RobotStateOut:
    """Select the active tool (0 = flange) and base (0 = world)."""
    c = service.set_active(db, controller_id, body.tool_no, body.base_no, if_match,
                           _present(db))
    return _answer(db, c, response)


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
    return _answer(db, service.approach(db, controller_id, body, if_match, _present(db)),
                   response)
