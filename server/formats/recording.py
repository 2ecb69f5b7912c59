"""The ``robot-recording/1`` JSON format: pydantic models, parsing, schema, writing.

A recording is what a controller (or a test rig) logged while a robot measured something;
the format is a public contract (``docs/recording-format.md``). Every model forbids unknown
fields and non-finite numbers, and numbers must be JSON numbers (strict: no ``"1.5"``, no
``true``). :func:`parse_recording` turns a document into a
:class:`solvers.recording.RecordingData` or raises :class:`RecordingError` naming the field,
e.g. ``("samples", 12, "joints_deg")``.

Regenerate the committed JSON Schema with::

    python -m server.formats.recording > docs/robot-recording-1.schema.json
"""

from __future__ import annotations

import dataclasses
import json
import re
from datetime import datetime
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import (BaseModel, ConfigDict, Field, TypeAdapter, ValidationError,
                      field_validator, model_validator)

from server.service.bounds import Text
from solvers.dh import DHJoint, RobotModel
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.recording import MIN_SAMPLES, RecordingData, recording_document

FORMAT = "robot-recording/1"
SCHEMA_ID = "urn:pendant:schema:robot-recording-1"


class RecordingError(CalibrationError):
    """A recording that does not follow ``robot-recording/1``; ``loc`` is the JSON path.

    Examples
    --------
    >>> e = RecordingError(("samples", 12, "joints_deg"), "has 5 values; the robot has 6 joints")
    >>> e.loc
    ('samples', 12, 'joints_deg')
    """


MAX_MAGNITUDE = 1e9
"""No number of a recording is larger (mm, deg, s, kg, mm/s): a larger one is a wrong unit or
a corrupt file, and the analysis would overflow to inf/NaN on it."""


def _bounded(v: Any) -> Any:
    """``v`` (a number or a list of numbers) if every number is within :data:`MAX_MAGNITUDE`."""
    values = v if isinstance(v, list) else [v]
    for x in values:
        if isinstance(x, float) and abs(x) > MAX_MAGNITUDE:
            raise ValueError(f"{x:g} is out of range: no value of a recording exceeds "
                             f"{MAX_MAGNITUDE:g} (mm, deg, s, kg) in magnitude; a wrong unit?")
    return v


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)

    _check_magnitude = field_validator("*")(_bounded)


Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


def _nonzero(v: list[float]) -> list[float]:
    if float(np.linalg.norm(v)) < 1e-9:
        raise ValueError("must be a non-zero vector")
    return v


class PoseIn(_Model):
    """x, y, z in mm; a, b, c in degrees: ``R = Rz(a) Ry(b) Rx(c)`` (intrinsic Z, Y', X'')."""

    x: float
    y: float
    z: float
    a: float
    b: float
    c: float

    def to_pose(self) -> Pose:
        return Pose(self.x, self.y, self.z, self.a, self.b, self.c)

    @classmethod
    def from_pose(cls, p: Pose) -> "PoseIn":
        return cls(x=p.x, y=p.y, z=p.z, a=p.a, b=p.b, c=p.c)


class DHRowIn(_Model):
    """One DH row; ``theta = direction * q + offset_deg``."""

    a_mm: float
    alpha_deg: float
    d_mm: float
    offset_deg: float
    direction: Literal[1, -1] = 1


class LinkMassesIn(_Model):
    """The arm's link masses (for its gravity torques): one per joint's link, each link's
    centre of mass in the link's own DH frame (default: the middle of the DH link)."""

    mass_kg: list[float] = Field(min_length=1, description="link 1 first, kg, each >= 0")
    com_mm: list[Vec3] | None = Field(None, description="per link, in its DH frame, mm")

    @field_validator("mass_kg")
    @classmethod
    def _nonnegative(cls, v: list[float]) -> list[float]:
        if any(x < 0 for x in v):
            raise ValueError("every link mass must be >= 0 kg")
        return v


