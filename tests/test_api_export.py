"""Export menu, history and restore: controller files, JSON backup, every change recorded."""

from __future__ import annotations

import pytest

from api_helpers import (C, TRUE_TCP_MM, calibrate, edit_slot, finish_job, ok, pose_array,
                        restore_slot)


def test_history_records_before_after_and_restore(client):
    calibrate(client, "tool.xyz_4point", 1)
    ok(edit_slot(client, f"{C}/tools/1", {"name": "pointer", "load": {"mass_kg": 1.2, "com_mm": [0, 0, 60]}}))
    hist = ok(client.get(f"{C}/tools/1/history"))
    assert [h["reason"] for h in hist] == ["calibration", "edit"]
    assert hist[0]["before"]["z_mm"] == 0.0 and hist[0]["after"]["z_mm"] == pytest.approx(TRUE_TCP_MM[2], abs=1e-3)
    assert hist[0]["session_id"] is not None
    slot = ok(restore_slot(client, f"{C}/tools/1", hist[0]['id']))  # back to before the calibration
    assert pose_array(slot["pose"]) == pytest.approx([0] * 6)
    assert len(ok(client.get(f"{C}/tools/1/history"))) == 3
    assert restore_slot(client, f"{C}/tools/2", hist[0]['id']).status_code == 404


@pytest.mark.parametrize("fmt", ["kuka", "abb", "fanuc", "ur"])
def test_export_controller_files(client, fmt):
    ok(edit_slot(client, f"{C}/tools/1", {"name": "pointer", "pose": {"x": 1, "y": 2, "z": 180},
                                        "load": {"mass_kg": 1.0, "com_mm": [0, 0, 50]}}))
    ok(edit_slot(client, f"{C}/bases/3", {"name": "table", "pose": {"x": 500, "z": 20, "a": 30}}))
    r = client.get(f"{C}/export", params={"format": fmt})
    assert r.status_code == 200, r.text
    assert "attachment" in r.headers["content-disposition"] and "cell-1" in r.headers["content-disposition"]
    assert ("0.18" if fmt == "ur" else "180") in r.text


@pytest.mark.parametrize("fmt", ["kuka", "abb"])
def test_import_round_trip(client, fmt):
    ok(edit_slot(client, f"{C}/tools/4", {"name": "pointer", "pose": {"x": 1.5, "y": -2, "z": 180, "a": 10}}))
    ok(edit_slot(client, f"{C}/bases/6", {"name": "fixture", "kind": "fixed_tool", "pose": {"x": 600, "y": 10, "z": 30}}))
    text = client.get(f"{C}/export", params={"format": fmt}).text
    other = ok(client.post("/controllers", json={"name": "other"}))
    res = ok(client.post(f"/controllers/{other['id']}/import", json={"format": fmt, "text": text}))
    assert res["entries"] == 2
    t4 = ok(client.get(f"/controllers/{other['id']}/tools/4"))
    assert pose_array(t4["pose"]) == pytest.approx([1.5, -2, 180, 10, 0, 0], abs=1e-4)
    b6 = ok(client.get(f"/controllers/{other['id']}/bases/6"))
    assert b6["kind"] == "fixed_tool" and b6["pose"]["x"] == pytest.approx(600)
    assert ok(client.get(f"/controllers/{other['id']}/tools/4/history"))[0]["reason"] == "import"


def test_json_backup_restores_tables_history_and_sessions(client):
    calibrate(client, "tool.xyz_4point", 1)
    backup = client.get(f"{C}/export", params={"format": "json"})
    assert backup.headers["content-type"].startswith("application/json")
    other = ok(client.post("/controllers", json={"name": "restored"}))
    job = finish_job(client, client.post(f"/controllers/{other['id']}/import",
                                         json={"format": "json", "text": backup.text}))
    assert job["state"] == "done" and job["links"]["result"] == f"/controllers/{other['id']}"
    assert job["result"] == {"format": "json", "entries": 48, "history": 1}
    t1 = ok(client.get(f"/controllers/{other['id']}/tools/1"))
    assert pose_array(t1["pose"])[:3] == pytest.approx(TRUE_TCP_MM, abs=1e-3)
    sessions = ok(client.get(f"/controllers/{other['id']}/sessions"))
    assert [s["state"] for s in sessions] == ["saved"] and len(sessions[0]["steps"]) == 4
    assert t1["provenance"]["session_id"] == sessions[0]["id"]
