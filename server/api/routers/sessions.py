"""Sessions: one run of a calibration menu: open, touch up step by step, compute, save or discard.

Everything a session holds (params, taught points, the computed report) is in the DB, so a
restart of the service loses nothing; a failed compute changes nothing.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi import APIRouter, Body, Query, Response

from db import crud
from server.api.deps import SessionDep, quick_read
from server.api.preconditions import IfMatch, set_etag
from server.api.routers.common import entry_out, session_out, step_out
from server.api.routers.external import ext_slot_out
from server.api.schemas import (EntryOut, ExtSlotOut, ReportOut, RunCycleOut, SessionIn,
                                SessionOut, SessionState, TouchUpIn)
from server.formats.recording import to_document
from server.menus import METHODS
from server.menus.methods import PARAM_HELP
from server.service import external as ext
from server.service import sessions as service
from server.service.robot import entry_matrix, physics_of, robot_of
from server.service.sessions import nominal_tool, resolve_inputs
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.recording import MIN_SAMPLES, RecordingData
from solvers.simulate import decoupled_arm

router = APIRouter(tags=["Sessions"])
PREFIX = "/controllers/{controller_id}/sessions"


@router.get("/methods")
def list_methods() -> list[dict[str, Any]]:
    """Every calibration menu: its table, what it writes, the params it needs and its steps."""
    return [{"name": m.name, "menu": m.menu, "title": m.title, "table": m.table, "kind": m.kind,
             "writes": m.writes, "required_params": {p: PARAM_HELP[p] for p in m.required},
             "extra_steps": m.extra_steps,
             "steps": [step_out(i, s, True, None).model_dump() for i, s in enumerate(m.steps)]}
            for m in METHODS.values()]


@router.post(PREFIX, status_code=201)
def open_session(controller_id: int, body: SessionIn, db: SessionDep,
                 response: Response) -> SessionOut:
    """Open a menu run on a target slot; the params the method needs are checked now, and the
    slots they name too (an empty touching or reference tool, a base that is no fixed tool)."""
    s = service.open_session(db, controller_id, body.method, body.target_no,
                             body.params.model_dump(exclude_none=True))
    set_etag(response, db, s)
    return session_out(s)


@router.get(PREFIX)
def list_sessions(controller_id: int, db: SessionDep,
                  state: SessionState | None = None) -> list[SessionOut]:
    crud.get_controller(db, controller_id)
    return [session_out(s) for s in crud.list_sessions(db, controller_id, state)]


@router.get(PREFIX + "/{session_id}")
@quick_read
def get_session(controller_id: int, session_id: int, db: SessionDep,
                response: Response) -> SessionOut:
    """The steps with their prompts, which are filled, and the report once computed. Its
    ``ETag`` may go with a later command as ``If-Match`` (412 if the session changed)."""
    s = crud.get_session(db, controller_id, session_id)
    set_etag(response, db, s)
    return session_out(s)


@router.post(PREFIX + "/{session_id}/touch-up")
def touch_up(controller_id: int, session_id: int, db: SessionDep, response: Response,
             body: TouchUpIn | None = Body(None), if_match: IfMatch = None) -> SessionOut:
    """Fill a step (default: the next empty one) with the emulated robot's current joints, or
    with ``joints_deg`` / ``flange_pose`` recorded on a real controller."""
    s = service.touch_up(db, controller_id, session_id, body or TouchUpIn(), if_match,
                         session_out)
    set_etag(response, db, s)
    return session_out(s)


@router.delete(PREFIX + "/{session_id}/points/{step}")
def delete_point(controller_id: int, session_id: int, step: int, db: SessionDep,
                 response: Response, if_match: IfMatch = None) -> SessionOut:
    """Forget one taught step (to re-teach it)."""
    s = service.delete_point(db, controller_id, session_id, step, if_match, session_out)
    set_etag(response, db, s)
    return session_out(s)


@router.post(PREFIX + "/{session_id}/compute")
def compute(controller_id: int, session_id: int, db: SessionDep, response: Response,
            if_match: IfMatch = None) -> ReportOut:
    """Solve from the session's touch-ups; nothing is written into the table yet. The target
    slot's version is kept: saving refuses a slot that changed after this compute."""
    s, report = service.compute(db, controller_id, session_id, if_match, session_out)
    set_etag(response, db, s)
    return report


@router.post(PREFIX + "/{session_id}/save")
def save(controller_id: int, session_id: int, db: SessionDep, response: Response,
         if_match: IfMatch = None,
         confirm: bool = Query(False, description="replace a slot of another kind, or a named "
                                                  "slot not calibrated here (else 409 naming "
                                                  "its kind and name)"),
         name: str | None = Query(None, max_length=64,
                                  description="the slot's name after the save (default: its "
                                              "own, or <kind><n> when its kind changes)")
         ) -> EntryOut | ExtSlotOut:
    """Write the computed frame into the target slot (XYZ menus keep A, B, C), with provenance
    and a history row. Refused (409, saying what changed) when the target slot changed after
    the compute: compute again on the slot as it is now. A tool or base slot keeps its kind
    and name: saving over a slot of another kind, or over a named slot that no menu
    calibrated (imported, typed in), is refused (409 naming its kind and name) unless
    ``confirm=true``. ``If-Match`` is the session's ETag."""
    s, e = service.save(db, controller_id, session_id, if_match, confirm, name, session_out)
    set_etag(response, db, s)
    return ext_slot_out(e) if s.target_table == ext.TABLE else entry_out(e)


