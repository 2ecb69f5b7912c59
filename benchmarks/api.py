"""Benchmark of the pendant service as a user meets it: Debian's ``wrk`` against uvicorn.

For each uvicorn worker count (``--workers 1,2``) the script migrates a fresh SQLite file,
starts ``uvicorn server.api.app:app --workers N`` on loopback (no job workers: nothing else takes
CPU), opens one XYZ 4-point session per connection with four touch-ups, and drives three
phases with ``wrk`` (C, two threads, ``--connections`` 20):

- ``touch-up``: ``POST .../sessions/{sid}/touch-up`` with recorded joints (a Lua script cycles
  sessions and steps: every request is a real re-teach that writes the point);
- ``controllers``: ``GET /controllers``;
- ``tool``: ``GET /controllers/1/tools/1``.

It prints requests/s, wrk's latency percentiles, any non-2xx answer, the service's CPU time
per request (user + system of the uvicorn processes over the phase, from /proc: unlike req/s it
hardly moves with what else runs on the machine), wrk's own CPU time per request (it shares the
cores) and the load average, per phase. Then, with
PostgreSQL (Debian's ``pg_virtualenv`` makes a throw-away cluster; ``--no-pg`` skips it), the
touch-up phase again at the best worker count. The last line is
``rps=<touch-up req/s, SQLite, best worker count> p99_ms=<its p99> pg_rps=<touch-up req/s on
PostgreSQL, or n/a> read_rps=<the slower of the two reads, at its best worker count>``.

    python benchmarks/api.py [--workers 1,2] [--connections 20] [--seconds 10] [--no-pg]
                             [--pg-delay-ms 0]

``--pg-delay-ms D`` puts ``benchmarks/delay_proxy.py`` between the service and PostgreSQL,
holding every chunk D ms each way: a database on another host, where each round trip a
batch makes under the controller's row lock costs 2 D.

Needs ``wrk`` (``apt-get install wrk``) and, for pg_rps, ``postgresql`` and psycopg.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.in_pg import report, run_in_pg, url_from_env  # noqa: E402
from emulator import approach, cell_for, home_joints  # noqa: E402
from solvers.robots import ROBOTS  # noqa: E402

TOKEN = "pdt_benchmark-administrator-token-0123456789"  # the service's first Administrator
HEADERS = {"Authorization": f"Bearer {TOKEN}"}
ORIENTATIONS = ((0.0, 0.0, 0.0), (30.0, 0.0, 0.0), (30.0, 120.0, 90.0), (30.0, 240.0, -90.0))
UNITS = {"us": 1e-3, "ms": 1.0, "s": 1e3}

TOUCH_LUA = """
local paths = {%(paths)s}
local bodies = {%(bodies)s}
local headers = {["Content-Type"] = "application/json", ["Authorization"] = "%(auth)s"}
local n = 0
request = function()
  local s = n %% #paths
  local k = math.floor(n / #paths) %% #bodies
  n = n + 1
  return wrk.format("POST", paths[s + 1], headers, bodies[k + 1])
end
"""


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


def wait_ready(base: str, proc: subprocess.Popen, timeout_s: float = 90.0) -> None:
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


def prepare(db_url: str) -> None:
    """Migrate ``db_url`` and make the demo controller once, before N workers share it."""
    from server.api.app import create_app
    from server.settings import Settings

    create_app(Settings(db_url=db_url, bootstrap_token=TOKEN)).state.engine.dispose()


def start(db_url: str, port: int, workers: int) -> subprocess.Popen:
    env = {**os.environ, "PENDANT_DB_URL": db_url, "PENDANT_ADMIN_TOKEN": TOKEN,
           "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    cmd = [sys.executable, "-m", "uvicorn", "server.api.app:app", "--port", str(port),
           "--workers", str(workers), "--log-level", "warning", "--no-access-log"]
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL)


def service_pids(proc: subprocess.Popen) -> list[int]:
    """uvicorn's process and its workers (``--workers N`` > 1 starts N children)."""
    out = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True).stdout
    return [proc.pid, *(int(p) for p in out.split())]


