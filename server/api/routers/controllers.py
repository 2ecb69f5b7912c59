"""Controllers: the emulated robot controllers (cells) the pendant talks to."""

from __future__ import annotations

from fastapi import APIRouter, Response

from db import crud
from db.models import Controller
from emulator import THERMAL_WARMUP_S, imperfections_document, imperfections_from_document
from server.api.deps import SessionDep, quick_read
from server.api.preconditions import IfMatch, etag, set_etag
from server.api.schemas import (CellOut, ClockIn, ClockOut, ControllerIn, ControllerOut, PhysicsIn,
                                PhysicsOut)
from server.service import controllers as service
from server.service import external
from server.service.robot import cell_of, robot_of
from solvers.physics import Imperfections

router = APIRouter(prefix="/controllers", tags=["Controllers"])


def controller_out(c: Controller) -> ControllerOut:
    robot = robot_of(c)
    return ControllerOut(id=c.id, name=c.name, robot=c.robot_key, robot_name=robot.name,
                         dh_convention=robot.dh_convention, dof=robot.dof, joints_deg=c.joints_deg,
                         active_tool_no=c.active_tool_no, active_base_no=c.active_base_no)


@router.get("")
def list_controllers(db: SessionDep) -> list[ControllerOut]:
    """Every emulated controller."""
    return [controller_out(c) for c in crud.list_controllers(db)]


@router.post("", status_code=201)
def create_controller(body: ControllerIn, db: SessionDep) -> ControllerOut:
    """A new controller with a library arm (``robot``) or a custom DH table (``custom_robot``)."""
    custom = body.custom_robot.model_dump() if body.custom_robot else None
    c = service.create_controller(db, body.name, body.robot, custom, body.cell_seed,
                                  body.external_axes)
    return controller_out(c)


@router.get("/{controller_id}")
@quick_read
def get_controller(controller_id: int, db: SessionDep, response: Response) -> ControllerOut:
    """The controller; its ``ETag`` (bumped by every motion and setting) goes with a later
    write as ``If-Match``."""
    c = crud.get_controller(db, controller_id)
    response.headers["ETag"] = etag(c.version)
    return controller_out(c)


@router.delete("/{controller_id}", status_code=204)
def delete_controller(controller_id: int, db: SessionDep, if_match: IfMatch = None) -> Response:
    """Remove a controller with its tables, history and sessions."""
    service.delete_controller(db, controller_id, if_match, controller_out)
    return Response(status_code=204)


@router.get("/{controller_id}/cell")
def get_cell(controller_id: int, db: SessionDep) -> CellOut:
    """What the person at the cell knows: approach targets, marked points from the drawings,
    the light barrier's beams, and the marks on the external axes (a cell that has them). The
    true tool, plate and fixed-tool poses stay hidden."""
    c = crud.get_controller(db, controller_id)
    public = cell_of(c).public()
    if c.external_axes:
        public["targets"] = public["targets"] + external.target_names()
    return CellOut(**public)


def physics_out(c: Controller) -> PhysicsOut:
    robot = robot_of(c)
    imp = imperfections_from_document(c.physics, robot.dof) if c.physics else Imperfections()
    return PhysicsOut(**imperfections_document(imp),
                      rigid=imp.is_rigid() and imp.noise_mm == 0)


@router.get("/{controller_id}/cell/physics")
def get_physics(controller_id: int, db: SessionDep) -> PhysicsOut:
    """The emulated arm's hidden imperfections (what the controller's model does not know)."""
    return physics_out(crud.get_controller(db, controller_id))


@router.put("/{controller_id}/cell/physics")
def put_physics(controller_id: int, body: PhysicsIn, db: SessionDep, response: Response,
                if_match: IfMatch = None) -> PhysicsOut:
    """Give the emulated arm imperfections (``{}`` = the rigid arm again). Checked against the
    arm: per-joint lists need one value per joint; backlash, compliance, latency, bending and
    noise must be >= 0; DH deltas name a_mm, d_mm or alpha_deg of a joint 1..n."""
    c = service.set_physics(db, controller_id, body.model_dump(), if_match, controller_out)
    set_etag(response, db, c)
    return physics_out(c)


@router.get("/{controller_id}/cell/clock")
def get_clock(controller_id: int, db: SessionDep) -> ClockOut:
    """The emulated clock: seconds since the cell was powered, advanced by every motion."""
    c = crud.get_controller(db, controller_id)
    return ClockOut(clock_s=float(c.clock_s or 0.0), thermal_warmup_s=THERMAL_WARMUP_S)


@router.put("/{controller_id}/cell/clock")
def put_clock(controller_id: int, body: ClockIn, db: SessionDep, response: Response,
              if_match: IfMatch = None) -> ClockOut:
    """Set the clock: 0 = just powered (cold), ``thermal_warmup_s`` or more = warm."""
    c = service.set_clock(db, controller_id, body.clock_s, if_match, controller_out)
    set_etag(response, db, c)
    return ClockOut(clock_s=c.clock_s, thermal_warmup_s=THERMAL_WARMUP_S)
