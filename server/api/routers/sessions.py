"""Sessions: one run of a calibration menu: open, touch up step by step, compute, save or discard.

Everything a session holds (params, taught points, the computed report) is in the DB, so a
restart of the service loses nothing; a failed compute changes nothing.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from fastapi import APIRouter, Body, Query, Response

import emulator
from db import crud
from db.models import EXT_KIN_SLOTS
from db.outbox import emit
from server.service import external as ext
from server.api.deps import SessionDep
from server.service import sessions as sessions_service
from server.api.preconditions import IfMatch, check, set_etag
from server.menus import METHODS
from server.menus.methods import PARAM_HELP
from server.api.routers.external import ext_slot_out
from server.api.routers.common import (cell_of, entry_matrix, entry_out, resolve_inputs, robot_of, session_out, spec_of,
                                   state_of, step_out, store_state, taught_data)
from server.api.routers.robot import physics_of
from server.api.schemas import (EntryOut, ExtSlotOut, ReportOut, RunCycleOut, SessionIn, SessionOut,
                            SessionState, TouchUpIn, jsonable)
from solvers.dh import forward_kinematics
from solvers.errors import CalibrationError
from solvers.frames import Pose

router = APIRouter(tags=["Sessions"])
PREFIX = "/controllers/{controller_id}/sessions"
POSE_KEYS = ("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg")


def _session(db: SessionDep, controller_id: int, session_id: int,
             if_match: str | None = None):  # noqa: ANN202
    """The session a command acts on; 412 (with the session) when ``If-Match`` is stale."""
    s = crud.get_session(db, controller_id, session_id)
    check(if_match, s.version, lambda: session_out(s),
          f"session {s.id} of controller {controller_id}")
    return s


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
    c = crud.get_controller(db, controller_id)
    spec = METHODS[body.method]
    params = body.params.model_dump(exclude_none=True)
    for p in spec.required:
        if p not in params:
            raise CalibrationError(("params", p), f"required by {spec.name}: {PARAM_HELP[p]}")
    if spec.table in crud.SLOTS and body.target_no > crud.slot_limit(c, spec.table):
        raise CalibrationError(("target_no",), f"{spec.name} writes a {spec.table} slot "
                               f"(1..{crud.slot_limit(c, spec.table)}), got {body.target_no}")
    if spec.table in crud.SLOTS:
        crud.ensure_entry(db, c, spec.table, body.target_no)  # an ABB-kind table grows to it
    if spec.table == "extkin" and body.target_no > EXT_KIN_SLOTS:
        raise CalibrationError(("target_no",), f"{spec.name} writes an external kinematic "
                               f"(EX_KIN 1..{EXT_KIN_SLOTS}), got {body.target_no}")
    s = crud.open_session(db, c, spec.name, spec.table, body.target_no, jsonable(params))
    if spec.menu == "ext" or any(k in params for k in ("tool_no", "reference_tool_no",
                                                        "fixed_tool_no")):
        resolve_inputs(db, s)  # an empty touching tool is refused now, not at Compute
    set_etag(response, db, s)
    return session_out(s)


@router.get(PREFIX)
def list_sessions(controller_id: int, db: SessionDep,
                  state: SessionState | None = None) -> list[SessionOut]:
    crud.get_controller(db, controller_id)
    return [session_out(s) for s in crud.list_sessions(db, controller_id, state)]


@router.get(PREFIX + "/{session_id}")
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
    s = sessions_service.touch_up(db, controller_id, session_id, body or TouchUpIn(), if_match)
    set_etag(response, db, s)
    return session_out(s)


@router.delete(PREFIX + "/{session_id}/points/{step}")
def delete_point(controller_id: int, session_id: int, step: int, db: SessionDep,
                 response: Response, if_match: IfMatch = None) -> SessionOut:
    """Forget one taught step (to re-teach it)."""
    s = _session(db, controller_id, session_id, if_match)
    crud.delete_point(db, s, step)
    set_etag(response, db, s)
    return session_out(s)


@router.post(PREFIX + "/{session_id}/compute")
def compute(controller_id: int, session_id: int, db: SessionDep, response: Response,
            if_match: IfMatch = None) -> ReportOut:
    """Solve from the session's touch-ups; nothing is written into the table yet. The target
    slot's version is kept: saving refuses a slot that changed after this compute."""
    s = _session(db, controller_id, session_id, if_match)
    crud.require_open(s)
    spec, points = spec_of(s), taught_data(s)
    spec.check_taught(points, s.params)
    result = ext.solve_in_chain(db, s, spec, points, resolve_inputs(db, s))
    report = ReportOut.from_result(result)
    frame = Pose.from_matrix(result.frame).as_array()
    crud.store_result(db, s, frame, report.model_dump(mode="json"))
    s.target_version = _target_slot(db, s).version
    set_etag(response, db, s)
    emit(db, "calibration-computed", crud.get_controller(db, controller_id), {
        "session_id": s.id, "method": s.method, "table": s.target_table, "number": s.target_no,
        "frame": dict(zip("xyzabc", frame.tolist())), "rms_error_mm": report.rms_error_mm,
        "max_error_mm": report.max_error_mm, "position_bound95_mm": report.position_bound95_mm})
    return report