def cpu_seconds(pids: list[int]) -> float:
    """User + system CPU time of ``pids`` so far (Linux /proc; 0 where it cannot be read)."""
    total = 0.0
    for pid in pids:
        try:
            fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def stop(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def parse_wrk(out: str) -> dict[str, float]:
    """requests/s, p50/p90/p99 (ms) and non-2xx count from ``wrk --latency`` output."""
    res: dict[str, float] = {"rps": float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1))}
    for pct in ("50", "90", "99"):
        m = re.search(rf"^\s+{pct}%\s+([\d.]+)(us|ms|s)\s*$", out, re.M)
        res[f"p{pct}_ms"] = float(m.group(1)) * UNITS[m.group(2)]
    m = re.search(r"Non-2xx or 3xx responses:\s+(\d+)", out)
    res["non2xx"] = float(m.group(1)) if m else 0.0
    m = re.search(r"(\d+) requests in", out)
    res["requests"] = float(m.group(1))
    errs = re.search(r"Socket errors:.*", out)
    res["socket_errors"] = errs.group(0) if errs else ""  # type: ignore[assignment]
    return res


def wrk(url: str, connections: int, seconds: float, script: Path | None = None) -> dict:
    cmd = ["wrk", "-t2", f"-c{connections}", f"-d{seconds:g}s", "--latency", "--timeout", "10s",
           "-H", f"Authorization: {HEADERS['Authorization']}"]
    if script is not None:
        cmd += ["-s", str(script)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run(cmd + [url], check=True, capture_output=True, text=True).stdout
    after = resource.getrusage(resource.RUSAGE_CHILDREN)  # wrk's own CPU (it has been waited for)
    res = parse_wrk(out)
    used = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    res["wrk_cpu_ms"] = used * 1e3 / max(res["requests"], 1)
    return res


def touch_script(base: str, n_sessions: int, joints: list[list[float]], tmp: Path) -> Path:
    paths = []
    with httpx.Client(base_url=base, timeout=30.0, headers=HEADERS) as http:
        for _ in range(n_sessions):
            s = http.post("/controllers/1/sessions",
                          json={"method": "tool.xyz_4point", "target_no": 1})
            s.raise_for_status()
            url = f"/controllers/1/sessions/{s.json()['id']}"
            for k, q in enumerate(joints):
                http.post(f"{url}/touch-up", json={"step": k, "joints_deg": q}).raise_for_status()
            paths.append(f"{url}/touch-up")
    bodies = [json.dumps({"step": k, "joints_deg": q}) for k, q in enumerate(joints)]
    path = tmp / "touch.lua"
    path.write_text(TOUCH_LUA % {"auth": HEADERS["Authorization"], "paths": ", ".join(json.dumps(p) for p in paths),
                                 "bodies": ", ".join(json.dumps(b) for b in bodies)})
    return path


def run_service(db_url: str, workers: int, args: argparse.Namespace, phases: tuple[str, ...],
                joints: list[list[float]], tmp: Path) -> dict[str, dict]:
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    prepare(db_url)
    proc = start(db_url, port, workers)
    try:
        wait_ready(base, proc)
        script = touch_script(base, args.connections, joints, tmp)
        urls = {"touch-up": (base, script), "controllers": (f"{base}/controllers", None),
                "tool": (f"{base}/controllers/1/tools/1", None)}
        out = {}
        pids = service_pids(proc)
        for name in phases:
            url, s = urls[name]
            wrk(url, args.connections, min(2.0, args.seconds), s)  # warm-up
            cpu0 = cpu_seconds(pids)
            out[name] = wrk(url, args.connections, args.seconds, s)
            out[name]["cpu_ms"] = (cpu_seconds(pids) - cpu0) * 1e3 / max(out[name]["requests"], 1)
            out[name]["load"] = os.getloadavg()[0]
        return out
    finally:
        stop(proc)


def delayed_pg(delay_ms: float) -> tuple[str, subprocess.Popen | None]:
    """The pg_virtualenv cluster's URL, behind ``benchmarks/delay_proxy.py`` holding each
    chunk ``delay_ms`` each way when it is > 0 (PostgreSQL on another host), and the proxy."""
    if delay_ms <= 0:
        return url_from_env(), None
    port = free_port()
    proxy = subprocess.Popen([sys.executable, str(ROOT / "benchmarks" / "delay_proxy.py"),
                              str(port), os.environ["PGHOST"], os.environ["PGPORT"],
                              str(delay_ms)])
    for _ in range(100):  # listening?
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                break
        time.sleep(0.05)
    return url_from_env(str(port)), proxy


def pg_touch_rps(workers: int, args: argparse.Namespace) -> str:
    """Touch-up req/s on PostgreSQL (a pg_virtualenv cluster), or 'n/a' (the reason on stderr)."""
    if args.no_pg:
        return "n/a"
    r = run_in_pg(__file__, ["--workers", str(workers), "--connections", str(args.connections),
                             "--seconds", str(args.seconds), "--pg-delay-ms", str(args.pg_delay_ms)])
    return "n/a" if r is None else f"{r['rps']:.1f}"


def show(title: str, rows: dict[str, dict]) -> None:
    print(title)
    print(f"  {'phase':12s} {'requests':>9s} {'non2xx':>7s} {'req/s':>8s} {'p50_ms':>7s} "
          f"{'p90_ms':>7s} {'p99_ms':>7s} {'cpu_ms/req':>10s} {'wrk_ms/req':>10s} {'load':>5s}")
    for name, r in rows.items():
        print(f"  {name:12s} {r['requests']:9.0f} {r['non2xx']:7.0f} {r['rps']:8.1f} "
              f"{r['p50_ms']:7.1f} {r['p90_ms']:7.1f} {r['p99_ms']:7.1f} {r['cpu_ms']:10.2f} "
              f"{r['wrk_cpu_ms']:10.3f} {r['load']:5.2f}  {r['socket_errors']}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", default="1,2", help="uvicorn worker counts to try (1,2)")
    ap.add_argument("--connections", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=10.0, help="per phase")
    ap.add_argument("--no-pg", action="store_true", help="skip the PostgreSQL run")
    ap.add_argument("--pg-delay-ms", type=float, default=0.0,
                    help="PostgreSQL behind a proxy holding each chunk this long each way "
                         "(benchmarks/delay_proxy.py: a database on another host)")
    ap.add_argument("--pg-inner", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if shutil.which("wrk") is None:
        print("benchmarks/api.py needs wrk: apt-get install wrk", file=sys.stderr)
        return 2
    joints = touch_joints()
    counts = [int(w) for w in args.workers.split(",")]
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} "
          f"({os.cpu_count()} CPUs)")
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        if args.pg_inner:
            url, proxy = delayed_pg(args.pg_delay_ms)
            try:
                rows = run_service(url, counts[0], args, ("touch-up",), joints, tmp)
            finally:
                if proxy is not None:
                    proxy.kill()
                    proxy.wait()
            delay = f", {args.pg_delay_ms:g} ms each way" if args.pg_delay_ms > 0 else ""
            show(f"PostgreSQL{delay}, uvicorn --workers {counts[0]}, {args.connections} "
                 "connections", rows)
            report(rps=round(rows["touch-up"]["rps"], 1))
            return 0
        results = {}
        for n in counts:
            db = f"sqlite:///{tmp / f'bench-{n}.db'}"
            results[n] = run_service(db, n, args, ("touch-up", "controllers", "tool"), joints, tmp)
            show(f"SQLite WAL, uvicorn --workers {n}, {args.connections} connections, wrk -t2",
                 results[n])
    best = max(counts, key=lambda n: results[n]["touch-up"]["rps"])
    pg = pg_touch_rps(best, args)
    t = results[best]["touch-up"]
    reads = {n: min(results[n]["controllers"]["rps"], results[n]["tool"]["rps"]) for n in counts}
    best_read = max(counts, key=lambda n: reads[n])
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    print(f"best worker count for touch-up: {best}, for reads: {best_read}")
    print(f"rps={t['rps']:.1f} p99_ms={t['p99_ms']:.1f} pg_rps={pg} "
          f"read_rps={reads[best_read]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
