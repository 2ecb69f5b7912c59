"""How long `pendant db upgrade` takes on a large SQLite file at revision 0011 (the upgrade
to 0012_no_id_reuse makes every table anew and copies its rows: docs/deploy.md).

A fresh file (the demo controller; one tool slot edited through the API, so its audit
record has the before and after of a frame), taken down to ``0011_session_opened_by``; that
slot-edit record is copied until the file holds ``--rows`` audit records; then
``python -m server.cli db upgrade --db …`` (the console script's module, a process of its
own) is timed. The last line::

    rows=… file_mb=… upgrade_s=… upgrade_cpu_s=…

(``upgrade_s``: the process' wall time, Python's start included; ``upgrade_cpu_s``: its user +
system CPU.)

    PYTHONPATH=$PWD python benchmarks/upgrade_time.py [--rows 1000000]   # --rows 100000: quick
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

TOKEN = "pdt_upgrade-time-benchmark-0123456789abcdef"
OLD = "0011_session_opened_by"


def make_file(path: Path, rows: int) -> None:
    from alembic import command
    from fastapi.testclient import TestClient
    from sqlalchemy import text

    from db.session import alembic_config, make_engine
    from server.api.app import create_app
    from server.settings import Settings

    url = f"sqlite:///{path}"
    app = create_app(Settings(db_url=url, bootstrap_token=TOKEN))
    with TestClient(app, base_url="http://127.0.0.1",
                    headers={"Authorization": f"Bearer {TOKEN}"}) as c:
        slot = "/controllers/1/tools/1"
        r = c.put(slot, json={"name": "pointer", "pose": {"x": 1.5, "y": -2.25, "z": 180.125,
                                                          "a": 0.5, "b": -0.25, "c": 179.75}},
                  headers={"If-Match": c.get(slot).headers["ETag"]})
        assert r.status_code == 200, r.text
    app.state.engine.dispose()
    command.downgrade(alembic_config(url), OLD)
    engine = make_engine(url)
    with engine.begin() as conn:
        edit = conn.execute(text("SELECT max(id) FROM audit_record WHERE \"after\" IS NOT NULL "
                                 "AND \"before\" IS NOT NULL")).scalar()
        assert edit is not None, "no slot-edit audit record to copy"
        have = conn.execute(text("SELECT count(*) FROM audit_record")).scalar()
        cols = [r[1] for r in conn.exec_driver_sql("PRAGMA table_info(audit_record)") if r[1] != "id"]
        names = ", ".join(f'"{c}"' for c in cols)
        conn.execute(text(
            f"WITH RECURSIVE n(k) AS (SELECT 1 UNION ALL SELECT k + 1 FROM n WHERE k < :more) "
            f"INSERT INTO audit_record ({names}) SELECT {names} FROM audit_record, n "
            f"WHERE audit_record.id = :edit"), {"more": max(rows - have, 0), "edit": edit})
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == OLD
    engine.dispose()


def children_cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000, help="audit records in the file")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="pendant-upgrade-time-") as tmp:
        path = Path(tmp) / "old.db"
        make_file(path, args.rows)
        mb = path.stat().st_size / 1e6
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        t, c = time.perf_counter(), children_cpu_s()
        run = subprocess.run([sys.executable, "-m", "server.cli", "db", "upgrade", "--db",
                              f"sqlite:///{path}"], env=env, capture_output=True, text=True,
                             check=False)
        upgrade_s, cpu_s = time.perf_counter() - t, children_cpu_s() - c
        assert run.returncode == 0, run.stdout + run.stderr
        print(run.stdout.strip())
    print(f"rows={args.rows} file_mb={mb:.0f} upgrade_s={upgrade_s:.1f} upgrade_cpu_s={cpu_s:.1f}")


if __name__ == "__main__":
    main()
