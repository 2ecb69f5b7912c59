"""Benchmark of the pendant service: touch-up and compute under 20 concurrent clients.

Starts ``pendant serve`` (uvicorn, one process) on loopback with a temporary SQLite file, opens
one XYZ 4-point session per client, then each client (a thread with its own httpx client)
re-teaches its steps (``POST .../touch-up`` with recorded joints) and computes
(``POST .../compute``) a bounded number of times within a time limit. Prints a table of
requests/s and latency percentiles; the last line is ``rps=<touch-up req/s> p99_ms=<touch-up p99>``.

    python benchmarks/api.py [--clients 20] [--requests 40] [--seconds 30]
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from server.emulator import approach, cell_for, home_joints  # noqa: E402
from solvers.robots import ROBOTS  # noqa: E402

TOKEN = "pdt_benchmark-administrator-token-0123456789"  # the service's first Administrator
HEADERS = {"Authorization": f"Bearer {TOKEN}"}
ORIENTATIONS = ((0.0, 0.0, 0.0), (30.0, 0.0, 0.0), (30.0, 120.0, 90.0), (30.0, 240.0, -90.0))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def touch_joints() -> list[list[float]]:
    """Joint values of four good touch-ups of the demo cell's reference tip."""
    robot = ROBOTS["kuka_kr6_r900_sixx"]
    cell, q, out = cell_for(robot, 1), np.array(home_joints(robot)), []
    for tilt, around, spin in ORIENTATIONS:
        q = approach(robot, cell, q, "reference_tip", tilt, around, spin)
        out.append(q.tolist())
    return out


def wait_ready(base: str, proc: subprocess.Popen, timeout_s: float = 60.0) -> None:
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout_s:
        if proc.poll() is not None:
            raise RuntimeError(f"the service exited with {proc.returncode}")
        try:
            if httpx.get(f"{base}/controllers", timeout=1.0, headers=HEADERS).status_code == 200:
                return
        except httpx.HTTPError:
            time.sleep(0.2)
    raise RuntimeError("the service did not start in time")


Request = Callable[[httpx.Client, str, int], httpx.Response]


def run_phase(base: str, urls: list[str], make_request: Request, n_requests: int,
              seconds: float) -> tuple[list[float], int, float]:
    """Each client sends up to n_requests (or until ``seconds``).

    Returns the latencies (s), the count of non-2xx answers and the wall time (s)."""
    lat: list[float] = []
    errors = [0]
    lock = threading.Lock()
    deadline = time.perf_counter() + seconds

    def client(url: str) -> None:
        mine: list[float] = []
        bad = 0
        with httpx.Client(base_url=base, timeout=30.0, headers=HEADERS) as http:
            for k in range(n_requests):
                if time.perf_counter() > deadline:
                    break
                t0 = time.perf_counter()
                r = make_request(http, url, k)
                mine.append(time.perf_counter() - t0)
                bad += r.status_code >= 300
        with lock:
            lat.extend(mine)
            errors[0] += bad

    threads = [threading.Thread(target=client, args=(u,)) for u in urls]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return lat, errors[0], time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--requests", type=int, default=40, help="per client and phase")
    ap.add_argument("--seconds", type=float, default=30.0, help="time limit per phase")
    args = ap.parse_args()

    joints = touch_joints()
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    with tempfile.TemporaryDirectory() as tmp:
        db = f"sqlite:///{Path(tmp) / 'bench.db'}"
        cmd = [sys.executable, "-m", "server.cli", "serve", "--port", str(port), "--db", db]
        env = {**os.environ, "PENDANT_ADMIN_TOKEN": TOKEN}
        proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        try:
            wait_ready(base, proc)
            urls = []
            with httpx.Client(base_url=base, timeout=30.0, headers=HEADERS) as http:
                for _ in range(args.clients):
                    s = http.post("/controllers/1/sessions",
                                  json={"method": "tool.xyz_4point", "target_no": 1})
                    url = f"/controllers/1/sessions/{s.json()['id']}"
                    for k, q in enumerate(joints):
                        r = http.post(f"{url}/touch-up", json={"step": k, "joints_deg": q})
                        r.raise_for_status()
                    urls.append(url)

            def touch(http: httpx.Client, url: str, k: int) -> httpx.Response:
                body = {"step": k % 4, "joints_deg": joints[k % 4]}
                return http.post(f"{url}/touch-up", json=body)

            def compute(http: httpx.Client, url: str, k: int) -> httpx.Response:
                return http.post(f"{url}/compute")

            rows = []
            for name, fn in (("touch-up", touch), ("compute", compute)):
                lat, errors, wall = run_phase(base, urls, fn, args.requests, args.seconds)
                ms = np.array(lat) * 1e3
                p50, p90, p99 = np.percentile(ms, [50, 90, 99])
                rows.append((name, len(lat), errors, len(lat) / wall, p50, p90, p99, ms.max()))
        finally:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()

    print(f"pendant API, {args.clients} concurrent clients, uvicorn 1 process, SQLite WAL")
    print(f"{'endpoint':10s} {'requests':>8s} {'errors':>6s} {'req/s':>8s} {'p50_ms':>8s} "
          f"{'p90_ms':>8s} {'p99_ms':>8s} {'max_ms':>8s}")
    for name, n, err, rps, p50, p90, p99, mx in rows:
        print(f"{name:10s} {n:8d} {err:6d} {rps:8.1f} {p50:8.1f} {p90:8.1f} {p99:8.1f} {mx:8.1f}")
    print(f"rps={rows[0][3]:.1f} p99_ms={rows[0][6]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
