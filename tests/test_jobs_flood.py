"""The 45-analyses flood (issue 8): the service, started as the README says (``pendant serve``,
its two job workers included), gets 45 analyses at once and a pendant keeps reading its tool
slot meanwhile. The analyses queue up as jobs; the read stays under 100 ms (median, and no
read above 1 s; the median, p95 and max are printed with the quiet median before the flood)."""

from __future__ import annotations

import os
import signal
import statistics
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import admin_http as httpx  # httpx as the first Administrator
from api_helpers import ADMIN_TOKEN

from solvers.physics import Imperfections
from solvers.simulate import simulate_recording

ROOT = Path(__file__).resolve().parent.parent
N_ANALYSES = 45
READERS = 2  # pendants polling their tool slot


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def serve(db_url: str, port: int) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
           "PENDANT_ADMIN_TOKEN": ADMIN_TOKEN}
    return subprocess.Popen([sys.executable, "-m", "server.cli", "serve", "--db", db_url,
                             "--port", str(port)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def wait_ready(base: str, proc: subprocess.Popen) -> None:
    for _ in range(300):
        assert proc.poll() is None, "pendant serve exited"
        try:
            if httpx.get(f"{base}/controllers", timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    raise AssertionError("pendant serve did not start")


def test_45_analyses_queue_up_and_a_read_stays_under_100_ms(tmp_path):
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    proc = serve(f"sqlite:///{tmp_path / 'pendant.db'}", port)
    try:
        wait_ready(base, proc)
        doc = simulate_recording("tracker", "ur10", Imperfections(noise_mm=0.02), 2000, seed=2)
        rid = httpx.post(f"{base}/recordings", json=doc, timeout=60).json()["id"]

        quiet: list[float] = []
        with httpx.Client(base_url=base, timeout=30) as warm:  # the read path is warm
            for _ in range(100):
                t0 = time.perf_counter()
                assert warm.get("/controllers/1/tools/1").status_code == 200
                quiet.append(1e3 * (time.perf_counter() - t0))

        def post(k: int) -> httpx.Response:
            with httpx.Client(base_url=base, timeout=60) as c:
                return c.post(f"/recordings/{rid}/analyze", params={"seed": k})

        with ThreadPoolExecutor(N_ANALYSES) as ex:  # 45 at once, as the issue measured
            answers = list(ex.map(post, range(N_ANALYSES)))
        assert [r.status_code for r in answers] == [202] * N_ANALYSES
        ids = [r.json()["id"] for r in answers]

        latencies: list[float] = []
        lock = threading.Lock()
        stop = threading.Event()

        def reader() -> None:
            with httpx.Client(base_url=base, timeout=30) as c:
                while not stop.is_set():
                    t0 = time.perf_counter()
                    r = c.get("/controllers/1/tools/1")
                    dt = time.perf_counter() - t0
                    assert r.status_code == 200
                    with lock:
                        latencies.append(dt)
                    time.sleep(0.02)

        threads = [threading.Thread(target=reader) for _ in range(READERS)]
        for t in threads:
            t.start()
        states: dict[str, int] = {}
        with httpx.Client(base_url=base, timeout=30) as c:
            running_seen = False
            for _ in range(100):  # 10 s of reads while the jobs run (not all need to finish)
                states = {}
                for job_id in ids[::5]:
                    s = c.get(f"/jobs/{job_id}").json()["state"]
                    states[s] = states.get(s, 0) + 1
                running_seen |= "running" in states
                time.sleep(0.1)
            stop.set()
            for t in threads:
                t.join()
            cancelled = [c.post(f"/jobs/{j}/cancel").json()["state"] for j in ids]
        assert running_seen, "no analysis ran while the reads were measured"
        lat_ms = sorted(1e3 * v for v in latencies)
        p95 = lat_ms[int(0.95 * (len(lat_ms) - 1))]
        print(f"\nquiet: median {statistics.median(quiet):.1f} ms; "
              f"{len(lat_ms)} reads of /tools/1 during the flood: median "
              f"{statistics.median(lat_ms):.1f} ms, p95 {p95:.1f} ms, max {lat_ms[-1]:.1f} ms; "
              f"jobs {states}; after cancel: {sorted(set(cancelled))}")
        assert len(lat_ms) >= 100
        # the read stays under 100 ms (its median; the machine's own load sets the tail) and
        # never stalls (before the jobs, one read waited 85 s behind 45 analyses)
        assert statistics.median(lat_ms) < 100 and lat_ms[-1] < 1000, lat_ms[-20:]
        assert set(cancelled) <= {"done", "cancelled", "running"}
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
