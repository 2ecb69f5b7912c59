"""Which poses to measure (``pose-plan/1``), and a recording measured at a plan's poses.

- ``POST /plan``: a D-optimal set of joint configurations for the named effects
  (:func:`solvers.analysis.plan.plan_poses`), within the joint limits, with the TCP inside a
  box and above the floor; for a laser tracker or for touching one point.
- ``POST /plan/recording``: a simulated laser-tracker recording at the plan's poses, of an arm
  with the given hidden physics (the body of ``GET /controllers/{id}/cell/physics``), stored
  as a recording (``POST /recordings/{id}/analyze`` then analyses it).

Both compute outside the app's write lock (a plan takes a few seconds; the recording is then
stored in a write of its own, :func:`server.service.transaction.writing`); a bad field is a 422
naming it.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Request
from pydantic import BaseModel, Field
from starlette.concurrency import run_in_threadpool

from server.api import idempotency
from server.service import transaction
from server.service.bounds import Deg, Mm
from server.service.recordings import store_recording
from solvers.analysis.plan import Workspace, parse_effects, plan_poses, record_plan
from solvers.dh import check_joint_limits
from solvers.errors import CalibrationError
from solvers.physics import Imperfections
from solvers.robots import ROBOTS

router = APIRouter(tags=["Analysis"])


class PlanIn(BaseModel):
    robot: str = Field(description="robot key, e.g. ur10 (GET /controllers shows the keys)")
    effects: list[str] = Field(description='effects to identify, e.g. ["joint_compliance:2", '
                                           '"link_length"] (no joint: every joint)')
    n: int = Field(30, ge=6, le=500, description="number of poses")
    workspace: list[Mm] | None = Field(None, min_length=6, max_length=6,
                                          description="box xmin,ymin,zmin,xmax,ymax,zmax (mm, "
                                                      "base frame); default in front of the robot")
    instrument: Literal["tracker", "touch"] = "tracker"
    payload_kg: float = Field(0.0, ge=0.0, le=1000.0, description="payload at 50 mm on flange z")
    noise_mm: float = Field(0.02, gt=0.0, le=10.0, description="for the predicted std")
    seed: int = Field(0, ge=0, le=2**32 - 1)


class PlanRecordingIn(BaseModel):
    robot: str
    joints_deg: list[Annotated[list[Deg], Field(min_length=1, max_length=7)]] = Field(
        min_length=4, description="the plan's poses (each within the robot's joint limits)")
    physics: dict[str, Any] = Field(default_factory=dict,
                                    description="hidden physics (GET .../cell/physics body)")
    payload_kg: float = Field(0.0, ge=0.0, le=1000.0)
    seed: int = Field(0, ge=0, le=2**32 - 1)


def _store(request: Request, doc: dict[str, Any]) -> int:
    with transaction.writing(request.app.state.sessionmaker,
                             operation="record_from_plan") as db:
        if idempotency.has_key(request):  # claimed with the recording it stores
            idempotency.claim(db, request)
        return store_recording(db, doc)


def _robot(key: str):
    if key not in ROBOTS:
        raise CalibrationError(("robot",), "unknown robot; known: " + ", ".join(sorted(ROBOTS)))
    return ROBOTS[key]


def _plan(body: PlanIn) -> dict[str, Any]:
    robot = _robot(body.robot)
    ws = None if body.workspace is None else Workspace.parse(
        ",".join(str(v) for v in body.workspace), robot)
    return plan_poses(robot, parse_effects(body.effects, robot.dof), body.n, workspace=ws,
                      instrument=body.instrument, payload=(body.payload_kg, (0.0, 0.0, 50.0)),
                      noise_mm=body.noise_mm, seed=body.seed)


@router.post("/plan")
async def make_plan(body: PlanIn) -> dict[str, Any]:
    """A D-optimal pose plan (``pose-plan/1``) for the effects; see docs/analysis.md."""
    return await run_in_threadpool(_plan, body)


@router.post("/plan/recording", status_code=201)
async def record_from_plan(request: Request, body: PlanRecordingIn) -> dict[str, Any]:
    """Measure the plan's poses on a simulated arm with ``physics``; stores the recording.
    An ``Idempotency-Key`` works as on every command: its retry answers the stored recording."""
    if idempotency.has_key(request):
        await idempotency.read_body(request)  # a key that is no key: 400 before the work
    robot = _robot(body.robot)
    for k, q in enumerate(body.joints_deg):
        if len(q) != robot.dof:
            raise CalibrationError(("joints_deg", k), f"has {len(q)} values; {robot.name} has "
                                   f"{robot.dof} joints")
        try:
            check_joint_limits(robot, q)
        except CalibrationError as err:
            raise CalibrationError(("joints_deg", k, *err.loc[1:]), err.reason) from None
    physics = {k: v for k, v in body.physics.items() if k != "rigid"}
    try:
        imp = Imperfections.from_dict(physics).check(robot.dof)
    except CalibrationError as err:
        raise CalibrationError(("physics", *err.loc), err.reason) from None
    doc = await run_in_threadpool(lambda: record_plan(
        robot, body.joints_deg, imp, seed=body.seed,
        payload=(body.payload_kg, (0.0, 0.0, 50.0))))
    rid = await run_in_threadpool(_store, request, doc)
    return {"id": rid, "kind": "tracker", "n_samples": len(body.joints_deg), "robot": robot.name}
