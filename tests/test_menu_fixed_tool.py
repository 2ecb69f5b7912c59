"""Fixed tool menu through HTTP: external TCP 5D and 6D with a calibrated pointer."""

from __future__ import annotations

import pytest

from api_helpers import (C, CELL, angle_deg, calibrate, calibrated_pointer, ok, open_session,
                        pose_matrix)

T_TRUE = CELL.T_world_fixedtool


@pytest.mark.parametrize("mode", ["5d", "6d"])
def test_fixed_tool(client, mode):
    calibrated_pointer(client, 1)
    report, slot = calibrate(client, f"fixed_tool.{mode}", 4, tool_no=1, extra=2)
    assert slot["table"] == "base" and slot["kind"] == "fixed_tool"
    assert len(report["residuals_mm"]) == 3 and report["max_error_mm"] < 1e-3
    T = pose_matrix(slot["pose"])
    assert T[:3, 3] == pytest.approx(T_TRUE[:3, 3], abs=1e-3)
    assert float(T[:3, 2] @ T_TRUE[:3, 2]) == pytest.approx(1.0, abs=1e-9)
    if mode == "6d":
        assert angle_deg(T[:3, :3], T_TRUE[:3, :3]) < 1e-4
    listed = ok(client.get(f"{C}/fixed-tools"))
    assert [e["number"] for e in listed] == [4]


@pytest.mark.parametrize("mode", ["5d", "6d"])
def test_fixed_tool_align_prompt_says_which_way(client, mode):
    """The lecture's "align Z with Z" has no sign; the pendant's prompt gives it (a flange
    aligned the other way round gives an axis 180 deg off)."""
    calibrated_pointer(client, 1)
    url = open_session(client, f"fixed_tool.{mode}", 4, tool_no=1)
    align = ok(client.get(url))["steps"][1]
    assert align["target"] == "fixed_tool_align"
    assert "flange +Z pointing into the fixed tool" in align["prompt"]
    assert "flange -Z along" in align["prompt"]
