"""A backup the service wrote is one it restores (issue 21, item 2): a controller with 20 000
history rows exports and restores through the API and through ``pendant backup`` /
``pendant restore`` (and ``pendant import --format json``).

The two 20 000-row tests are ``slow``: the lowest-versions pass of ``tests/run`` leaves them
out (test_api_export's JSON backup and the bad-backup test below make the same calls there, at
a small size)."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest
from sqlalchemy import func, insert, select

from api_helpers import C, edit_slot, finish_job, ok
from db.models import EntryHistory, utcnow
from server.cli.main import main
from server.api.limits import IMPORT_LIMIT_BYTES

ROWS = 20_000


def long_history(client, rows: int = ROWS) -> None:
    """``rows`` history rows on cell-1 as ordinary edits make them: tool and base slots whose
    poses change by full-precision numbers (the size of a real history, not of zeros)."""
    ok(edit_slot(client, f"{C}/tools/1", {"name": "pointer"}))
    rng = np.random.default_rng(21)
    maker = client.app.state.sessionmaker
    with maker() as db:
        template = db.scalars(select(EntryHistory)).first()
        batch = []
        last = {t: {**template.after, "kind": t} for t in ("tool", "base")}
        for k in range(rows - 1):
            table = "tool" if k % 2 else "base"
            before = last[table]
            after = last[table] = {**before, "name": f"{table}-{k % 16 + 1}", **{
                f: float(v) for f, v in zip(("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg"),
                                            rng.uniform(-170.0, 170.0, 6))}}
            batch.append({"controller_id": 1, "entry_table": table, "number": k % 16 + 1,
                          "reason": "edit", "changed_at": utcnow(), "before": before,
                          "after": after, "changed_by": "eva"})
            if len(batch) == 2000:
                db.execute(insert(EntryHistory), batch)
                batch = []
        if batch:
            db.execute(insert(EntryHistory), batch)
        db.commit()


def history_rows(client) -> list[tuple]:
    """cell-1's history rows, their poses as canonical JSON (1 and 1.0 differ): read as plain
    rows, not ORM objects (a third of the time for 20 000 rows)."""
    h = EntryHistory
    with client.app.state.sessionmaker() as db:
        return [(table, number, reason, json.dumps(before, sort_keys=True),
                 json.dumps(after, sort_keys=True))
                for table, number, reason, before, after in db.execute(
                    select(h.entry_table, h.number, h.reason, h.before, h.after)
                    .where(h.controller_id == 1).order_by(h.id))]


def wipe_history(client) -> None:
    """Lose the history (what a restore must bring back)."""
    with client.app.state.sessionmaker() as db:
        db.query(EntryHistory).delete()
        db.commit()
        assert db.scalar(select(func.count()).select_from(EntryHistory)) == 0


@pytest.mark.slow
def test_20000_history_rows_export_and_restore_through_the_api(client):
    long_history(client)
    rows = history_rows(client)
    assert len(rows) == ROWS
    r = client.get(f"{C}/export", params={"format": "json"})
    assert r.status_code == 200
    body = json.dumps({"format": "json", "text": r.text})
    assert len(body) > 16 * 2**20  # past the old limits: 16 MiB body, 5 000 000 characters
    assert len(body) < IMPORT_LIMIT_BYTES
    print(f"{ROWS} history rows: export {len(r.text)} characters, import body {len(body)} bytes "
          f"({len(body) / ROWS:.0f} per row)")
    wipe_history(client)
    etag = client.get(C).headers["ETag"]
    job = finish_job(client, client.post(f"{C}/import", content=body, headers={
        "content-type": "application/json", "If-Match": etag}))
    assert job["state"] == "done", job
    assert job["result"]["history"] == ROWS
    assert history_rows(client) == rows


def test_a_controller_file_keeps_its_5_million_character_limit(client):
    r = client.post(f"{C}/import", json={"format": "kuka", "text": "x" * 5_000_001})
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "text"]
    assert "5000000 characters" in r.json()["detail"][0]["msg"]


def test_an_import_past_the_limit_is_413_naming_it(client):
    r = client.post(f"{C}/import", content=b"x" * (IMPORT_LIMIT_BYTES + 1),
                    headers={"content-type": "application/json"})
    assert r.status_code == 413
    assert "64 MiB" in r.json()["detail"][0]["msg"]


def cli(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(list(argv))
    return rc, out.getvalue(), err.getvalue()


@pytest.mark.slow
def test_20000_history_rows_backup_and_restore_through_the_cli(client, db_url, tmp_path):
    long_history(client)
    rows = history_rows(client)
    path = tmp_path / "cell-1.json"
    rc, out, err = cli("backup", "cell-1", "-o", str(path), "--db", db_url)
    assert rc == 0, err
    assert f"backup with {ROWS} history rows" in err
    assert json.loads(path.read_text())["format"] == "pendant-backup/1"
    wipe_history(client)
    rc, out, err = cli("restore", str(path), "--controller", "cell-1", "--dry-run",
                       "--db", db_url)
    assert rc == 0 and "dry run" in out, err
    assert history_rows(client) == []
    rc, out, err = cli("restore", str(path), "--controller", "cell-1", "--db", db_url)
    assert rc == 0, err
    assert f"{ROWS} history rows" in out
    assert history_rows(client) == rows
    wipe_history(client)
    rc, out, err = cli("import", str(path), "--controller", "cell-1", "--db", db_url)
    assert rc == 0, err
    assert history_rows(client) == rows
    audit = ok(client.get("/audit", params={"limit": 100000}))
    restores = [a for a in audit if a["action"] == "backup.restore" and a["table"] is None]
    assert [a["source"] for a in restores] == ["cli", "cli"]
    assert restores[-1]["after"]["history_rows"] == ROWS


def test_restore_refuses_a_bad_backup_naming_the_field(client, db_url, tmp_path):
    path = tmp_path / "bad.json"
    rc, out, err = cli("backup", "1", "-o", str(path), "--db", db_url)
    assert rc == 0, err
    doc = json.loads(path.read_text())
    doc["entries"][0]["x_mm"] = 1e308
    path.write_text(json.dumps(doc))
    rc, out, err = cli("restore", str(path), "--controller", "cell-1", "--db", db_url)
    assert rc == 2 and "Traceback" not in err
    assert "text.entries.0.x_mm" in err
