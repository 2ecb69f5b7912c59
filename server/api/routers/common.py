"""What several menus show alike: slots and sessions as ``...Out``. The arm, the cell and a
session's steps are the service's (``server.service.robot``, ``server.service.sessions``)."""

from __future__ import annotations

from db.models import CalibSession, FrameEntry, TaughtPoint
from server.api.schemas import (EntryOut, LoadOut, PointOut, PoseOut, ProvenanceOut, ReportOut,
                                SessionOut, StepOut)
from server.menus.methods import Step
from server.service.sessions import spec_of


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


# -------------------------------------------------------------------------------- sessions

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
                      created_at=s.created_at, opened_by=s.opened_by)


def step_out(i: int, st: Step, required: bool, p: TaughtPoint | None) -> StepOut:
    return StepOut(index=i, prompt=st.prompt, required=required, filled=p is not None,
                   target=st.target, tilt_deg=st.tilt_deg, around_deg=st.around_deg % 360.0,
                   spin_deg=st.spin_deg,
                   tool_point_mm=None if st.tool_point_mm is None else list(st.tool_point_mm),
                   point=None if p is None else point_out(p),
                   external_axes=None if st.external_axes is None else dict(st.external_axes))
