"""What several menus share: the controller's arm and cell, slots and sessions as ``...Out``,
and the inputs a method needs from the tables. No math: kinematics go through solvers.dh."""

from __future__ import annotations

import numpy as np
from sqlalchemy.orm import Session

from db import crud
from db.models import CalibSession, Controller, FrameEntry, TaughtPoint
from emulator import Cell, ControllerState, cell_for, robot_from_custom
from server.service.external import ext_inputs
from server.menus import METHODS
from server.menus.methods import MethodInputs, MethodSpec, Step, TaughtData
from server.api.schemas import (EntryOut, LoadOut, PointOut, PoseOut, ProvenanceOut, ReportOut,
                            SessionOut, StepOut)
from solvers.dh import RobotModel, check_joint_limits, forward_kinematics
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.robots import ROBOTS


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


# --------------------------------------------------------------------------------- entries

def entry_out(e: FrameEntry) -> EntryOut:
    load = None
    if e.mass_kg is not None:
        com = [e.com_x_mm, e.com_y_mm, e.com_z_mm]
        inertia = [e.inertia_x_kgm2, e.inertia_y_kgm2, e.inertia_z_kgm2]
        axes = [e.inertia_a_deg, e.inertia_b_deg, e.inertia_c_deg]
        load = LoadOut(mass_kg=e.mass_kg, com_mm=[v or 0.0 for v in com],
                       inertia_kgm2=[v or 0.0 for v in inertia],
                       inertia_axes_deg=[v or 0.0 for v in axes])
    provenance = ProvenanceOut(method=e.method, session_id=e.session_id,
                               error_max_mm=e.error_max_mm, error_rms_mm=e.error_rms_mm,
                               updated_at=e.updated_at, updated_by=e.updated_by)
    return EntryOut(table=e.entry_table, number=e.number, name=e.name,  # type: ignore[arg-type]
                    kind=e.kind, pose=PoseOut.exact(e.pose_values()),  # type: ignore[arg-type]
                    load=load, mech_unit=e.mech_unit, provenance=provenance)


def load_values(load: object | None) -> dict:
    if load is None:
        return {}
    com, inertia = load.com_mm, load.inertia_kgm2  # type: ignore[attr-defined]
    axes = getattr(load, "inertia_axes_deg", (0.0, 0.0, 0.0))
    return {"mass_kg": load.mass_kg,  # type: ignore[attr-defined]
            "com_x_mm": com[0], "com_y_mm": com[1], "com_z_mm": com[2],
            "inertia_x_kgm2": inertia[0], "inertia_y_kgm2": inertia[1],
            "inertia_z_kgm2": inertia[2], "inertia_a_deg": axes[0], "inertia_b_deg": axes[1],
            "inertia_c_deg": axes[2]}


# -------------------------------------------------------------------------------- sessions

def spec_of(s: CalibSession) -> MethodSpec:
    return METHODS[s.method]


def step_list(s: CalibSession) -> list[Step]:
    """Required steps, then the extra steps already taught."""
    spec = spec_of(s)
    steps = spec.step_prompts(s.params)
    taught = {p.step for p in s.points}
    extra = sorted(k for k in taught if k >= len(steps))
    return steps + [spec.extra_step(k - len(steps)) for k in extra]


def point_out(p: TaughtPoint) -> PointOut:
    vel = None if p.vx_mm_s is None else [p.vx_mm_s, p.vy_mm_s, p.vz_mm_s]
    return PointOut(step=p.step, source=p.source, joints_deg=p.joints_deg,
                    flange_pose=PoseOut.of(p.pose_values()), beam_id=p.beam_id, edge=p.edge,
                    velocity_mm_s=vel, created_at=p.created_at, external_axes=p.external_axes)


def session_out(s: CalibSession) -> SessionOut:
    spec = spec_of(s)
    n_required = len(spec.step_prompts(s.params))
    by_step = {p.step: p for p in s.points}
    taught_extra = sorted(k for k in by_step if k >= n_required)
    steps = []
    for i, st in enumerate(spec.step_prompts(s.params)):
        steps.append(step_out(i, st, True, by_step.get(i)))
    for k in taught_extra:
        steps.append(step_out(k, spec.extra_step(k - n_required), False, by_step[k]))
    result = s.result_values()
    return SessionOut(id=s.id, controller_id=s.controller_id, method=s.method, title=spec.title,
                      state=s.state, target_table=s.target_table,  # type: ignore[arg-type]
                      target_no=s.target_no, params=s.params, steps=steps,
                      extra_steps_allowed=max(spec.extra_steps - len(taught_extra), 0),
                      result=None if result is None else PoseOut.of(result),
                      report=None if s.report is None else ReportOut.model_validate(s.report),
                      created_at=s.created_at)


def step_out(i: int, st: Step, required: bool, p: TaughtPoint | None) -> StepOut:
    return StepOut(index=i, prompt=st.prompt, required=required, filled=p is not None,
                   target=st.target, tilt_deg=st.tilt_deg, around_deg=st.around_deg % 360.0,
                   spin_deg=st.spin_deg,
                   tool_point_mm=None if st.tool_point_mm is None else list(st.tool_point_mm),
                   point=None if p is None else point_out(p),
                   external_axes=None if st.external_axes is None else dict(st.external_axes))


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
