"""Base menu through HTTP: 3-point, indirect and numeric, touched with a calibrated pointer."""

from __future__ import annotations

import numpy as np
import pytest

from api_helpers import (C, CELL, angle_deg, calibrate, calibrated_pointer, ok, open_session,
                        pose_matrix, walk)


def test_base_3point(client):
    calibrate(client, "tool.xyz_4point", 1)
    report, slot = calibrate(client, "base.3point", 2, tool_no=1)
    T = pose_matrix(slot["pose"])
    assert slot["kind"] == "base"
    assert T[:3, 3] == pytest.approx(CELL.T_world_plate[:3, 3], abs=1e-3)
    assert angle_deg(T[:3, :3], CELL.T_world_plate[:3, :3]) < 1e-3
    assert report["angle_bound95_deg"] is not None or report["position_bound95_mm"] is not None


def test_base_indirect_from_known_points(client):
    calibrate(client, "tool.xyz_4point", 1)
    known = [CELL.plate_points_mm[f"point_{k}"].tolist() for k in range(1, 6)]
    url = open_session(client, "base.indirect", 3, tool_no=1, known_points_mm=known)
    s = walk(client, url)
    assert [st["target"] for st in s["steps"]] == [f"base_point_{k}" for k in range(1, 6)]
    assert "reference point 2" in s["steps"][1]["prompt"]
    report = ok(client.post(f"{url}/compute"))
    assert report["tre_mm"] is not None
    assert report["max_error_mm"] < 1e-3
    T = pose_matrix(ok(client.post(f"{url}/save"))["pose"])
    assert T[:3, 3] == pytest.approx(CELL.T_world_plate[:3, 3], abs=1e-3)
    assert angle_deg(T[:3, :3], CELL.T_world_plate[:3, :3]) < 1e-3


def test_base_3point_with_an_empty_tool_is_refused_by_name(client):
    """Refused at Open (issue 14), not after the touch-ups."""
    r = client.post(f"{C}/sessions", json={"method": "base.3point", "target_no": 2, "params": {"tool_no": 7}})
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "params", "tool_no"]
    assert "tool 7 is empty" in r.json()["detail"][0]["msg"]


def test_base_numeric(client):
    url = open_session(client, "base.numeric", 32, pose={"x": 500, "y": -20, "z": 10, "a": 90, "b": 0, "c": 0})
    ok(client.post(f"{url}/compute"))
    slot = ok(client.post(f"{url}/save"))
    assert slot["number"] == 32 and slot["pose"]["a"] == pytest.approx(90.0)


def test_jog_in_the_calibrated_base_moves_along_its_x(client):
    """Active tool 1 and base 2: a +X jog in base coordinates moves the TCP along the plate's X."""
    calibrated_pointer(client, 1)
    calibrate(client, "base.3point", 2, tool_no=1)
    ok(client.put(f"{C}/robot/active", json={"tool_no": 1, "base_no": 2}))
    before = ok(client.get(f"{C}/robot"))["tcp_pose"]
    after = ok(client.post(f"{C}/robot/jog", json={"mode": "base", "axis": "X", "increment": 10.0}))["tcp_pose"]
    d = np.array([after[k] - before[k] for k in "xyz"])
    assert d == pytest.approx([10.0, 0.0, 0.0], abs=1e-3)
