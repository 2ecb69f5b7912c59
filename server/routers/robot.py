"""Robot: the emulated arm's joints, jogging, active tool and base, and the approach motion."""

from __future__ import annotations

from fastapi import APIRouter

from db import crud
from db.models import Controller
from server import emulator
from server.deps import SessionDep
from server.routers.common import active_frames, cell_of, robot_of
from server.schemas import ActiveIn, ApproachIn, JogIn, JointsIn, PoseOut, RobotStateOut
from solvers.dh import check_joint_limits, forward_kinematics
from solvers.errors import CalibrationError

router = APIRouter(prefix="/controllers/{controller_id}/robot", tags=["Robot"])


def state_out(db: SessionDep, c: Controller) -> RobotStateOut:
    robot = robot_of(c)
    tool, base = active_frames(db, c)
    T_base_tcp = emulator.tcp_pose(robot, c.joints_deg, tool, base)
    return RobotStateOut(joints_deg=[round(q, 9) for q in c.joints_deg],
                         limits_deg=robot.limits_deg().tolist(),
                         active_tool_no=c.active_tool_no, active_base_no=c.active_base_no,
                         flange_pose=PoseOut.of_matrix(forward_kinematics(robot, c.joints_deg)),
                         tcp_pose=PoseOut.of_matrix(T_base_tcp))


def _move(c: Controller, q: object) -> None:
    c.joints_deg = [float(x) for x in q]  # type: ignore[union-attr]


@router.get("")
def get_robot(controller_id: int, db: SessionDep) -> RobotStateOut:
    """Joints, limits, active tool/base, flange pose (world) and TCP pose (active base)."""
    return state_out(db, crud.get_controller(db, controller_id))


@router.put("/joints")
def set_joints(controller_id: int, body: JointsIn, db: SessionDep) -> RobotStateOut:
    """Move to joint values (deg); refused naming joint, value and limit outside the limits."""
    c = crud.get_controller(db, controller_id)
    robot = robot_of(c)
    if len(body.joints_deg) != robot.dof:
        raise CalibrationError(("joints_deg",), f"has {len(body.joints_deg)} values; the robot has "
                               f"{robot.dof} joints")
    check_joint_limits(robot, body.joints_deg)
    _move(c, body.joints_deg)
    return state_out(db, c)


@router.post("/home")
def home(controller_id: int, db: SessionDep) -> RobotStateOut:
    """Move to HOME (flange pointing down in front of the arm)."""
    c = crud.get_controller(db, controller_id)
    _move(c, emulator.home_joints(robot_of(c)))
    return state_out(db, c)


@router.post("/jog")
def jog(controller_id: int, body: JogIn, db: SessionDep) -> RobotStateOut:
    """One increment in joint, world, base or tool coordinates (active tool and base)."""
    c = crud.get_controller(db, controller_id)
    robot = robot_of(c)
    if body.mode == "joint" and (not body.axis.startswith("A") or len(body.axis) != 2):
        raise CalibrationError(("axis",), f"joint mode jogs A1..A{robot.dof}, got {body.axis!r}")
    if body.mode == "joint" and int(body.axis[1]) > robot.dof:
        raise CalibrationError(("axis",), f"the robot has {robot.dof} joints, got {body.axis!r}")
    if body.mode != "joint" and body.axis not in emulator.CARTESIAN_AXES:
        raise CalibrationError(("axis",),
                               f"{body.mode} mode jogs X, Y, Z, A, B, C, got {body.axis!r}")
    tool, base = active_frames(db, c)
    _move(c, emulator.jog(robot, c.joints_deg, body.mode, body.axis, body.increment, tool, base))
    return state_out(db, c)


@router.put("/active")
def set_active(controller_id: int, body: ActiveIn, db: SessionDep) -> RobotStateOut:
    """Select the active tool (0 = flange) and base (0 = world)."""
    c = crud.get_controller(db, controller_id)
    if body.tool_no is not None:
        c.active_tool_no = body.tool_no
    if body.base_no is not None:
        c.active_base_no = body.base_no
    return state_out(db, c)


@router.post("/approach")
def approach(controller_id: int, body: ApproachIn, db: SessionDep) -> RobotStateOut:
    """Careful jogging, done for you: the physical tip (true tool, or a mark of the held
    workpiece) onto a cell target from tilt/around; ``fixed_tool_align`` aligns the flange
    with the fixed tool. Refused (422) when the pose is out of reach or limits."""
    c = crud.get_controller(db, controller_id)
    q = emulator.approach(robot_of(c), cell_of(c), c.joints_deg, body.target, body.tilt_deg,
                          body.around_deg, body.spin_deg, body.tool_point_mm, body.miss_mm)
    _move(c, q)
    return state_out(db, c)
