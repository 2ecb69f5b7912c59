"""The service as a plant runs it: several uvicorn worker processes on one database, driven by
many concurrent HTTP clients (httpx), and killed with SIGKILL.

``service(db_url, workers)`` starts ``uvicorn server.api.app:app --workers N`` in its own process
group (so the workers race on a fresh database's schema themselves) and yields a
:class:`Service`; it is stopped (the group, SIGKILL) on exit.
"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import admin_http as httpx  # httpx as the first Administrator
from api_helpers import ADMIN_TOKEN

from browser_helpers import free_port

ROOT = Path(__file__).resolve().parent.parent


@dataclass
class Service:
    url: str
    proc: subprocess.Popen
    log: Path
    restarts: int = 0  # workers killed so far (each comes back with its own startup line)

    def workers(self) -> list[int]:
        """The pids of the master's worker processes (children of the uvicorn master)."""
        path = Path(f"/proc/{self.proc.pid}/task/{self.proc.pid}/children")
        try:
            children = [int(p) for p in path.read_text().split()]
        except OSError:
            return []
        out = []
        for pid in children:  # not multiprocessing's resource tracker
            try:
                if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    out.append(pid)
            except OSError:
                pass
        return out

    def log_text(self) -> str:
        return self.log.read_text(errors="replace")


def wait_healthy(url: str, proc: subprocess.Popen, log: Path, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"the service exited ({proc.returncode}):\n{log.read_text()}")
        try:
            if httpx.get(f"{url}/healthz", timeout=2).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    raise RuntimeError(f"the service did not answer /healthz in {timeout_s} s:\n{log.read_text()}")


def start(db_url: str, workers: int, log: Path, port: int | None = None) -> Service:
    port = port or free_port()
    env = {**os.environ, "PENDANT_DB_URL": db_url, "PYTHONPATH": str(ROOT),
           "OPENBLAS_NUM_THREADS": "1", "PENDANT_ADMIN_TOKEN": ADMIN_TOKEN}
    f = log.open("ab")
    proc = subprocess.Popen([sys.executable, "-m", "uvicorn", "server.api.app:app", "--host",
                             "127.0.0.1", "--port", str(port), "--workers", str(workers),
                             "--timeout-worker-healthcheck", "60"],
                            cwd=ROOT, env=env, stdout=f, stderr=subprocess.STDOUT,
                            start_new_session=True)
    f.close()
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url, proc, log)
    except BaseException:
        kill(proc)
        raise
    return Service(url, proc, log)


def kill(proc: subprocess.Popen) -> None:
    """SIGKILL the service's process group (master and workers): a crash, not a shutdown."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=30)


def wait_workers(svc: Service, n: int, timeout_s: float = 120.0) -> None:
    """Until the master has ``n`` live workers that all answer (after a restart)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        started = svc.log_text().count("Application startup complete")
        if len(svc.workers()) == n and started >= n + svc.restarts:
            return
        time.sleep(0.1)
    raise RuntimeError(f"{n} workers not up in {timeout_s} s:\n{svc.log_text()}")


@contextmanager
def service(db_url: str, workers: int, log: Path) -> Iterator[Service]:
    svc = start(db_url, workers, log)
    try:
        wait_workers(svc, workers)
        yield svc
    finally:
        kill(svc.proc)


async def _send(url: str, requests: list[tuple[str, str, dict | None, dict]],
                limit: int) -> list[httpx.Response | Exception]:
    sem = asyncio.Semaphore(limit)
    limits = httpx.Limits(max_connections=limit, max_keepalive_connections=limit)
    async with httpx.AsyncClient(base_url=url, timeout=60, limits=limits) as client:
        async def one(method: str, path: str, body: dict | None, headers: dict):
            async with sem:
                try:
                    return await client.request(method, path, json=body, headers=headers)
                except httpx.HTTPError as err:
                    return err
        return await asyncio.gather(*(one(*r) for r in requests))


def concurrently(url: str, requests: list[tuple[str, str, dict | None, dict]],
                 limit: int = 200) -> list[httpx.Response | Exception]:
    """Send every request at once (up to ``limit`` connections); responses or errors, in order."""
    return asyncio.run(_send(url, requests, limit))