class RobotIn(_Model):
    """The robot's rigid model as the controller knows it."""

    model: str = Field(min_length=1, description="free text; the service matches it to its library")
    dh_convention: Literal["standard", "modified"]
    joints: list[DHRowIn] = Field(min_length=1, description="one DH row per joint, joint 1 first")
    base_pose: PoseIn | None = None
    flange_pose: PoseIn | None = None
    link_masses: LinkMassesIn | None = Field(
        None, description="optional: the arm's link masses; without them the service uses its "
                          "catalogue's (or a generic estimate) and says so")

    @model_validator(mode="after")
    def _masses_per_joint(self) -> "RobotIn":
        lm = self.link_masses
        if lm is not None:
            n = len(self.joints)
            if len(lm.mass_kg) != n:
                raise ValueError(f"link_masses.mass_kg has {len(lm.mass_kg)} values; the robot "
                                 f"has {n} joints")
            if lm.com_mm is not None and len(lm.com_mm) != n:
                raise ValueError(f"link_masses.com_mm has {len(lm.com_mm)} values; the robot "
                                 f"has {n} joints")
        return self


class PayloadIn(_Model):
    """The payload on the flange; its centre of mass in the flange frame."""

    mass_kg: float = Field(ge=0)
    com_mm: Vec3


class BeamIn(_Model):
    """One light beam: a point on it and its direction, robot base frame."""

    id: Text = Field(min_length=1)
    point_mm: Vec3
    direction: Vec3

    _check_direction = field_validator("direction")(_nonzero)


class SensorIn(_Model):
    """A light-barrier sensor: its beams and the tool's shaft diameter."""

    beams: list[BeamIn] = Field(min_length=1)
    tool_diameter_mm: float = Field(gt=0)

    @model_validator(mode="after")
    def _unique_ids(self) -> "SensorIn":
        seen: set[str] = set()
        for i, b in enumerate(self.beams):
            if b.id in seen:
                raise RecordingError(("sensor", "beams", i, "id"),
                                     f"beam id {b.id!r} is used twice")
            seen.add(b.id)
        return self


class SampleIn(_Model):
    """A touch-up: the TCP was on the fixed point."""

    t_s: float = Field(ge=0, description="seconds since the recording began")
    joints_deg: list[float] = Field(min_length=1, description="one value per joint")


class TrackerSampleIn(SampleIn):
    """A pose measured by an external instrument."""

    measured_mm: Vec3 = Field(description="TCP position in the instrument's frame")


class BeamSampleIn(SampleIn):
    """One trigger of one beam."""

    beam: str = Field(min_length=1, description="id of a beam in sensor.beams")
    edge: Literal["enter", "leave", "tip"]
    tcp_velocity_mm_s: Vec3 = Field(description="commanded TCP velocity at the trigger, base frame")

    _check_velocity = field_validator("tcp_velocity_mm_s")(_nonzero)


class _RecordingBase(_Model):
    format: Literal["robot-recording/1"]
    recorded_at: str | None = Field(default=None, description="ISO 8601, e.g. 2026-11-02T08:15:00Z")
    robot: RobotIn
    tool: PoseIn = Field(description="nominal TCP in the flange frame; its z axis is the tool axis")
    payload: PayloadIn | None = None
    start_joints_deg: list[float] | None = None

    @field_validator("recorded_at")
    @classmethod
    def _iso_time(cls, v: str | None) -> str | None:
        if v is not None:
            try:
                if not re.match(r"^\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}", v):
                    raise ValueError("no time of day")
                datetime.fromisoformat(v)
            except ValueError:
                raise ValueError("must be an ISO 8601 time like 2026-11-02T08:15:00Z, "
                                 f"got {v!r}") from None
        return v

    @model_validator(mode="after")
    def _consistent(self) -> "_RecordingBase":
        n = len(self.robot.joints)
        if self.start_joints_deg is not None and len(self.start_joints_deg) != n:
            raise RecordingError(("start_joints_deg",), f"has {len(self.start_joints_deg)} values; "
                                 f"the robot has {n} joints")
        samples = self.samples  # type: ignore[attr-defined]
        kind = self.kind  # type: ignore[attr-defined]
        need = MIN_SAMPLES[kind]
        if len(samples) < need:
            raise RecordingError(("samples",), f"a {kind} recording needs at least {need} "
                                 f"samples, got {len(samples)}")
        for k, s in enumerate(samples):
            if len(s.joints_deg) != n:
                raise RecordingError(("samples", k, "joints_deg"),
                                     f"has {len(s.joints_deg)} values; the robot has {n} joints")
            if k and s.t_s < samples[k - 1].t_s:
                raise RecordingError(("samples", k, "t_s"),
                                     f"{s.t_s} s is before the previous sample's "
                                     f"{samples[k - 1].t_s} s; samples must be in recording order")
        return self