KIND_WORDS = {"tool": "tool", "workpiece": "robot-held workpiece", "base": "base",
              "fixed_tool": "fixed tool", "coordinated_base": "base on an external kinematic"}


def _auto_name(kind: str, number: int) -> str:
    return f"{kind}{number}"


def slot_conflict(spec: Any, e: Any, number: int) -> str | None:
    """Why saving ``spec``'s result into tool/base slot ``e`` needs the person's word, or None.

    A slot keeps its kind and its name unless the person says otherwise: it is asked when the
    slot holds something (values, a name or a provenance) of another kind, or carries a name a
    person or an import gave (not the automatic ``<kind><n>``) and was not written by a
    calibration menu (a re-calibration of a named slot by a menu is not asked again)."""
    occupied = bool(e.name) or e.method is not None or any(e.pose_values())
    if not occupied:
        return None
    what = f"{KIND_WORDS.get(e.kind, e.kind)}{' ' + repr(e.name) if e.name else ''}"
    table = "TOOL" if spec.table == "tool" else "BASE"
    if e.kind != spec.kind:
        return (f"{table} {number} holds a {what}; {spec.name} would turn it into a "
                f"{KIND_WORDS.get(spec.kind, spec.kind)} named "
                f"{_auto_name(spec.kind, number)!r}: save with confirm=true to replace it "
                "(name=... to choose the name), or open the menu on an empty slot")
    if e.name and e.name != _auto_name(e.kind, number) and e.session_id is None:
        return (f"{table} {number} holds the {what} ({e.method or 'typed in'}, not calibrated "
                f"here); save with confirm=true to overwrite its values and keep its name "
                f"(name=... to rename it)")
    return None


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
    s = _session(db, controller_id, session_id, if_match)
    if s.state != "computed":
        raise crud.StateConflict(("path", "session_id"),
                                 f"session {s.id} is {s.state}: compute it before saving")
    spec = spec_of(s)
    e = _target_slot(db, s)
    _check_target_unchanged(db, s, e)
    if s.target_table == ext.TABLE:
        ext.change_slot(db, e, ext.save_values(s, s.result_values(), s.report or {}),
                        reason="calibration", session_id=s.id)
        crud.close_session(db, s, "saved")
        set_etag(response, db, s)
        return ext_slot_out(e)
    why = slot_conflict(spec, e, s.target_no)
    if why is not None and not confirm:
        raise crud.StateConflict(("query", "confirm"), why)
    if name is not None:
        from server.service.bounds import check_name
        check_name(name, ("query", "name"))
    r = s.result_values()
    keys = POSE_KEYS[:3] if spec.writes == "xyz" else POSE_KEYS  # XYZ menus keep A, B, C
    values: dict[str, Any] = dict(zip(keys, r))  # type: ignore[arg-type]
    report = s.report or {}
    values.update(kind=spec.kind, method=spec.name, session_id=s.id,
                  error_max_mm=report.get("max_error_mm"), error_rms_mm=report.get("rms_error_mm"))
    if spec.kind == "coordinated_base":  # ext.offset: the base rides on EX_KIN ext_no
        values["mech_unit"] = ext.mech_unit(db, s.controller_id, s.params["ext_no"])
    if name is not None:
        values["name"] = name
    elif not e.name or e.kind != spec.kind:  # a slot of another kind does not keep its name
        values["name"] = _auto_name(spec.kind, s.target_no)
    crud.change_entry(db, e, values, reason="calibration", session_id=s.id)
    crud.close_session(db, s, "saved")
    set_etag(response, db, s)
    return entry_out(e)


def _target_slot(db: SessionDep, s):  # noqa: ANN001, ANN202
    """The slot session ``s`` writes: a tool or base slot, or an external kinematic."""
    if s.target_table == ext.TABLE:
        return ext.get_slot(db, s.controller_id, s.target_no)
    return crud.get_entry(db, s.controller_id, s.target_table, s.target_no)


def _check_target_unchanged(db: SessionDep, s, e) -> None:  # noqa: ANN001
    """409 naming the change when slot ``e`` is not the version session ``s`` computed on."""
    if s.target_version is None or e.version == s.target_version:
        return
    table = getattr(e, "entry_table", s.target_table)
    changes = crud.history(db, s.controller_id, table, e.number)
    last = changes[-1] if changes else None
    what = "" if last is None else (
        f": last changed by {last.reason}"
        + (f" of session {last.session_id}" if last.session_id else "")
        + f" at {last.changed_at.isoformat(timespec='seconds')} (history {last.id})")
    raise crud.StateConflict(("path", "session_id"), f"{table} {e.number} changed after "
                             f"session {s.id} was computed{what}; saving would overwrite it "
                             "blind: compute again (or discard)")


