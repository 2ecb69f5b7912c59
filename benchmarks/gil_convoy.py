"""Why a database round trip in a worker thread costs milliseconds under load: the GIL's
convoy (``benchmarks/README.md``, plant.py, "Where the time goes").

A thread that waits for the database lets go of the GIL; when the answer is there it must take
the GIL back, and while another thread of the process computes (the event loop answering
requests) it waits until that thread is made to let go: up to the switch interval, 5 ms. One
thread sends ``SELECT 1`` in a loop, alone and beside one thread that only computes, at
several switch intervals: on SQLite (a file in a temporary directory: sqlite3 lets go of the
GIL around every statement too) and, inside ``pg_virtualenv``, on PostgreSQL (psycopg). The
last line:

    sqlite_alone_qps=… sqlite_beside_qps=… pg_alone_qps=… pg_beside_qps=…   (at 5 ms)

    python benchmarks/gil_convoy.py [--seconds 2] [--no-pg]
"""

from __future__ import annotations

import argparse
import os
import sqlite3
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.in_pg import report, run_in_pg  # noqa: E402

INTERVALS_S = (0.005, 0.001, 0.0002)  # 5 ms is CPython's default


def queries_per_second(connect: Callable[[], object], seconds: float, beside: bool) -> float:
    """``SELECT 1`` answered per second by one thread, with or without a computing thread."""
    stop = threading.Event()

    def compute() -> None:
        x = 0
        while not stop.is_set():
            x += 1

    spinner = threading.Thread(target=compute) if beside else None
    conn = connect()
    if spinner:
        spinner.start()
    try:
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            conn.execute("SELECT 1").fetchone()  # type: ignore[attr-defined]
            n += 1
        return n / (time.perf_counter() - t0)
    finally:
        stop.set()
        if spinner:
            spinner.join()
        conn.close()  # type: ignore[attr-defined]


def measure(name: str, connect: Callable[[], object], seconds: float) -> dict[str, float]:
    default = sys.getswitchinterval()
    out = {}
    try:
        for interval in INTERVALS_S:
            sys.setswitchinterval(interval)
            alone = queries_per_second(connect, seconds, False)
            beside = queries_per_second(connect, seconds, True)
            print(f"{name}, switch interval {interval * 1e3:g} ms: {alone:.0f} queries/s alone, "
                  f"{beside:.0f} beside a computing thread ({alone / beside:.0f}x slower)",
                  flush=True)
            if interval == 0.005:
                out = {"alone": alone, "beside": beside}
    finally:
        sys.setswitchinterval(default)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--no-pg", action="store_true")
    ap.add_argument("--pg-inner", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.pg_inner:
        import psycopg

        r = measure("postgresql", lambda: psycopg.connect("", autocommit=True), args.seconds)
        report(alone=round(r["alone"]), beside=round(r["beside"]))
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "convoy.db")
        lite = measure("sqlite", lambda: sqlite3.connect(path, check_same_thread=False),
                       args.seconds)
    pg = {"alone": float("nan"), "beside": float("nan")}
    if not args.no_pg and (r := run_in_pg(__file__, ["--seconds", str(args.seconds)])):
        pg = r
    print(f"sqlite_alone_qps={lite['alone']:.0f} sqlite_beside_qps={lite['beside']:.0f} "
          f"pg_alone_qps={pg['alone']:.0f} pg_beside_qps={pg['beside']:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