class TouchRecordingIn(_RecordingBase):
    """kind touch: the TCP was brought onto one fixed point, again and again."""

    kind: Literal["touch"]
    samples: list[SampleIn]


class TrackerRecordingIn(_RecordingBase):
    """kind tracker: an external instrument measured the TCP at each pose."""

    kind: Literal["tracker"]
    samples: list[TrackerSampleIn]


class BeamRecordingIn(_RecordingBase):
    """kind beam: a light-barrier sensor triggered on the tool's shaft or tip."""

    kind: Literal["beam"]
    sensor: SensorIn
    samples: list[BeamSampleIn]

    @model_validator(mode="after")
    def _known_beams(self) -> "BeamRecordingIn":
        ids = [b.id for b in self.sensor.beams]
        for k, s in enumerate(self.samples):
            if s.beam not in ids:
                raise RecordingError(("samples", k, "beam"), f"unknown beam {s.beam!r}; "
                                     f"sensor.beams has {', '.join(map(repr, ids))}")
        return self


RecordingIn = Annotated[Union[TouchRecordingIn, TrackerRecordingIn, BeamRecordingIn],
                        Field(discriminator="kind")]
"""The whole document; usable as a FastAPI body type."""

RECORDING_ADAPTER: TypeAdapter = TypeAdapter(RecordingIn)
_KINDS = ("touch", "tracker", "beam")
_KIND_FIELDS = {"measured_mm": "tracker", "sensor": "beam", "beam": "beam", "edge": "beam",
                "tcp_velocity_mm_s": "beam"}


def _error_from(exc: ValidationError) -> RecordingError:
    """The first pydantic error as a :class:`RecordingError` with the document's JSON path."""
    err = exc.errors(include_url=False)[0]
    loc = tuple(err["loc"])
    if loc and loc[0] in _KINDS:  # the discriminated union's tag, not part of the document
        loc = loc[1:]
    kind_tags = "'touch', 'tracker' or 'beam'"
    if err["type"] == "union_tag_invalid":
        return RecordingError(("kind",), f"must be {kind_tags}, got {err['ctx']['tag']}")
    if err["type"] == "union_tag_not_found":
        return RecordingError(("kind",), f"is required: {kind_tags}")
    cause = (err.get("ctx") or {}).get("error")
    if isinstance(cause, RecordingError):
        return RecordingError(cause.loc, cause.reason)
    reason = str(cause) if isinstance(cause, ValueError) else err["msg"]
    if err["type"] == "extra_forbidden":
        owner = _KIND_FIELDS.get(str(loc[-1])) if loc else None
        reason = (f"is a field of {owner} recordings only" if owner
                  else "unknown field (not part of robot-recording/1)")
    elif err["type"] == "finite_number":
        reason = "is not a finite number (NaN and infinity are not allowed)"
    elif err["type"] == "missing":
        reason = "is required"
    elif err["type"] in ("float_type", "int_type"):
        reason = "must be a number (a JSON number, not a string or true/false)"
    elif reason.startswith("Input should be"):
        reason = "must be" + reason[len("Input should be"):]
    return RecordingError(loc, reason)


def _refuse_null(value: object, loc: tuple[str | int, ...]) -> None:
    """The format has no null: an optional field is left out, never written as null."""
    if value is None:
        raise RecordingError(loc, "must be left out or given a value; the format has no null")
    if isinstance(value, dict):
        for key, item in value.items():
            _refuse_null(item, loc + (key,))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _refuse_null(item, loc + (i,))


