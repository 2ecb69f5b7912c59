"""The operations of a menu run (a calibration session): open it, touch up a step, forget a
step, run the light barrier's cycle or take a real one's triggers, compute, save, discard;
and what they share (the method of a session, its steps, the solver's inputs from the tables).

Read top to bottom, a touch-up is: the controller and the session (under the request's write
lock), the caller's ``If-Match``, the step to fill, the flange pose (the emulated arm's joints,
or joints / a flange pose recorded on a real controller), the point written, and the emulated
controller's clock advanced. One transaction: the request's.

Everything a session holds (params, taught points, the computed report) is in the DB, so a
restart of the service loses nothing; a failed compute changes nothing.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sqlalchemy.orm import Session

import emulator
from db import crud
from db.models import EXT_KIN_SLOTS, CalibSession, ExternalKinematic, FrameEntry
from db.outbox import emit
from server.api.schemas import ReportOut, TouchUpIn, jsonable
from server.auth import audit
from server.formats.recording import parse_recording
from server.menus import METHODS
from server.menus.methods import PARAM_HELP, MethodInputs, MethodSpec, Step, TaughtData
from server.service import external as ext
from server.service.bounds import check_given_name
from server.service.external import ext_inputs
from server.service.preconditions import Present, check_row
from server.service.robot import (cell_of, entry_matrix, flange_pose_of, physics_of, robot_of,
                                  state_of, store_state)
from solvers.dh import forward_kinematics
from solvers.errors import CalibrationError
from solvers.frames import Pose

POSE_KEYS = ("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg")


# --------------------------------------------------------------------- a session's method

def spec_of(s: CalibSession) -> MethodSpec:
    return METHODS[s.method]


def step_list(s: CalibSession) -> list[Step]:
    """Required steps, then the extra steps already taught."""
    spec = spec_of(s)
    steps = spec.step_prompts(s.params)
    taught = {p.step for p in s.points}
    extra = sorted(k for k in taught if k >= len(steps))
    return steps + [spec.extra_step(k - len(steps)) for k in extra]


def next_step(s: CalibSession) -> int:
    """The first empty required step, else the next optional one; 409 when none is left."""
    spec = spec_of(s)
    n_required = len(spec.step_prompts(s.params))
    taught = {p.step for p in s.points}
    for k in range(n_required):
        if k not in taught:
            return k
    k = max(taught | {n_required - 1}) + 1
    if k >= n_required + spec.extra_steps:
        raise crud.StateConflict(("body", "step"), f"all {n_required} steps of {s.method} are "
                                 "taught; name a step to re-teach it")
    return k


def check_step(s: CalibSession, step: int) -> None:
    spec = spec_of(s)
    limit = len(spec.step_prompts(s.params)) + spec.extra_steps
    if step >= limit:
        raise CalibrationError(("step",), f"{s.method} has steps 0..{limit - 1}, got {step}")


def _slot_tcp(db: Session, controller_id: int, number: int, loc: str, what: str) -> np.ndarray:
    e = crud.get_entry(db, controller_id, "tool", number)
    if e.x_mm == e.y_mm == e.z_mm == 0.0:
        raise CalibrationError(("params", loc), f"tool {number} is empty (TCP at the flange "
                               f"centre): calibrate {what} first")
    return np.array([e.x_mm, e.y_mm, e.z_mm])


def resolve_inputs(db: Session, s: CalibSession) -> MethodInputs:
    """The solver inputs of a session, read from its params and the controller's tables."""
    p = s.params
    tcp = None
    if p.get("tool_no"):
        tcp = _slot_tcp(db, s.controller_id, p["tool_no"], "tool_no", "the touching tool")
    elif s.method in ("tool.abc_world_5d", "tool.abc_world_6d", "tool.abc_2point"):
        tcp = _slot_tcp(db, s.controller_id, s.target_no, "target_no", "its XYZ (an XYZ menu)")
    ref = None
    if p.get("reference_tool_no"):
        ref = _slot_tcp(db, s.controller_id, p["reference_tool_no"], "reference_tool_no",
                        "the reference tool")
    fixed = None
    if p.get("fixed_tool_no"):
        e = crud.get_entry(db, s.controller_id, "base", p["fixed_tool_no"])
        if e.kind != "fixed_tool":
            raise CalibrationError(("params", "fixed_tool_no"), f"base {e.number} is a {e.kind}, "
                                   "not a fixed tool: calibrate it with Fixed tool > 5D/6D first")
        fixed = np.array([e.x_mm, e.y_mm, e.z_mm])
    known = p.get("known_points_mm")
    known = None if known is None else np.array(known, dtype=float)
    pose = None if p.get("pose") is None else Pose(**p["pose"])
    beams = {b["id"]: (np.array(b["point_mm"], float), np.array(b["direction"], float))
             for b in p.get("beams") or []}
    external = ext_inputs(db, s) if s.method.startswith("ext.") else None
    return MethodInputs(tcp_mm=tcp, reference_tcp_mm=ref, fixed_tcp_mm=fixed, known_mm=known,
                        pose=pose, beams=beams, tool_diameter_mm=p.get("tool_diameter_mm"),
                        external=external)


