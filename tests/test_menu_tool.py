"""Tool menu through HTTP: every tool method walked as a person would, on the emulated cell."""

from __future__ import annotations

import numpy as np
import pytest

from api_helpers import (C, CELL, TRUE_TCP_MM, angle_deg, approach, calibrate, ok, open_session,
                        pose_array, pose_matrix, walk)

R_TRUE = CELL.T_flange_tool[:3, :3]


def test_tool_xyz_4point_four_touch_ups_then_save(client):
    """Tool > XYZ 4-point: touch the reference tip from four orientations, save, read it back."""
    report, slot = calibrate(client, "tool.xyz_4point", 1)
    assert report["max_error_mm"] < 1e-3
    assert report["position_bound95_mm"] is not None
    assert pose_array(slot["pose"])[:3] == pytest.approx(TRUE_TCP_MM, abs=1e-3)
    assert pose_array(slot["pose"])[3:] == pytest.approx([0, 0, 0])  # XYZ menus keep A, B, C
    assert slot["provenance"]["method"] == "tool.xyz_4point"
    assert slot["provenance"]["session_id"] is not None
    assert ok(client.get(f"{C}/tools/1")) == slot


def test_tool_xyz_4point_names_the_bad_touch_up(client):
    """Six touch-ups, the fifth 1.5 mm off: the report names it and gives the refit without it."""
    url = open_session(client, "tool.xyz_4point", 3)
    walk(client, url)
    approach(client, "reference_tip", tilt_deg=20, around_deg=60, spin_deg=45, miss_mm=[1.0, -1.0, 0.5])
    ok(client.post(f"{url}/touch-up"))
    approach(client, "reference_tip", tilt_deg=25, around_deg=300, spin_deg=-60)
    s = ok(client.post(f"{url}/touch-up"))
    assert [st["filled"] for st in s["steps"]] == [True] * 6
    report = ok(client.post(f"{url}/compute"))
    assert report["bad_point"]["index"] == 4
    assert "re-teach" in report["bad_point"]["message"]
    assert pose_array(report["bad_point"]["refit_frame"])[:3] == pytest.approx(TRUE_TCP_MM, abs=1e-3)


def test_tool_xyz_4point_refuses_one_orientation_four_times(client):
    url = open_session(client, "tool.xyz_4point", 1)
    for _ in range(4):
        ok(client.post(f"{url}/touch-up"))
    r = client.post(f"{url}/compute")
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"][:2] == ["body", "flange_poses"]
    assert "orientation" in r.json()["detail"][0]["msg"]
    assert all(st["filled"] for st in ok(client.get(url))["steps"])  # nothing lost


def test_tool_xyz_reference_from_a_calibrated_reference_tool(client):
    calibrate(client, "tool.xyz_4point", 1)
    report, slot = calibrate(client, "tool.xyz_reference", 2, reference_tool_no=1, extra=2)
    assert len(report["residuals_mm"]) == 3
    assert pose_array(slot["pose"])[:3] == pytest.approx(TRUE_TCP_MM, abs=1e-3)


def test_tool_xyz_reference_needs_its_reference_tool(client):
    r = client.post(f"{C}/sessions", json={"method": "tool.xyz_reference", "target_no": 2})
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "params", "reference_tool_no"]


@pytest.mark.parametrize("mode", ["5d", "6d"])
def test_tool_abc_world(client, mode):
    """ABC World: XYZ first, then align the tool with the world axes and touch up once."""
    calibrate(client, "tool.xyz_4point", 1)
    report, slot = calibrate(client, f"tool.abc_world_{mode}", 1)
    T = pose_matrix(slot["pose"])
    assert T[:3, 3] == pytest.approx(TRUE_TCP_MM, abs=1e-3)
    assert float(T[:3, 2] @ R_TRUE[:, 2]) == pytest.approx(1.0, abs=1e-9)  # tool axis found
    if mode == "6d":
        assert angle_deg(T[:3, :3], R_TRUE) < 1e-4


def test_tool_abc_world_needs_the_xyz_first(client):
    url = open_session(client, "tool.abc_world_6d", 4)
    ok(client.post(f"{url}/touch-up"))
    r = client.post(f"{url}/compute")
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "params", "target_no"]


def test_tool_abc_2point(client):
    calibrate(client, "tool.xyz_4point", 1)
    report, slot = calibrate(client, "tool.abc_2point", 1)
    assert report["angle_bound95_deg"] > 0
    assert angle_deg(pose_matrix(slot["pose"])[:3, :3], R_TRUE) < 1e-4


def test_tool_numeric(client):
    url = open_session(client, "tool.numeric", 5, pose={"x": 1, "y": 2, "z": 150, "a": 0, "b": 90, "c": 0})
    assert ok(client.get(url))["steps"] == []
    ok(client.post(f"{url}/compute"))
    slot = ok(client.post(f"{url}/save"))
    assert pose_array(slot["pose"]) == pytest.approx([1, 2, 150, 0, 90, 0])
    assert slot["provenance"]["method"] == "tool.numeric"


def test_tool_xyz_4point_noisy_touch_ups_within_the_bound(client):
    """Eight sloppy touch-ups (0.1 mm misses): the TCP error is of the size the report bounds."""
    rng = np.random.default_rng(7)
    url = open_session(client, "tool.xyz_4point", 2)
    orientations = [(0, 0, 0), (30, 0, 0), (30, 120, 90), (30, 240, -90), (25, 60, 30), (25, 180, -30),
                    (20, 300, 120), (15, 90, -120)]
    for tilt, around, spin in orientations:
        approach(client, "reference_tip", tilt_deg=tilt, around_deg=around, spin_deg=spin,
                 miss_mm=rng.normal(0.0, 0.1, 3).tolist())
        ok(client.post(f"{url}/touch-up"))
    report = ok(client.post(f"{url}/compute"))
    error_mm = np.linalg.norm(pose_array(report["frame"])[:3] - TRUE_TCP_MM)
    assert 0.02 < report["max_error_mm"] < 0.6
    assert error_mm < 1.5 * report["position_bound95_mm"]
