"""A benchmark's PostgreSQL run: the same script again, inside a throw-away cluster.

Debian's ``pg_virtualenv`` makes a cluster, exports ``PGHOST``, ``PGPORT``, ``PGUSER``,
``PGPASSWORD`` and ``PGDATABASE``, runs the command and drops the cluster. A benchmark calls
:func:`run_in_pg` with its own file and arguments; that inner run (``--pg-inner``) measures
on :func:`url_from_env` and ends with :func:`report`'s line::

    pg_inner read=1.175 touch=4.425

which :func:`run_in_pg` returns as numbers, printing the rest of the inner run's output as
its own.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PREFIX = "pg_inner "  # the inner run's figures line


def url_from_env(port: str | None = None) -> str:
    """The cluster's URL, from what ``pg_virtualenv`` exports (``port``: another, a proxy's)."""
    e = os.environ
    return (f"postgresql+psycopg://{e['PGUSER']}:{e.get('PGPASSWORD', '')}@{e['PGHOST']}:"
            f"{port or e['PGPORT']}/{e['PGDATABASE']}")


def report(**figures: float) -> None:
    """The inner run's last line: its figures, ``name=value`` each."""
    print(PREFIX + " ".join(f"{k}={v}" for k, v in figures.items()), flush=True)


def run_in_pg(script: str, args: list[str], name: str = "postgresql") -> dict[str, float] | None:
    """Run ``script --pg-inner *args`` inside a throw-away cluster; print what it printed
    but its figures line, and return those figures; ``None`` (the reason on stderr) when
    ``pg_virtualenv`` is missing or the run failed."""
    if shutil.which("pg_virtualenv") is None:
        print(f"{name}: pg_virtualenv not found (apt-get install postgresql)", file=sys.stderr)
        return None
    r = subprocess.run(["pg_virtualenv", "-t", sys.executable, script, "--pg-inner", *args],
                       capture_output=True, text=True, cwd=ROOT, check=False)
    lines = r.stdout.splitlines()
    shown = [line for line in lines if not line.startswith(PREFIX)]
    if shown:
        print("\n".join(shown), flush=True)
    last = next((line for line in reversed(lines) if line.startswith(PREFIX)), None)
    if r.returncode != 0 or last is None:
        print(f"{name}: the run failed (exit {r.returncode}): {r.stderr[-800:]}",
              file=sys.stderr)
        return None
    return {k: float(v) for k, v in (kv.split("=", 1) for kv in last[len(PREFIX):].split())}
