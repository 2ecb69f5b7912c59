"""Workpiece menu through HTTP: a robot-held workpiece brushed on the calibrated fixed tool."""

from __future__ import annotations

import pytest

from api_helpers import C, CELL, angle_deg, calibrate, calibrated_pointer, ok, pose_matrix

T_TRUE = CELL.T_flange_workpiece


@pytest.fixture
def fixed_tool_4(client):
    calibrated_pointer(client, 1)
    calibrate(client, "fixed_tool.6d", 4, tool_no=1)
    return 4


def test_workpiece_direct(client, fixed_tool_4):
    report, slot = calibrate(client, "workpiece.direct", 9, fixed_tool_no=fixed_tool_4)
    assert slot["table"] == "tool" and slot["kind"] == "workpiece"
    T = pose_matrix(slot["pose"])
    assert T[:3, 3] == pytest.approx(T_TRUE[:3, 3], abs=1e-3)
    assert angle_deg(T[:3, :3], T_TRUE[:3, :3]) < 1e-3
    assert [e["number"] for e in ok(client.get(f"{C}/workpieces"))] == [9]


def test_workpiece_indirect(client, fixed_tool_4):
    known = [CELL.workpiece_points_mm[f"point_{k}"].tolist() for k in range(1, 5)]
    report, slot = calibrate(client, "workpiece.indirect", 10, fixed_tool_no=fixed_tool_4, known_points_mm=known)
    assert len(report["residuals_mm"]) == 4 and report["max_error_mm"] < 1e-3
    T = pose_matrix(slot["pose"])
    assert T[:3, 3] == pytest.approx(T_TRUE[:3, 3], abs=1e-3)
    assert angle_deg(T[:3, :3], T_TRUE[:3, :3]) < 1e-3


def test_workpiece_needs_a_fixed_tool_not_a_base(client):
    r = client.post(f"{C}/sessions", json={"method": "workpiece.direct", "target_no": 9,
                                           "params": {"fixed_tool_no": 5}})
    assert r.status_code == 422  # refused at Open (issue 14), not at Compute
    assert r.json()["detail"][0]["loc"] == ["body", "params", "fixed_tool_no"]