def validate_document(doc: dict | str | bytes
                      ) -> TouchRecordingIn | TrackerRecordingIn | BeamRecordingIn:
    """The validated pydantic model of a document (dict, or JSON text / bytes).

    Raises
    ------
    RecordingError
        Invalid JSON, or the first violation of the format, naming the field.
    """
    if isinstance(doc, (str, bytes, bytearray)):
        try:
            doc = json.loads(doc)
        except UnicodeDecodeError as exc:
            raise RecordingError((), f"is not UTF-8 text: {exc}") from None
        except json.JSONDecodeError as exc:
            raise RecordingError((), f"is not valid JSON: {exc.msg} at line {exc.lineno} "
                                 f"column {exc.colno}") from None
    if not isinstance(doc, dict):
        raise RecordingError((), f"a recording must be a JSON object, got {type(doc).__name__}")
    _refuse_null(doc, ())
    try:
        return RECORDING_ADAPTER.validate_python(doc)
    except ValidationError as exc:
        raise _error_from(exc) from None


def _robot_model(r: RobotIn) -> RobotModel:
    joints = tuple(DHJoint(a_mm=j.a_mm, alpha_deg=j.alpha_deg, d_mm=j.d_mm, offset_deg=j.offset_deg,
                           direction=j.direction) for j in r.joints)
    return RobotModel(name=r.model, dh_convention=r.dh_convention, joints=joints,
                      base_pose=r.base_pose.to_pose() if r.base_pose else Pose(),
                      flange_pose=r.flange_pose.to_pose() if r.flange_pose else Pose(),
                      source="robot-recording/1 file")


def parse_recording(doc: dict | str | bytes, measurements_optional: bool = False) -> RecordingData:
    """Read a ``robot-recording/1`` document into a :class:`RecordingData`.

    Parameters
    ----------
    doc : dict, str or bytes
        The parsed JSON object, or its UTF-8 text.
    measurements_optional : bool
        A tracker recording whose samples carry no ``measured_mm`` at all is read, with
        ``measured_mm`` None (``pendant predict`` predicts poses not measured yet).

    Raises
    ------
    RecordingError
        ``loc`` is the JSON path of the first bad field (``("samples", 12, "joints_deg")``),
        ``reason`` says what is wrong.

    Examples
    --------
    >>> rec = parse_recording({"format": "robot-recording/1", "kind": "touch",
    ...     "robot": {"model": "one axis", "dh_convention": "standard",
    ...               "joints": [{"a_mm": 100, "alpha_deg": 0, "d_mm": 0, "offset_deg": 0}]},
    ...     "tool": {"x": 0, "y": 0, "z": 0, "a": 0, "b": 0, "c": 0},
    ...     "samples": [{"t_s": k, "joints_deg": [10 * k]} for k in range(4)]})
    >>> rec.kind, rec.joints_deg.shape
    ('touch', (4, 1))
    >>> parse_recording({"format": "robot-recording/1", "kind": "dance"})
    Traceback (most recent call last):
    ...
    server.formats.recording.RecordingError: kind: must be 'touch', 'tracker' or 'beam', got dance
    """
    if measurements_optional:
        if isinstance(doc, (str, bytes)):
            try:
                doc = json.loads(doc)
            except ValueError:
                pass
        samples_in = doc.get("samples") if isinstance(doc, dict) else None
        if (doc.get("kind") == "tracker" and isinstance(samples_in, list) and samples_in
                and all(isinstance(s, dict) and "measured_mm" not in s for s in samples_in)):
            filled = {**doc, "samples": [{**s, "measured_mm": [0.0, 0.0, 0.0]}
                                         for s in samples_in]}
            rec = parse_recording(filled)
            return dataclasses.replace(rec, measured_mm=None)
    m = validate_document(doc)
    n = len(m.robot.joints)
    samples = m.samples
    beams: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    extra: dict[str, Any] = {}
    if isinstance(m, TrackerRecordingIn):
        extra["measured_mm"] = np.array([s.measured_mm for s in samples], dtype=float)
    if isinstance(m, BeamRecordingIn):
        for b in m.sensor.beams:
            d = np.array(b.direction, dtype=float)
            beams[b.id] = (np.array(b.point_mm, dtype=float), d / np.linalg.norm(d))
        extra.update(beams=beams, tool_diameter_mm=float(m.sensor.tool_diameter_mm),
                     beam_ids=np.array([s.beam for s in samples], dtype=str),
                     edges=np.array([s.edge for s in samples], dtype=str),
                     tcp_velocity_mm_s=np.array([s.tcp_velocity_mm_s for s in samples],
                                                dtype=float))
    if m.robot.link_masses is not None:
        from solvers.gravity import LinkMasses
        lm = m.robot.link_masses
        extra["link_masses"] = LinkMasses(
            mass_kg=tuple(float(x) for x in lm.mass_kg),
            com_mm=None if lm.com_mm is None else tuple(tuple(float(x) for x in c)
                                                        for c in lm.com_mm),
            source="the recording's link masses")
    return RecordingData(
        kind=m.kind, robot=_robot_model(m.robot), tool=m.tool.to_pose().as_matrix(),
        t_s=np.array([s.t_s for s in samples], dtype=float),
        joints_deg=np.array([s.joints_deg for s in samples], dtype=float).reshape(len(samples), n),
        payload_mass_kg=float(m.payload.mass_kg) if m.payload else 0.0,
        payload_com_mm=np.array(m.payload.com_mm if m.payload else [0.0, 0.0, 0.0], dtype=float),
        start_joints_deg=(None if m.start_joints_deg is None
                          else np.array(m.start_joints_deg, dtype=float)),
        recorded_at=m.recorded_at, **extra)