def taught_data(s: CalibSession) -> list[TaughtData | None]:
    """Points by step (None for a gap) as the solver adapters take them."""
    if not s.points:
        return []
    out: list[TaughtData | None] = [None] * (max(p.step for p in s.points) + 1)
    for p in s.points:
        vel = None if p.vx_mm_s is None else (p.vx_mm_s, p.vy_mm_s, p.vz_mm_s)
        T = Pose(*p.pose_values()).as_matrix()
        out[p.step] = TaughtData(T, p.beam_id, p.edge, vel,  # type: ignore[arg-type]
                                 external_axes=p.external_axes)
    return out


def session(db: Session, controller_id: int, session_id: int, if_match: str | None = None,
            present: Present | None = None) -> CalibSession:
    """The session a command acts on; PreconditionFailed (with ``present(s)``) when
    ``if_match`` is stale."""
    return check_row(if_match, crud.get_session(db, controller_id, session_id), present,
                     f"session {session_id} of controller {controller_id}")


# ------------------------------------------------------------------------------ operations

def open_session(db: Session, controller_id: int, method: str, target_no: int,
                 params: dict[str, Any]) -> CalibSession:
    """Open a menu run on a target slot; the params the method needs are checked now, and the
    slots they name too (an empty touching or reference tool, a base that is no fixed tool).
    The session records who opened it: the user name the audit records for this actor
    (``no-auth`` with auth off, ``cli:USER`` from the CLI, None for the system)."""
    c = crud.get_controller(db, controller_id)
    spec = METHODS[method]
    for p in spec.required:
        if p not in params:
            raise CalibrationError(("params", p), f"required by {spec.name}: {PARAM_HELP[p]}")
    if spec.table in crud.SLOTS and target_no > crud.slot_limit(c, spec.table):
        raise CalibrationError(("target_no",), f"{spec.name} writes a {spec.table} slot "
                               f"(1..{crud.slot_limit(c, spec.table)}), got {target_no}")
    if spec.table in crud.SLOTS:
        crud.ensure_entry(db, c, spec.table, target_no)  # an ABB-kind table grows to it
    if spec.table == "extkin" and target_no > EXT_KIN_SLOTS:
        raise CalibrationError(("target_no",), f"{spec.name} writes an external kinematic "
                               f"(EX_KIN 1..{EXT_KIN_SLOTS}), got {target_no}")
    s = crud.open_session(db, c, spec.name, spec.table, target_no, jsonable(params),
                          opened_by=audit.current().user_name)
    if spec.menu == "ext" or any(k in params for k in ("tool_no", "reference_tool_no",
                                                        "fixed_tool_no")):
        resolve_inputs(db, s)  # an empty touching tool is refused now, not at Compute
    return s