@router.post(PREFIX + "/{session_id}/discard")
def discard(controller_id: int, session_id: int, db: SessionDep, response: Response,
            if_match: IfMatch = None) -> SessionOut:
    """Close the session without writing anything."""
    s = service.discard(db, controller_id, session_id, if_match, session_out)
    set_etag(response, db, s)
    return session_out(s)


# ------------------------------------------------------------------------- light barrier

@router.post(PREFIX + "/{session_id}/run-cycle")
def run_cycle(controller_id: int, session_id: int, db: SessionDep, response: Response,
              if_match: IfMatch = None) -> RunCycleOut:
    """Run the light-barrier measuring cycle on the emulated robot and sensor; every beam
    trigger becomes a taught point (replacing earlier ones)."""
    s, run = service.run_cycle(db, controller_id, session_id, if_match, session_out)
    set_etag(response, db, s)
    return RunCycleOut(triggers=len(run.triggers), passes=run.passes, session=session_out(s))


@router.post(PREFIX + "/{session_id}/beam-recording")
def post_beam_recording(controller_id: int, session_id: int, db: SessionDep, response: Response,
                        recording: dict[str, Any] = Body(...),
                        if_match: IfMatch = None) -> SessionOut:
    """Take the triggers of a ``robot-recording/1`` document of kind ``beam`` (a real
    controller's cycle) as the session's points; its sensor block becomes the params."""
    s = service.take_beam_recording(db, controller_id, session_id, recording, if_match,
                                    session_out)
    set_etag(response, db, s)
    return session_out(s)


# ---------------------------------------------------------------------------- recordings

RECORDING_KINDS = {"tool.xyz_4point": "touch", "tool.xyz_reference": "touch",
                   "tool.light_barrier": "beam"}


@router.get(PREFIX + "/{session_id}/recording")
def session_recording(controller_id: int, session_id: int, db: SessionDep) -> dict[str, Any]:
    """The session's taught points as a ``robot-recording/1`` document: kind ``touch`` for
    tool.xyz_4point / tool.xyz_reference (>= 4 points), kind ``beam`` for tool.light_barrier
    (>= 6 triggers). Samples in the order they were taught (emulated clock, ``t_s`` from the
    first), the controller's DH table (decoupled), the nominal tool (the session's result, else
    the slot; the cycle's nominal tool for beams), the active tool's load as the payload, and
    ``start_joints_deg`` one degree behind the first sample along each joint's last motion
    (so the backlash flank of the first sample is the one the emulated arm had)."""
    c = crud.get_controller(db, controller_id)
    s = crud.get_session(db, controller_id, session_id)
    kind = RECORDING_KINDS.get(s.method)
    if kind is None:
        raise CalibrationError(("method",), f"session {s.id} is {s.method}; recordings are made "
                               "from " + ", ".join(RECORDING_KINDS) + " sessions")
    points = sorted(s.points, key=lambda p: (p.t_s is None, p.t_s or 0.0, p.step))
    for p in points:
        if p.joints_deg is None:
            raise CalibrationError(("points", p.step, "joints_deg"), "taught as a flange pose: a "
                                   "recording needs the joint values")
    need = MIN_SAMPLES[kind]
    if len(points) < need:
        raise CalibrationError(("points",), f"a {kind} recording needs at least {need} taught "
                               f"points; session {s.id} has {len(points)}")
    if kind == "beam":
        tool = nominal_tool(db, s)
    elif s.result_values() is not None:
        tool = Pose(*s.result_values()).as_matrix()
    else:
        tool = entry_matrix(crud.get_entry(db, controller_id, "tool", s.target_no))
    arm = decoupled_arm(robot_of(c), tool)  # the format holds decoupled joints (FANUC J2/J3)
    q = np.array([p.joints_deg for p in points], dtype=float)
    times, t_prev = [], 0.0
    for p in points:
        t_prev = p.t_s if p.t_s is not None else t_prev
        times.append(t_prev)
    t = np.maximum.accumulate(np.array(times) - times[0])
    start = None
    if points[0].motion_sign is not None:
        start = (q[0] - np.array(points[0].motion_sign, dtype=float)) @ arm.C.T
    physics = physics_of(db, c)
    extra: dict[str, Any] = {}
    if kind == "beam":
        params = s.params
        extra = dict(beams=resolve_inputs(db, s).beams,
                     tool_diameter_mm=float(params.get("tool_diameter_mm") or 0.0),
                     beam_ids=np.array([p.beam_id for p in points], dtype=str),
                     edges=np.array([p.edge for p in points], dtype=str),
                     tcp_velocity_mm_s=np.array([[p.vx_mm_s, p.vy_mm_s, p.vz_mm_s]
                                                 for p in points], dtype=float))
    rec = RecordingData(kind=kind, robot=arm.model, tool=tool, t_s=t, joints_deg=q @ arm.C.T,
                        payload_mass_kg=physics.payload_mass_kg,
                        payload_com_mm=physics.payload_com_mm, start_joints_deg=start,
                        recorded_at=s.created_at.isoformat(), **extra)
    return to_document(rec)