def to_document(rec: RecordingData) -> dict:
    """The ``robot-recording/1`` document (a JSON-ready dict) of a recording, validated.

    ``parse_recording(to_document(rec))`` gives ``rec`` back (poses to 1e-9).

    Raises
    ------
    RecordingError
        The robot has a joint coupling (the format holds decoupled joints), or the result is
        not a valid recording (e.g. too few samples).
    """
    try:
        doc = recording_document(rec)
    except CalibrationError as exc:
        raise RecordingError(exc.loc, exc.reason) from None
    validate_document(doc)
    return doc


def _without_null(node: object) -> object:
    """pydantic writes an optional field as ``anyOf: [X, null]`` with ``default: null``; the
    format has no null (an optional field is left out), so the schema says just X."""
    if isinstance(node, list):
        return [_without_null(x) for x in node]
    if not isinstance(node, dict):
        return node
    out = {k: _without_null(v) for k, v in node.items()}
    if "anyOf" in out:
        kept = [x for x in out["anyOf"] if x != {"type": "null"}]
        if len(kept) != len(out["anyOf"]):
            if "default" in out and out["default"] is None:
                del out["default"]
            if len(kept) == 1:
                del out["anyOf"]
                out = {**kept[0], **out}
            else:
                out["anyOf"] = kept
    return out


def recording_json_schema() -> dict:
    """JSON Schema (draft 2020-12) of ``robot-recording/1``, as committed in
    ``docs/robot-recording-1.schema.json``.

    The schema checks types, required and unknown fields and enumerations; the
    cross-field rules (joint count per sample, beam ids, time order, minimum sample count,
    non-zero directions, finite numbers) are :func:`parse_recording`'s.
    """
    schema = _without_null(RECORDING_ADAPTER.json_schema())
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": SCHEMA_ID,
            "title": FORMAT,
            "description": "A robot recording: the joint values a controller logged while the "
                           "robot measured something, and what was observed. "
                           "See docs/recording-format.md.",
            **schema}


def schema_text() -> str:
    """The committed schema file's exact text."""
    return json.dumps(recording_json_schema(), indent=2) + "\n"


__all__ = ["RecordingError", "RecordingIn", "RECORDING_ADAPTER", "PoseIn", "DHRowIn", "RobotIn",
           "PayloadIn", "BeamIn", "SensorIn", "SampleIn", "TrackerSampleIn", "BeamSampleIn",
           "TouchRecordingIn", "TrackerRecordingIn", "BeamRecordingIn", "parse_recording",
           "validate_document", "to_document", "recording_json_schema", "schema_text", "FORMAT"]


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.stdout.write(schema_text())
