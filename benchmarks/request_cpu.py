"""The service's CPU per request, without contention: one uvicorn worker on a fresh database,
requests sent one after another on one keep-alive connection, the worker's user + system CPU
read from /proc around each batch (the smallest of three batches of N).

Reads ``GET /controllers/1`` and touch-ups (``POST .../touch-up`` with recorded joints, a
re-teach that writes the point) on SQLite, then on PostgreSQL in a throw-away
``pg_virtualenv`` cluster (``--no-pg`` skips it). The last line:

    lite_read_cpu_ms=… lite_touch_cpu_ms=… pg_read_cpu_ms=… pg_touch_cpu_ms=…

    python benchmarks/request_cpu.py [--requests 400] [--no-pg]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.in_pg import report, run_in_pg, url_from_env  # noqa: E402
from benchmarks.api import (
    HEADERS,
    cpu_seconds,
    free_port,
    prepare,
    service_pids,
    start,
    stop,
    touch_joints,
    wait_ready,
)


def measure(db_url: str, n: int) -> dict[str, float]:
    """CPU ms per read and per touch-up of one worker on ``db_url``."""
    prepare(db_url)
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    proc = start(db_url, port, 1)
    out: dict[str, float] = {}
    try:
        wait_ready(base, proc)
        pid = service_pids(proc)[-1]
        joints = touch_joints()
        with httpx.Client(base_url=base, headers=HEADERS, timeout=30.0) as http:
            s = http.post("/controllers/1/sessions",
                          json={"method": "tool.xyz_4point", "target_no": 1}).json()
            url = f"/controllers/1/sessions/{s['id']}/touch-up"
            for name, send in (("read", lambda k: http.get("/controllers/1")),
                               ("touch", lambda k: http.post(url, json={
                                   "step": k % 4, "joints_deg": joints[k % 4]}))):
                best = float("inf")
                for _ in range(3):
                    c0 = cpu_seconds([pid])
                    for k in range(n):
                        r = send(k)
                        if r.status_code >= 300:
                            raise RuntimeError(f"{name}: {r.status_code} {r.text[:200]}")
                    best = min(best, (cpu_seconds([pid]) - c0) * 1e3 / n)
                out[name] = best
    finally:
        stop(proc)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--requests", type=int, default=400)
    ap.add_argument("--no-pg", action="store_true")
    ap.add_argument("--pg-inner", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.pg_inner:
        r = measure(url_from_env(), args.requests)
        report(read=round(r["read"], 3), touch=round(r["touch"], 3))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        lite = measure(f"sqlite:///{tmp}/cpu.db", args.requests)
    print(f"sqlite: read {lite['read']:.3f} ms, touch-up {lite['touch']:.3f} ms of CPU "
          f"(load {os.getloadavg()[0]:.2f})", flush=True)
    pg = {"read": float("nan"), "touch": float("nan")}
    if not args.no_pg and (r := run_in_pg(__file__, ["--requests", str(args.requests)])):
        pg = r
        print(f"postgresql: read {pg['read']:.3f} ms, touch-up {pg['touch']:.3f} ms of CPU")
    print(f"lite_read_cpu_ms={lite['read']:.3f} lite_touch_cpu_ms={lite['touch']:.3f} "
          f"pg_read_cpu_ms={pg['read']:.3f} pg_touch_cpu_ms={pg['touch']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