def touch_up(db: Session, controller_id: int, session_id: int, body: TouchUpIn,
             if_match: str | None = None, present: Present | None = None) -> CalibSession:
    """Fill a step of session ``session_id`` (``body.step``, default the next empty one) with
    the emulated robot's current joints, or with ``body.joints_deg`` / ``body.flange_pose``
    recorded on a real controller. A re-teach overwrites the step; a computed result becomes
    stale. 412 when ``if_match`` is not the session's version; 409 when it is closed."""
    c = crud.get_controller(db, controller_id)
    s = session(db, controller_id, session_id, if_match, present)
    crud.require_open(s)
    if body.joints_deg is not None and body.flange_pose is not None:
        raise CalibrationError(("flange_pose",), "give joints_deg or flange_pose, not both")
    step = next_step(s) if body.step is None else body.step
    check_step(s, step)
    if body.flange_pose is not None:
        pose, joints, source = body.flange_pose.to_pose(), None, "flange_pose"
    elif body.joints_deg is not None:
        joints, source = list(body.joints_deg), "joints"
        pose = flange_pose_of(c, joints)
    else:
        joints, source = list(c.joints_deg), "touch_up"
        pose = flange_pose_of(c, joints)
    emulated = source == "touch_up"
    crud.put_point(db, s, step, source, pose.as_array(), joints, t_s=float(c.clock_s or 0.0),
                   motion_sign=c.motion_sign if emulated else None,
                   external_axes=c.external_axes if emulated else body.external_axes)
    store_state(c, emulator.touched_up(state_of(c)))
    return s


def delete_point(db: Session, controller_id: int, session_id: int, step: int,
                 if_match: str | None = None, present: Present | None = None) -> CalibSession:
    """Forget one taught step (to re-teach it)."""
    s = session(db, controller_id, session_id, if_match, present)
    crud.delete_point(db, s, step)
    return s


def compute(db: Session, controller_id: int, session_id: int, if_match: str | None = None,
            present: Present | None = None) -> tuple[CalibSession, ReportOut]:
    """Solve from the session's touch-ups; nothing is written into the table yet. The target
    slot's version is kept: saving refuses a slot that changed after this compute."""
    s = session(db, controller_id, session_id, if_match, present)
    crud.require_open(s)
    spec, points = spec_of(s), taught_data(s)
    spec.check_taught(points, s.params)
    result = ext.solve_in_chain(db, s, spec, points, resolve_inputs(db, s))
    report = ReportOut.from_result(result)
    frame = Pose.from_matrix(result.frame).as_array()
    crud.store_result(db, s, frame, report.model_dump(mode="json"))
    s.target_version = target_slot(db, s).version
    emit(db, "calibration-computed", crud.get_controller(db, controller_id), {
        "session_id": s.id, "method": s.method, "table": s.target_table, "number": s.target_no,
        "frame": dict(zip("xyzabc", frame.tolist())), "rms_error_mm": report.rms_error_mm,
        "max_error_mm": report.max_error_mm, "position_bound95_mm": report.position_bound95_mm})
    return s, report


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


def save(db: Session, controller_id: int, session_id: int, if_match: str | None = None,
         confirm: bool = False, name: str | None = None, present: Present | None = None
         ) -> tuple[CalibSession, FrameEntry | ExternalKinematic]:
    """Write the computed frame into the target slot (XYZ menus keep A, B, C), with provenance
    and a history row; the session and the slot written. Refused (409, saying what changed)
    when the target slot changed after the compute. A tool or base slot keeps its kind and
    name: saving over a slot of another kind, or over a named slot that no menu calibrated
    (imported, typed in), is refused (409 naming its kind and name) unless ``confirm``."""
    s = session(db, controller_id, session_id, if_match, present)
    if s.state != "computed":
        raise crud.StateConflict(("path", "session_id"),
                                 f"session {s.id} is {s.state}: compute it before saving")
    spec = spec_of(s)
    e = target_slot(db, s)
    _check_target_unchanged(db, s, e)
    if s.target_table == ext.TABLE:
        ext.change_slot(db, e, ext.save_values(s, s.result_values(), s.report or {}),
                        reason="calibration", session_id=s.id)
        crud.close_session(db, s, "saved")
        return s, e
    why = slot_conflict(spec, e, s.target_no)
    if why is not None and not confirm:
        raise crud.StateConflict(("query", "confirm"), why)
    if name is not None:
        check_given_name(name, ("query", "name"))
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
    return s, e


