"""Analysis signs, checked without the project's simulator: the "real" robot is the nominal
DH table with one row changed by hand, measured by plain forward kinematics, so a sign error
shared by ``solvers.physics`` and the analysis cannot hide here.

Spec (analysis-report/1): ``offset_deg`` is true minus recorded (the joint really stands at
the recorded value plus offset_deg, in the direction of its DH angle); ``delta_mm`` is true
minus nominal.
"""

from __future__ import annotations

import numpy as np
import pytest

from server.formats.recording import parse_recording
from solvers.analysis import analyze
from solvers.dh import forward_kinematics
from solvers.frames import Pose, apply
from solvers.robots import ROBOTS

TCP_MM = np.array([10.0, -5.0, 120.0])
INSTRUMENT = Pose(2000.0, -300.0, 150.0, 30.0, 2.0, -1.0)  # T_instrument_base


def tracker_document(nominal_key: str, true_robot, n: int = 120, noise_mm: float = 0.005,
                     seed: int = 7) -> dict:
    nominal = ROBOTS[nominal_key]
    rng = np.random.default_rng(seed)
    lim = np.clip(nominal.limits_deg() * 0.7, -160, 160)
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, nominal.dof))
    tcp = apply(forward_kinematics(true_robot, q), TCP_MM)
    measured = apply(INSTRUMENT.as_matrix(), tcp) + rng.normal(0.0, noise_mm, (n, 3))
    p = nominal.params()
    joints = [{"a_mm": float(p["a_mm"][i]), "alpha_deg": float(p["alpha_deg"][i]),
               "d_mm": float(p["d_mm"][i]), "offset_deg": float(p["offset_deg"][i]),
               "direction": int(p["direction"][i])} for i in range(nominal.dof)]
    return {
        "format": "robot-recording/1", "kind": "tracker",
        "robot": {"model": nominal.name, "dh_convention": nominal.dh_convention, "joints": joints},
        "tool": {"x": 0.0, "y": 0.0, "z": 100.0, "a": 0.0, "b": 0.0, "c": 0.0},
        "samples": [{"t_s": float(k), "joints_deg": q[k].tolist(), "measured_mm": measured[k].tolist()}
                    for k in range(n)],
    }


def first_finding(doc: dict) -> dict:
    report = analyze(parse_recording(doc))
    assert report["findings"], report["locate"]["summary"]
    return report["findings"][0]


@pytest.mark.parametrize("key, joint, delta_deg", [
    ("kuka_kr6_r900_sixx", 2, -0.05),  # KUKA A2, counted in the DH sense
    ("kuka_kr6_r900_sixx", 3, +0.04),
    ("tm5_900", 3, -0.05),             # modified DH
])
def test_joint_offset_sign_is_true_minus_recorded(key, joint, delta_deg):
    nominal = ROBOTS[key]
    true = nominal.with_joint(joint - 1, offset_deg=nominal.joints[joint - 1].offset_deg + delta_deg)
    f = first_finding(tracker_document(key, true))
    assert (f["effect"], f["joint"]) == ("joint_offset", joint)
    assert f["parameters"]["offset_deg"] == pytest.approx(delta_deg, rel=0.05)


@pytest.mark.parametrize("key, joint, param, delta_mm", [
    ("kuka_kr6_r900_sixx", 2, "a_mm", -0.4),
    ("kuka_kr6_r900_sixx", 4, "d_mm", +0.4),
    ("tm5_900", 3, "a_mm", -0.4),       # modified DH: row 3 carries the a before joint 3
])
def test_link_length_sign_is_true_minus_nominal(key, joint, param, delta_mm):
    nominal = ROBOTS[key]
    row = nominal.joints[joint - 1]
    true = nominal.with_joint(joint - 1, **{param: getattr(row, param) + delta_mm})
    f = first_finding(tracker_document(key, true))
    assert (f["effect"], f["joint"], f["parameters"]["dh_parameter"]) == ("link_length", joint, param[0])
    assert f["parameters"]["delta_mm"] == pytest.approx(delta_mm, rel=0.05)