@router.post(PREFIX + "/{session_id}/discard")
def discard(controller_id: int, session_id: int, db: SessionDep, response: Response,
            if_match: IfMatch = None) -> SessionOut:
    """Close the session without writing anything."""
    s = _session(db, controller_id, session_id, if_match)
    crud.require_open(s)
    crud.close_session(db, s, "discarded")
    set_etag(response, db, s)
    return session_out(s)


# ------------------------------------------------------------------------- light barrier

def _light_barrier_session(db: SessionDep, controller_id: int, session_id: int,
                           if_match: str | None = None):  # noqa: ANN202
    s = _session(db, controller_id, session_id, if_match)
    crud.require_open(s)
    if s.method != "tool.light_barrier":
        raise CalibrationError(("method",), f"session {s.id} is {s.method}; the cycle belongs to "
                               "tool.light_barrier")
    return s


def _nominal_tool(db: SessionDep, s) -> np.ndarray:  # noqa: ANN001
    """T_flange_tcp the cycle is planned for: params.nominal_tool, else the target slot."""
    if s.params.get("nominal_tool"):
        return Pose(**s.params["nominal_tool"]).as_matrix()
    nominal = entry_matrix(crud.get_entry(db, s.controller_id, "tool", s.target_no))
    if np.allclose(nominal[:3, 3], 0.0):
        raise CalibrationError(("params", "nominal_tool"), f"tool {s.target_no} is empty: give "
                               "the nominal TCP (the tool's drawing length) for the cycle")
    return nominal


@router.post(PREFIX + "/{session_id}/run-cycle")
def run_cycle(controller_id: int, session_id: int, db: SessionDep, response: Response,
              if_match: IfMatch = None) -> RunCycleOut:
    """Run the light-barrier measuring cycle on the emulated robot and sensor; every beam
    trigger becomes a taught point (replacing earlier ones)."""
    c = crud.get_controller(db, controller_id)
    s = _light_barrier_session(db, controller_id, session_id, if_match)
    cell = cell_of(c)
    params = dict(s.params)
    if not params.get("beams"):
        params["beams"] = cell.public()["beams"]
        params.setdefault("tool_diameter_mm", cell.tool_diameter_mm)
        s.params = params
    if "tool_diameter_mm" not in params:
        raise CalibrationError(("params", "tool_diameter_mm"),
                               "required with your own beams: the shaft diameter")
    nominal = _nominal_tool(db, s)
    beams = resolve_inputs(db, s).beams
    run = emulator.run_beam_cycle(robot_of(c), cell, c.joints_deg, nominal, beams,
                                  float(params["tool_diameter_mm"]),
                                  tuple(params.get("heights_mm") or (10.0, 40.0)),
                                  physics=physics_of(db, c))
    crud.clear_points(db, s)
    for k, ev in enumerate(run.triggers):
        pose = Pose.from_matrix(ev.T_base_flange).as_array()
        crud.put_point(db, s, k, "beam", pose, run.trigger_joints_deg[k], ev.beam_id, ev.edge,
                       ev.tcp_velocity_mm_s, t_s=float(run.trigger_t_s[k]),
                       motion_sign=run.trigger_signs[k])
    store_state(c, emulator.after_cycle(state_of(c), run))
    set_etag(response, db, s)
    return RunCycleOut(triggers=len(run.triggers), passes=run.passes, session=session_out(s))


@router.post(PREFIX + "/{session_id}/beam-recording")
def post_beam_recording(controller_id: int, session_id: int, db: SessionDep, response: Response,
                        recording: dict[str, Any] = Body(...),
                        if_match: IfMatch = None) -> SessionOut:
    """Take the triggers of a ``robot-recording/1`` document of kind ``beam`` (a real
    controller's cycle) as the session's points; its sensor block becomes the params."""
    from server.formats.recording import parse_recording

    s = _light_barrier_session(db, controller_id, session_id, if_match)
    rec = parse_recording(recording)
    if rec.kind != "beam":
        raise CalibrationError(("kind",),
                               f"must be 'beam' for the light-barrier menu, got {rec.kind!r}")
    T = forward_kinematics(rec.robot, rec.joints_deg)
    params = dict(s.params)
    params["beams"] = [{"id": k, "point_mm": jsonable(p), "direction": jsonable(d)}
                       for k, (p, d) in rec.beams.items()]
    params["tool_diameter_mm"] = rec.tool_diameter_mm
    s.params = params
    crud.clear_points(db, s)
    for k in range(rec.n_samples):
        vel = None if rec.tcp_velocity_mm_s is None else rec.tcp_velocity_mm_s[k]
        crud.put_point(db, s, k, "beam", Pose.from_matrix(T[k]).as_array(), rec.joints_deg[k],
                       str(rec.beam_ids[k]), str(rec.edges[k]), vel, t_s=float(rec.t_s[k]))
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
    from server.formats.recording import to_document
    from solvers.recording import MIN_SAMPLES, RecordingData
    from solvers.simulate import decoupled_arm

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
        tool = _nominal_tool(db, s)
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