def target_slot(db: Session, s: CalibSession) -> FrameEntry | ExternalKinematic:
    """The slot session ``s`` writes: a tool or base slot, or an external kinematic."""
    if s.target_table == ext.TABLE:
        return ext.get_slot(db, s.controller_id, s.target_no)
    return crud.get_entry(db, s.controller_id, s.target_table, s.target_no)


def _check_target_unchanged(db: Session, s: CalibSession,
                            e: FrameEntry | ExternalKinematic) -> None:
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


def discard(db: Session, controller_id: int, session_id: int, if_match: str | None = None,
            present: Present | None = None) -> CalibSession:
    """Close the session without writing anything."""
    s = session(db, controller_id, session_id, if_match, present)
    crud.require_open(s)
    crud.close_session(db, s, "discarded")
    return s


# ------------------------------------------------------------------------- light barrier

def _light_barrier_session(db: Session, controller_id: int, session_id: int,
                           if_match: str | None, present: Present | None) -> CalibSession:
    s = session(db, controller_id, session_id, if_match, present)
    crud.require_open(s)
    if s.method != "tool.light_barrier":
        raise CalibrationError(("method",), f"session {s.id} is {s.method}; the cycle belongs to "
                               "tool.light_barrier")
    return s


def nominal_tool(db: Session, s: CalibSession) -> np.ndarray:
    """T_flange_tcp the cycle is planned for: params.nominal_tool, else the target slot."""
    if s.params.get("nominal_tool"):
        return Pose(**s.params["nominal_tool"]).as_matrix()
    nominal = entry_matrix(crud.get_entry(db, s.controller_id, "tool", s.target_no))
    if np.allclose(nominal[:3, 3], 0.0):
        raise CalibrationError(("params", "nominal_tool"), f"tool {s.target_no} is empty: give "
                               "the nominal TCP (the tool's drawing length) for the cycle")
    return nominal


def run_cycle(db: Session, controller_id: int, session_id: int, if_match: str | None = None,
              present: Present | None = None) -> tuple[CalibSession, emulator.CycleRun]:
    """Run the light-barrier measuring cycle on the emulated robot and sensor; every beam
    trigger becomes a taught point (replacing earlier ones). The session and the cycle run."""
    c = crud.get_controller(db, controller_id)
    s = _light_barrier_session(db, controller_id, session_id, if_match, present)
    cell = cell_of(c)
    params = dict(s.params)
    if not params.get("beams"):
        params["beams"] = cell.public()["beams"]
        params.setdefault("tool_diameter_mm", cell.tool_diameter_mm)
        s.params = params
    if "tool_diameter_mm" not in params:
        raise CalibrationError(("params", "tool_diameter_mm"),
                               "required with your own beams: the shaft diameter")
    nominal = nominal_tool(db, s)
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
    return s, run


def take_beam_recording(db: Session, controller_id: int, session_id: int,
                        recording: dict[str, Any], if_match: str | None = None,
                        present: Present | None = None) -> CalibSession:
    """Take the triggers of a ``robot-recording/1`` document of kind ``beam`` (a real
    controller's cycle) as the session's points; its sensor block becomes the params."""
    s = _light_barrier_session(db, controller_id, session_id, if_match, present)
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
    return s
