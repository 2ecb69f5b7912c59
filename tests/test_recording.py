"""robot-recording/1: the real UR10 file parses; every kind of bad document is refused by name."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from server.formats.recording import (RecordingError, parse_recording, recording_json_schema, schema_text,
                              to_document)
from solvers.errors import CalibrationError
from solvers.recording import last_motion_sign, motion_signs

REAL = Path(__file__).parent / "data" / "ur10-laser-tracker" / "recording-series-d.json"
SCHEMA_FILE = Path(__file__).resolve().parents[1] / "docs" / "robot-recording-1.schema.json"

POSE0 = {"x": 0, "y": 0, "z": 0, "a": 0, "b": 0, "c": 0}
ROW = {"a_mm": 0, "alpha_deg": 0, "d_mm": 100, "offset_deg": 0}


def small(kind: str = "tracker") -> dict:
    """A minimal valid two-joint document of ``kind``."""
    doc = {"format": "robot-recording/1", "kind": kind,
           "robot": {"model": "test arm", "dh_convention": "standard",
                     "joints": [{"a_mm": 300, "alpha_deg": 0, "d_mm": 0, "offset_deg": 0},
                                {"a_mm": 200, "alpha_deg": 0, "d_mm": 0, "offset_deg": 10,
                                 "direction": -1}]},
           "tool": {**POSE0, "z": 150},
           "samples": [{"t_s": float(k), "joints_deg": [10.0 * k, -5.0 * k]} for k in range(6)]}
    if kind == "tracker":
        for k, s in enumerate(doc["samples"]):
            s["measured_mm"] = [k, 2.0 * k, 0]
    if kind == "beam":
        doc["sensor"] = {"beams": [{"id": "bx", "point_mm": [400, 0, 0], "direction": [2, 0, 0]},
                                   {"id": "by", "point_mm": [400, 0, 0], "direction": [0, 1, 0]}],
                         "tool_diameter_mm": 6.0}
        for k, s in enumerate(doc["samples"]):
            s.update(beam="bx" if k % 2 else "by", edge=("enter", "leave", "tip")[k % 3],
                     tcp_velocity_mm_s=[10.0, 0, 0])
    return doc


@pytest.fixture(scope="module")
def real() -> dict:
    return json.loads(REAL.read_text())


def test_real_ur10_tracker_file_parses(real):
    rec = parse_recording(REAL.read_bytes())
    assert rec.kind == "tracker" and rec.robot.name == "Universal Robots UR10 (CB3)"
    assert rec.joints_deg.shape == (632, 6) and rec.measured_mm.shape == (632, 3)
    assert rec.t_s[1] == 10.0 and rec.robot.dof == 6
    np.testing.assert_array_equal(rec.tool, np.eye(4))
    assert rec.payload_mass_kg == 0.0 and rec.start_joints_deg is None


@pytest.mark.parametrize("kind", ["touch", "tracker", "beam"])
def test_every_kind_round_trips_through_to_document(kind):
    rec = parse_recording(json.dumps(small(kind)))
    back = parse_recording(to_document(rec))
    np.testing.assert_allclose(back.joints_deg, rec.joints_deg)
    np.testing.assert_allclose(back.tool, rec.tool, atol=1e-9)
    assert back.robot.joints == rec.robot.joints and back.kind == kind
    if kind == "beam":
        np.testing.assert_allclose(rec.beams["bx"][1], [1, 0, 0])  # unit direction
        assert rec.beam_ids.tolist() == ["by", "bx"] * 3 and rec.edges[2] == "tip"
        np.testing.assert_allclose(back.tcp_velocity_mm_s, rec.tcp_velocity_mm_s)


def _refuse(doc: dict, mutate) -> RecordingError:
    doc = copy.deepcopy(doc)
    mutate(doc)
    with pytest.raises(RecordingError) as info:
        parse_recording(doc)
    assert isinstance(info.value, CalibrationError)
    return info.value


def test_refuses_wrong_joint_count_naming_the_sample(real):
    e = _refuse(real, lambda d: d["samples"][12]["joints_deg"].pop())
    assert e.loc == ("samples", 12, "joints_deg") and "6 joints" in e.reason


def test_refuses_nan_naming_the_number(real):
    e = _refuse(real, lambda d: d["samples"][3]["joints_deg"].__setitem__(2, float("nan")))
    assert e.loc == ("samples", 3, "joints_deg", 2) and "finite" in e.reason
    with pytest.raises(RecordingError) as info:
        parse_recording(json.dumps(small()).replace('"measured_mm": [0, 0.0, 0]',
                                                    '"measured_mm": [Infinity, 0, 0]'))
    assert info.value.loc == ("samples", 0, "measured_mm", 0)


def test_refuses_unknown_kind(real):
    e = _refuse(real, lambda d: d.__setitem__("kind", "dance"))
    assert e.loc == ("kind",) and "dance" in e.reason


def test_refuses_missing_measured_mm(real):
    e = _refuse(real, lambda d: d["samples"][5].pop("measured_mm"))
    assert e.loc == ("samples", 5, "measured_mm") and "required" in e.reason


def test_refuses_unknown_field(real):
    assert _refuse(real, lambda d: d["robot"].__setitem__("colour", "red")).loc == ("robot", "colour")
    e = _refuse(real, lambda d: d["samples"][0].__setitem__("beam", "bx"))
    assert e.loc == ("samples", 0, "beam") and "beam recordings only" in e.reason


def test_refuses_unknown_beam_id():
    e = _refuse(small("beam"), lambda d: d["samples"][4].__setitem__("beam", "bz"))
    assert e.loc == ("samples", 4, "beam") and "bz" in e.reason


@pytest.mark.parametrize("mutate, loc", [
    (lambda d: d.pop("sensor"), ("sensor",)),
    (lambda d: d["samples"][2].pop("edge"), ("samples", 2, "edge")),
    (lambda d: d["samples"][2].__setitem__("edge", "middle"), ("samples", 2, "edge")),
    (lambda d: d["sensor"]["beams"][1].__setitem__("direction", [0, 0, 0]),
     ("sensor", "beams", 1, "direction")),
    (lambda d: d["sensor"]["beams"][1].__setitem__("id", "bx"), ("sensor", "beams", 1, "id")),
    (lambda d: d["samples"][2].__setitem__("t_s", 0.5), ("samples", 2, "t_s")),
    (lambda d: d.__setitem__("samples", d["samples"][:5]), ("samples",)),
    (lambda d: d.__setitem__("format", "robot-recording/2"), ("format",)),
    (lambda d: d["tool"].pop("c"), ("tool", "c")),
    (lambda d: d["robot"]["joints"][0].__setitem__("direction", 2), ("robot", "joints", 0, "direction")),
    (lambda d: d["robot"]["joints"][0].__setitem__("a_mm", "300"), ("robot", "joints", 0, "a_mm")),
    (lambda d: d.__setitem__("start_joints_deg", [0, 0, 0]), ("start_joints_deg",)),
    (lambda d: d.__setitem__("recorded_at", "yesterday"), ("recorded_at",)),
    (lambda d: d.__setitem__("payload", {"mass_kg": -1, "com_mm": [0, 0, 0]}), ("payload", "mass_kg")),
])
def test_refuses_bad_beam_documents_by_field(mutate, loc):
    assert _refuse(small("beam"), mutate).loc == loc


def test_refuses_non_json_and_non_objects():
    with pytest.raises(RecordingError, match="not valid JSON"):
        parse_recording("{")
    with pytest.raises(RecordingError, match="JSON object"):
        parse_recording("[1, 2]")


def test_committed_schema_file_is_up_to_date():
    """Regenerate with ``python -m server.formats.recording > docs/robot-recording-1.schema.json``."""
    assert SCHEMA_FILE.read_text() == schema_text()
    schema = recording_json_schema()
    assert schema["title"] == "robot-recording/1" and schema["$id"]
    assert schema["discriminator"]["propertyName"] == "kind"


def test_last_motion_sign_uses_start_joints_and_keeps_sign_when_still():
    doc = small("touch")
    doc["start_joints_deg"] = [5.0, -10.0]
    doc["samples"][2]["joints_deg"] = [10.0, -5.0]  # same as sample 1
    rec = parse_recording(doc)
    s = last_motion_sign(rec)
    assert s[0].tolist() == [-1.0, 1.0] and s[1].tolist() == [1.0, -1.0]
    assert s[2].tolist() == [1.0, -1.0]  # did not move: same flank as before
    assert motion_signs(rec.joints_deg)[0].tolist() == [0.0, 0.0]


def test_the_documented_example_is_a_valid_recording():
    import re

    text = (SCHEMA_FILE.parent / "recording-format.md").read_text()
    example = re.findall(r"```json\n(.*?)```", text, re.S)[1]
    rec = parse_recording(example)
    assert rec.kind == "tracker" and rec.n_samples == 4 and rec.payload_mass_kg == 2.0


@pytest.mark.parametrize("path, value, reason", [
    (("robot", "base_pose"), None, "no null"),
    (("payload",), None, "no null"),
    (("samples", 3, "joints_deg", 2), None, "no null"),
    (("recorded_at",), "2026-11-02", "ISO 8601 time"),
])
def test_null_fields_and_a_date_without_time_are_refused_by_path(path, value, reason):
    """The format defines no null (optional fields are left out) and recorded_at is a time."""
    doc = json.loads(REAL.read_text())
    target = doc
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    with pytest.raises(RecordingError) as e:
        parse_recording(doc)
    assert e.value.loc == path and reason in e.value.reason
