"""The ``pendant`` command: calibrate from a JSON/CSV file, export a controller."""

from __future__ import annotations

import json

import numpy as np
import pytest

from api_helpers import CELL, TRUE_TCP_MM
from server.cli.main import main
from emulator import approach, home_joints
from solvers.dh import forward_kinematics
from solvers.frames import Pose
from solvers.robots import ROBOTS

KR6 = ROBOTS["kuka_kr6_r900_sixx"]


@pytest.fixture(scope="module")
def touches() -> list[np.ndarray]:
    q, out = np.array(home_joints(KR6)), []
    for tilt, around, spin in ((0, 0, 0), (30, 0, 0), (30, 120, 90), (30, 240, -90), (20, 60, 30)):
        q = approach(KR6, CELL, q, "reference_tip", tilt, around, spin)
        out.append(q)
    return out


def test_calibrate_json_joints(tmp_path, touches, capsys):
    f = tmp_path / "touch.json"
    f.write_text(json.dumps({"robot": "kuka_kr6_r900_sixx", "points": [{"joints_deg": q.tolist()} for q in touches]}))
    assert main(["calibrate", "tool.xyz_4point", str(f), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [report["frame"][k] for k in "xyz"] == pytest.approx(TRUE_TCP_MM, abs=1e-3)
    assert len(report["residuals_mm"]) == 5


def test_calibrate_csv_flange_poses(tmp_path, touches, capsys):
    rows = ["x,y,z,a,b,c"] + [",".join(f"{v:.9f}" for v in Pose.from_matrix(forward_kinematics(KR6, q)).as_array())
                              for q in touches]
    f = tmp_path / "touch.csv"
    f.write_text("\n".join(rows) + "\n")
    assert main(["calibrate", "tool.xyz_4point", str(f)]) == 0
    out = capsys.readouterr().out
    assert "max " in out and f"z {TRUE_TCP_MM[2]:.3f}" in out


def test_calibrate_errors_name_the_field(tmp_path, touches, capsys):
    f = tmp_path / "touch.json"
    f.write_text(json.dumps({"points": [{"joints_deg": touches[0].tolist()}]}))
    assert main(["calibrate", "tool.xyz_4point", str(f)]) == 2
    assert "points.0.joints_deg" in capsys.readouterr().err


@pytest.mark.parametrize("rail, argv, line", [
    ("E4", [], "inputs.rail: must be an object"),
    ({"axis": "E9", "direction": [0, 1, 0]}, [], "inputs.rail.axis: must be one of E1..E6"),
    ({"axis": "E1", "direction": [0, 0, 0]}, [], "inputs.rail.direction: must be three finite"),
    ({"axis": "E1", "direction": [0, 1, 0], "scale": -1}, [], "inputs.rail.scale: must be a "
                                                              "positive number"),
    ({"axis": "E1", "direction": [0, 1, 0], "calibrated": "yes"}, [],
     "inputs.rail.calibrated: must be true or false"),
    ({"axis": "E1", "direction": [0, 1, 0], "travel": 3}, [], "inputs.rail.travel: unknown"),
    ({"axis": "E1", "direction": [10 ** 400, 0, 0]}, [], "inputs.rail.direction: must be three"),
    ({"axis": "E1", "direction": ["0", "1", "0"]}, [], "inputs.rail.direction: must be three"),
    ({"axis": "E1", "direction": [0, 1, 0], "scale": 10 ** 400}, [],
     "inputs.rail.scale: must be a positive number"),
    (None, ["--rail", "E1"], "--rail: must be AXIS:X,Y,Z or AXIS:X,Y,Z:calibrated"),
    (None, ["--rail", "E1:0,1"], "--rail: must be 3 finite comma-separated numbers"),
    (None, ["--rail", "E7:0,1,0"], "--rail: must be one of E1..E6"),
])
def test_a_bad_rail_names_the_field(tmp_path, touches, capsys, rail, argv, line):
    """``inputs.rail`` / ``--rail`` of ``pendant calibrate``: one line naming the field."""
    f = tmp_path / "touch.json"
    inputs = {} if rail is None else {"rail": rail}
    f.write_text(json.dumps({"robot": "kuka_kr6_r900_sixx", "inputs": inputs,
                             "points": [{"joints_deg": q.tolist()} for q in touches]}))
    assert main(["calibrate", "tool.xyz_4point", str(f), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"pendant: {line}") and "Traceback" not in err, err


@pytest.mark.parametrize("axes, line", [
    ({"E1": "abc"}, "points.1.external_axes.E1: must be a finite number"),
    ({"E1": None}, "points.1.external_axes.E1: must be a finite number"),
    ({"E1": 1e300}, "points.1.external_axes.E1: must be a finite number"),
    ([1, 2], "points.1.external_axes: must be an object"),
    ({"E9": 1.0}, "points.1.external_axes.E9: external axes are E1..E6"),
])
def test_bad_external_axes_in_a_file_name_the_point(tmp_path, touches, capsys, axes, line):
    """A touch-up's ``external_axes`` in a ``pendant calibrate`` file: one line naming the
    point and the axis, never a traceback."""
    f = tmp_path / "touch.json"
    points = [{"joints_deg": q.tolist(), "external_axes": {"E1": 0.0}} for q in touches]
    points[1]["external_axes"] = axes
    f.write_text(json.dumps({"robot": "kuka_kr6_r900_sixx", "points": points,
                             "inputs": {"rail": {"axis": "E1", "direction": [0, 1, 0],
                                                 "calibrated": True}}}))
    assert main(["calibrate", "tool.xyz_4point", str(f)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"pendant: {line}") and "Traceback" not in err, err


def test_export_prints_the_controller_file(tmp_path, capsys):
    assert main(["export", "cell-1", "--format", "kuka", "--db", f"sqlite:///{tmp_path / 'p.db'}"]) == 0
    assert "TOOL_DATA" in capsys.readouterr().out
    assert main(["export", "nope", "--db", f"sqlite:///{tmp_path / 'p.db'}"]) == 2
