"""Pydantic models of the API: ``...In`` bodies (``extra="forbid"``, finite numbers) and ``...Out``.

Units are in the field names (``_mm``, ``_deg``, ``_kg``). A pose is ``{x, y, z, a, b, c}``:
mm and KUKA A, B, C degrees, ``R = Rz(a) Ry(b) Rx(c)``.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (AfterValidator, BaseModel, ConfigDict, Field, ValidationInfo,
                      field_validator, model_validator)

from server.api.limits import IMPORT_LIMIT_BYTES
from server.service.bounds import (MAX_MM, MECH_UNIT_CHARS, ClockS, NAME_CHARS, Deg, Kg, Kgm2,
                                   Mm, Text, check_given_name)
from server.menus import METHODS
from solvers.frames import Pose
from solvers.report import CalibrationResult

# Magnitudes no cell has (server/service/bounds.py, the same on every path): beyond them a number is a
# typo or the wrong unit, so the request is refused naming the field.
Physical = Annotated[float, Field(ge=-1e3, le=1e3)]  # an imperfection of the emulated arm

MethodName = Literal[tuple(METHODS)]  # type: ignore[valid-type]
EntryKind = Literal["tool", "workpiece", "base", "fixed_tool", "coordinated_base"]
SessionState = Literal["open", "computed", "saved", "discarded"]
SlotName = Annotated[str, Field(max_length=NAME_CHARS),
                     AfterValidator(lambda v: check_given_name(v, ("name",)))]
TableName = Literal["tool", "base"]
Vec3 = Annotated[list[Mm], Field(min_length=3, max_length=3)]
ExportFormat = Literal["kuka", "abb", "fanuc", "ur", "json", "kuka_machine", "abb_moc"]
ImportFormat = Literal["kuka", "abb", "fanuc", "ur", "json"]


class In(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class Out(BaseModel):
    model_config = ConfigDict(extra="forbid")


# ------------------------------------------------------------------------------------ poses

class PoseIn(In):
    """x, y, z (mm), a, b, c (deg), KUKA ``R = Rz(a) Ry(b) Rx(c)``."""

    x: Mm = 0.0
    y: Mm = 0.0
    z: Mm = 0.0
    a: Deg = 0.0
    b: Deg = 0.0
    c: Deg = 0.0

    def to_pose(self) -> Pose:
        return Pose(self.x, self.y, self.z, self.a, self.b, self.c)


class PoseOut(Out):
    x: float
    y: float
    z: float
    a: float
    b: float
    c: float

    @classmethod
    def of(cls, values: object) -> "PoseOut":
        v = [round(float(x), 6) + 0.0 for x in values]  # type: ignore[union-attr]
        return cls(x=v[0], y=v[1], z=v[2], a=v[3], b=v[4], c=v[5])

    @classmethod
    def exact(cls, values: object) -> "PoseOut":
        """A stored slot's pose with every digit (a client that writes it back changes
        nothing; JSON numbers carry the double exactly)."""
        v = [float(x) + 0.0 for x in values]  # type: ignore[union-attr]
        return cls(x=v[0], y=v[1], z=v[2], a=v[3], b=v[4], c=v[5])

    @classmethod
    def of_matrix(cls, T: object) -> "PoseOut":
        p = Pose.from_matrix(np.asarray(T, dtype=float))
        return cls.of(p.as_array())


# ------------------------------------------------------------------------------ controllers

class DHJointIn(In):
    a_mm: Mm
    alpha_deg: Deg
    d_mm: Mm
    offset_deg: Deg = 0.0
    direction: Literal[1, -1] = 1
    q_min_deg: Deg = -360.0
    q_max_deg: Deg = 360.0

    @model_validator(mode="after")
    def _limits_ordered(self) -> "DHJointIn":
        if not self.q_min_deg < self.q_max_deg:
            raise ValueError(f"q_min_deg ({self.q_min_deg:g}) must be below q_max_deg "
                             f"({self.q_max_deg:g})")
        return self


class RobotIn(In):
    """A custom arm: DH table (standard or modified), mounting and flange poses."""

    name: Text = Field("custom", max_length=64)
    dh_convention: Literal["standard", "modified"]
    joints: list[DHJointIn] = Field(min_length=1, max_length=7)
    base_pose: PoseIn | None = None
    flange_pose: PoseIn | None = None
    reach_mm: float | None = Field(None, gt=0, le=MAX_MM)


class ControllerIn(In):
    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.\-]+$")
    robot: str | None = Field("kuka_kr6_r900_sixx",
                              description="library key of solvers.robots.ROBOTS")
    custom_robot: RobotIn | None = None
    cell_seed: int = Field(1, ge=0, le=2**32 - 1,
                           description="seed of the emulated cell's hidden truth")
    external_axes: bool = Field(False, description="the cell gets a turntable (E1), a tilt and "
                                "turn positioner (E2, E3) and a rail carrying the robot (E4)")


class ControllerOut(Out):
    id: int
    name: str
    robot: str | None
    robot_name: str
    dh_convention: str
    dof: int
    joints_deg: list[float]
    active_tool_no: int
    active_base_no: int


# ------------------------------------------------------------------------------------ robot

class RobotStateOut(Out):
    joints_deg: list[float]
    limits_deg: list[list[float]]
    active_tool_no: int
    active_base_no: int
    flange_pose: PoseOut  # T_world_flange
    tcp_pose: PoseOut  # active TCP in the active base
    external_axes: dict[str, float] | None = Field(
        None, description="E1..E4 (deg; the rail E4 in mm) of a cell with external axes")
    external_limits: dict[str, list[float]] | None = None


class JointsIn(In):
    joints_deg: list[Deg] = Field(min_length=1, max_length=7)


class JogIn(In):
    mode: Literal["joint", "world", "base", "tool"]
    axis: Literal["A1", "A2", "A3", "A4", "A5", "A6", "A7", "X", "Y", "Z", "A", "B", "C",
                  "E1", "E2", "E3", "E4", "E5", "E6"]
    increment: float = Field(description="mm for X, Y, Z and a rail; degrees for joints, "
                                         "rotary external axes and A, B, C",
                             ge=-100.0, le=100.0)


ExtAxis = Literal["E1", "E2", "E3", "E4", "E5", "E6"]
EXT_AXIS_LIMIT = 1e4  # a recorded external axis value, deg (a rail: mm), within ± this


class ExternalAxesIn(In):
    """Move external axes to these values (deg; a rail in mm); omitted axes stay."""

    values: dict[ExtAxis, Annotated[float, Field(ge=-1e4, le=1e4)]] = Field(min_length=1)


class ActiveIn(In):
    tool_no: int | None = Field(None, ge=0, le=16, strict=True, description="0 = flange")
    base_no: int | None = Field(None, ge=0, le=32, strict=True, description="0 = world")


AIM_NOISE_MM = 0.1  # a person's eye on a reference tip, per axis (|miss| about 0.16 mm)


class ApproachIn(In):
    """Jog the true tip (or workpiece mark) onto a cell target from an orientation."""

    target: str = Field(min_length=1, max_length=64)
    tilt_deg: float = Field(0.0, ge=0.0, le=80.0,
                            description="tool axis tilt from the target's normal")
    around_deg: Deg = Field(0.0, description="azimuth of the tilt about the target's normal")
    spin_deg: Deg = Field(0.0, description="rotation of the tool about its own axis")
    tool_point_mm: Vec3 | None = Field(None,
                                       description="another point of the held body (its frame)")
    miss_mm: Vec3 | None = Field(None, description="miss the target by this vector (world, mm)")
    flange_orientation: Annotated[list[Vec3], Field(min_length=3, max_length=3)] | None = Field(
        None, description="the flange's orientation in world (3x3 rotation matrix, rows), e.g. "
                          "a report's next_orientation; replaces tilt/around/spin")
    noise_mm: float = Field(AIM_NOISE_MM, ge=0.0, le=5.0,
                            description="the operator's aim: each axis stops off the mark by a "
                                        "normal error of this sigma (mm), seeded by the cell and "
                                        "its motion count, so a walk-through repeats; 0 = ideal "
                                        "aim (exactly on the mark)")


class CellOut(Out):
    targets: list[str]
    base_points_mm: dict[str, list[float]]
    workpiece_points_mm: dict[str, list[float]]
    beams: list[dict[str, Any]]
    tool_diameter_mm: float



CyclicError = Annotated[list[Physical], Field(min_length=2, max_length=2,
                                           description="[amplitude_deg, periods_per_rev]")]


class PhysicsIn(In):
    """The emulated arm's hidden imperfections (``solvers.physics.Imperfections``); an omitted
    field is no such effect, ``{}`` the rigid arm. Per-joint lists have one value per joint."""

    joint_offset_deg: list[Physical] | None = Field(None,
                                                    description="true minus shown, per joint")
    dh_delta: dict[str, Physical] = Field(default_factory=dict,
                                       description='true minus nominal DH, {"a_mm:2": 0.3}; '
                                                   "a_mm, d_mm or alpha_deg of joint 1..n")
    compliance_deg_per_Nm: list[Physical] | None = Field(None,
                                                         description="joint yield per torque")
    backlash_deg: list[Physical] | None = Field(None, description="full lost motion per joint")
    thermal_drift_mm: Physical = Field(0.0, description="base shift reached after the warm-up hour")
    thermal_direction: Vec3 = Field([0.0, 0.0, 1.0], description="direction of the drift")
    trigger_latency_ms: Physical = Field(0.0, description="light barrier: recorded this much later")
    tool_deflection_mm_per_N: Physical = Field(0.0, description="tool tip bending per N of payload "
                                                             "weight across the tool axis")
    cyclic_error: dict[str, CyclicError] = Field(default_factory=dict,
                                                 description='{"3": [0.02, 4]} gear ripple')
    noise_mm: Physical = Field(0.0, description="operator's aim / trigger jitter, std per axis")


class PhysicsOut(Out):
    joint_offset_deg: list[float] | None
    dh_delta: dict[str, float]
    compliance_deg_per_Nm: list[float] | None
    backlash_deg: list[float] | None
    thermal_drift_mm: float
    thermal_direction: list[float]
    trigger_latency_ms: float
    tool_deflection_mm_per_N: float
    cyclic_error: dict[str, list[float]]
    noise_mm: float
    rigid: bool = Field(description="no effect and no noise: the emulator is the model exactly")


class ClockIn(In):
    clock_s: ClockS = Field(description="emulated seconds since the cell was powered "
                                        "(0..1e9; server/service/bounds.py)")


class ClockOut(Out):
    clock_s: float
    thermal_warmup_s: float = Field(description="the thermal drift is complete after this time")

# ------------------------------------------------------------------------------------ tables

class LoadIn(In):
    mass_kg: Kg
    com_mm: Vec3 = [0.0, 0.0, 0.0]
    inertia_kgm2: Annotated[list[Kgm2], Field(min_length=3, max_length=3)] = [0.0, 0.0, 0.0]
    inertia_axes_deg: Annotated[list[Deg], Field(min_length=3, max_length=3)] = [0.0, 0.0, 0.0]


class LoadOut(Out):
    mass_kg: float
    com_mm: list[float]
    inertia_kgm2: list[float]
    inertia_axes_deg: list[float] = [0.0, 0.0, 0.0]


class ProvenanceOut(Out):
    method: str | None
    session_id: int | None
    error_max_mm: float | None
    error_rms_mm: float | None
    updated_at: datetime | None
    updated_by: str | None = Field(None, description="the user who last changed the slot")


class PosePatchIn(In):
    """A slot's pose in a partial update: the components given replace the stored ones; the
    others keep their stored value to the last digit (JSON Merge Patch, RFC 7396)."""

    x: Mm | None = None
    y: Mm | None = None
    z: Mm | None = None
    a: Deg | None = None
    b: Deg | None = None
    c: Deg | None = None

    def merged(self, stored: tuple[float, ...]) -> tuple[float, ...]:
        """The stored x, y, z, a, b, c with the given components replaced."""
        given = (self.x, self.y, self.z, self.a, self.b, self.c)
        return tuple(float(s) if g is None else float(g) for g, s in zip(given, stored))


class LoadPatchIn(In):
    """A slot's load in a partial update: what is given replaces, the rest stays (a slot
    without a load starts from mass 0 with zero centre of mass and inertia)."""

    mass_kg: Kg | None = None
    com_mm: Vec3 | None = None
    inertia_kgm2: Annotated[list[Kgm2], Field(min_length=3, max_length=3)] | None = None
    inertia_axes_deg: Annotated[list[Deg], Field(min_length=3, max_length=3)] | None = None


class EntryIn(In):
    """Edit a slot by hand (numeric input without a session): JSON Merge Patch semantics.

    Omitted fields stay as they are, also inside ``pose`` and ``load`` (``{"pose": {"x":
    12.5}}`` changes X alone); ``"load": null`` removes the load ("not set")."""

    name: SlotName | None = None
    kind: EntryKind | None = None
    pose: PosePatchIn | None = None
    load: LoadPatchIn | None = None
    mech_unit: str | None = Field(None, min_length=1, max_length=MECH_UNIT_CHARS,
                                  description="coordinated_base: the mechanical unit moving it")


class EntryOut(Out):
    table: TableName
    number: int
    name: str
    kind: EntryKind
    pose: PoseOut
    load: LoadOut | None
    mech_unit: str | None = None
    provenance: ProvenanceOut


class HistoryOut(Out):
    id: int
    table: TableName
    number: int
    reason: str
    session_id: int | None
    changed_at: datetime
    before: dict[str, Any]
    after: dict[str, Any]
    changed_by: str | None = None  # the user (revision 0003_auth); None before it or restored


# ------------------------------------------------------------------- external kinematics

ExtKind = Literal["none", "turntable", "positioner", "linear_unit"]


class ExtSlotIn(In):
    """Edit an external kinematic by hand (its machine data); omitted fields stay."""

    name: SlotName | None = None
    kind: ExtKind | None = None
    axes: list[ExtAxis] | None = Field(None, max_length=2,
                                       description="its external axes, e.g. [\"E2\", \"E3\"]")
    root: PoseIn | None = Field(None, description="T_base_root: z the axis (a linear unit: z "
                                "the travel direction)")
    flange: PoseIn | None = Field(None, description="the flange offset (a positioner: its turn "
                                  "axis' root in the tilt flange)")
    scale: float | None = Field(None, gt=0.5, lt=2.0, description="turn or travel per counted "
                                "unit")


class ExtSlotOut(Out):
    number: int
    name: str
    kind: ExtKind
    axes: list[str]
    root: PoseOut
    flange: PoseOut
    scale: float | None
    provenance: ProvenanceOut


class ExtHistoryOut(HistoryOut):
    table: Literal["extkin"]  # type: ignore[assignment]


class ExternalErrorsIn(In):
    """The emulated external machines' hidden errors (emulator.external.ERROR_FIELDS); an
    omitted machine or field has no such error."""

    turntable: dict[str, float] = Field(default_factory=dict, description="tilt_deg, "
                                        "root_offset_mm, sign, scale")
    positioner: dict[str, float] = Field(default_factory=dict, description="tilt_deg, "
                                         "root_offset_mm, sign, scale, turn_tilt_deg, "
                                         "axis_offset_mm, turn_sign")
    rail: dict[str, float] = Field(default_factory=dict, description="direction_tilt_deg, sign, "
                                   "scale")


# ---------------------------------------------------------------------------------- sessions

class BeamIn(In):
    id: Text = Field(min_length=1, max_length=32)
    point_mm: Vec3
    direction: Vec3


class SessionParamsIn(In):
    tool_no: int | None = Field(None, ge=1, le=16, strict=True)  # strict: true is no slot
    reference_tool_no: int | None = Field(None, ge=1, le=16, strict=True)
    fixed_tool_no: int | None = Field(None, ge=1, le=32, strict=True)
    known_points_mm: list[Vec3] | None = Field(None, min_length=4, max_length=64)
    pose: PoseIn | None = None
    beams: list[BeamIn] | None = Field(None, min_length=1)
    tool_diameter_mm: float | None = Field(None, gt=0, le=MAX_MM)
    nominal_tool: PoseIn | None = Field(None,
                                        description="light barrier: nominal TCP for the cycle")
    heights_mm: list[Mm] | None = Field(None, min_length=2, max_length=4)
    ext_no: int | None = Field(None, ge=1, le=6, strict=True,
                               description="ext.offset: the external kinematic the base rides on")
    axis: ExtAxis | None = Field(None, description="ext.root_point / ext.linear_unit: the "
                                 "kinematic's axis to read (default its first)")


class SessionIn(In):
    method: MethodName
    target_no: int = Field(ge=1, le=999, strict=True,
                           description="tool (1-16) or base (1-32) slot to calibrate")
    params: SessionParamsIn = SessionParamsIn()


class TouchUpIn(In):
    """Fill a step: no body = the emulated robot's current joints; or joints / a flange pose
    recorded on a real controller. ``step`` defaults to the first empty step."""

    step: int | None = Field(None, ge=0, strict=True)
    joints_deg: list[Deg] | None = Field(None, min_length=1, max_length=7)
    flange_pose: PoseIn | None = None
    external_axes: dict[ExtAxis, Annotated[float, Field(ge=-EXT_AXIS_LIMIT,
                                                        le=EXT_AXIS_LIMIT)]] | None = Field(
        None, description="with joints_deg / flange_pose: the external axis values recorded "
                          "with them (deg; a rail in mm)")


class PointOut(Out):
    step: int
    source: str
    joints_deg: list[float] | None
    flange_pose: PoseOut
    beam_id: str | None = None
    edge: str | None = None
    velocity_mm_s: list[float] | None = None
    created_at: datetime
    external_axes: dict[str, float] | None = None


class StepOut(Out):
    index: int
    prompt: str
    required: bool
    filled: bool
    target: str | None
    tilt_deg: float
    around_deg: float
    spin_deg: float
    tool_point_mm: list[float] | None
    point: PointOut | None
    external_axes: dict[str, float] | None = Field(
        None, description="ext menus: the external axis values to move to before the target")


class FindingOut(Out):
    code: str
    message: str
    loc: list[str | int]
    severity: str


class BadPointOut(Out):
    index: int
    residual_mm: float
    threshold_mm: float
    refit_frame: PoseOut
    refit_rms_mm: float
    message: str


def _bad_point_words(bp: Any, residual_in_fit_mm: float) -> str:
    """The bad point once, both its numbers explained: the leave-one-out distance (what the
    test judges) and its residual in the fit with it (its bar in the chart), and the refit."""
    return (f"{bp.message()}. Its bar, {residual_in_fit_mm:.3f} mm, is its residual in the fit "
            f"that includes it, which it pulls towards itself; without it the RMS residual is "
            f"{float(bp.refit_rms_mm):.3f} mm")


class ReportOut(Out):
    method: str
    frame: PoseOut
    residuals_mm: list[float]
    residuals_deg: list[float] | None
    max_error_mm: float
    mean_error_mm: float
    rms_error_mm: float
    max_error_deg: float | None
    worst_point: int | None
    parameter_names: list[str]
    covariance: list[list[float]] | None
    sigma_mm: float | None
    sigma_source: Literal["residual", "assumed"] | None
    dof: int | None
    position_bound95_mm: float | None
    angle_bound95_deg: float | None
    mahalanobis_bound95: float | None
    tre_mm: float | None
    bad_point: BadPointOut | None
    warnings: list[FindingOut]
    guidance: str | None
    next_orientation: list[list[float]] | None
    extras: dict[str, Any]

    @classmethod
    def from_result(cls, result: CalibrationResult) -> "ReportOut":
        r = result.report
        bp = r.bad_point
        return cls(
            method=result.method, frame=PoseOut.of_matrix(result.frame),
            residuals_mm=jsonable(r.residuals_mm),
            residuals_deg=None if r.residuals_deg is None else jsonable(r.residuals_deg),
            max_error_mm=r.max_error_mm, mean_error_mm=r.mean_error_mm, rms_error_mm=r.rms_error_mm,
            max_error_deg=r.max_error_deg, worst_point=r.worst_point,
            parameter_names=list(r.parameter_names),
            covariance=None if r.covariance is None else jsonable(r.covariance),
            sigma_mm=_opt(r.sigma_mm), sigma_source=r.sigma_source, dof=r.dof,
            position_bound95_mm=_opt(r.position_bound95_mm),
            angle_bound95_deg=_opt(r.angle_bound95_deg),
            mahalanobis_bound95=_opt(r.mahalanobis_bound95), tre_mm=_opt(r.tre_mm),
            bad_point=None if bp is None else BadPointOut(
                index=bp.index, residual_mm=float(bp.residual_mm),
                threshold_mm=float(bp.threshold_mm),
                refit_frame=PoseOut.of_matrix(bp.refit_frame), refit_rms_mm=float(bp.refit_rms_mm),
                message=_bad_point_words(bp, float(r.residuals_mm[bp.index]))),
            warnings=[FindingOut(code=f.code, message=f.message, loc=list(f.loc),
                                 severity=f.severity) for f in r.warnings],
            guidance=r.guidance,
            next_orientation=None if r.next_orientation is None else jsonable(r.next_orientation),
            extras=jsonable(dict(r.extras)))


class SessionOut(Out):
    id: int
    controller_id: int
    method: str
    title: str
    state: SessionState
    target_table: Literal["tool", "base", "extkin"]
    target_no: int
    params: dict[str, Any]
    steps: list[StepOut]
    extra_steps_allowed: int
    result: PoseOut | None
    report: ReportOut | None
    created_at: datetime
    opened_by: str | None = Field(description="Who opened the session (the user name "
                                  "the audit records); null for one opened before it was recorded")


class BeamRecordingIn(BaseModel):
    """A ``robot-recording/1`` document of kind ``beam``; validated by server/formats/recording.py."""

    model_config = ConfigDict(extra="allow")


class RunCycleOut(Out):
    triggers: int
    passes: int
    session: SessionOut


# ------------------------------------------------------------------------------ import/export

FILE_CHARS = 5_000_000  # a controller file (KUKA, ABB, FANUC, UR) is far below


class SlotRefIn(In):
    table: TableName
    number: int = Field(ge=1)


class ImportIn(In):
    format: ImportFormat
    text: Text = Field(
        min_length=1, max_length=IMPORT_LIMIT_BYTES,
        description="the file; a controller file has at most 5 000 000 characters, a JSON "
                    "backup as many as the body's 64 MiB limit holds (no NUL)")
    dry_run: bool = Field(False, description="say what would change; write nothing")
    encoding: Literal["utf-8", "cp1252"] = Field(
        "utf-8", description="the file's own encoding (the text as decoded from it): an "
        "export in this format writes the file back in it")
    slots: list[SlotRefIn] | None = Field(
        None, description="apply only these slots of the file (the preview's tick boxes); "
        "the others keep what they hold. Default: every slot the file names")

    @field_validator("text")
    @classmethod
    def _file_length(cls, text: str, info: ValidationInfo) -> str:
        fmt = info.data.get("format")
        if fmt != "json" and len(text) > FILE_CHARS:
            raise ValueError(f"a {fmt} controller file has at most {FILE_CHARS} characters, "
                             f"got {len(text)}")
        return text


class SlotChangeOut(Out):
    """One slot a controller file names: before -> after (None = unused)."""

    table: TableName
    number: int
    line: int | None = Field(description="where the file gives the slot")
    before: dict[str, Any] | None
    after: dict[str, Any] | None
    kind_change: str | None = Field(description='"tool -> workpiece" when the kind changes')
    changed: bool


class SkippedOut(Out):
    """A declaration the import left out, with its line and why."""

    line: int
    field: str
    reason: str


class ImportOut(Out):
    format: str
    entries: int
    history: int = 0
    dry_run: bool = False
    slots: list[SlotChangeOut] = []
    skipped: list[SkippedOut] = []


# -------------------------------------------------------------------------------------- util

def _opt(v: object) -> float | None:
    return None if v is None else float(v)  # type: ignore[arg-type]


def jsonable(v: Any) -> Any:
    """numpy arrays and scalars, dataclasses' tuples and Poses as plain JSON values."""
    if isinstance(v, np.ndarray):
        return jsonable(v.tolist())
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if np.isfinite(f) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if isinstance(v, Pose):
        return dict(zip("xyzabc", (float(x) for x in v.as_array())))
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, (str, int, bool)) or v is None:
        return v
    return str(v)
