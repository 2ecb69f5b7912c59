"""``pendant serve`` stopped with Ctrl-C starts again at once on the same port (issue 27), and
every start says where its database is; a start after the first says how to get a login."""

from __future__ import annotations

import http.client
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(port: int, db: Path) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k != "PENDANT_ADMIN_TOKEN"}
    env["PYTHONPATH"] = str(ROOT)  # no token given: the first start makes the Administrator
    return subprocess.Popen([sys.executable, "-m", "server.cli", "serve", "--port", str(port),
                             "--db", f"sqlite:///{db}", "--job-workers", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            cwd=ROOT, start_new_session=True)


def _connect_when_up(port: int, proc: subprocess.Popen) -> http.client.HTTPConnection:
    """A keep-alive connection that got an answer (polls until the service listens)."""
    for _ in range(600):
        if proc.poll() is not None:
            raise AssertionError(proc.communicate()[1])
        conn = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
        try:
            conn.request("GET", "/healthz")
            assert conn.getresponse().read()
            return conn
        except OSError:
            conn.close()
            time.sleep(0.05)
    raise AssertionError("the service did not start")


def _stop(proc: subprocess.Popen) -> str:
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C
    try:
        return proc.communicate(timeout=30)[1]
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


def _time_wait_on(port: int) -> bool:
    """Whether a TCP connection of local port ``port`` is in TIME_WAIT (/proc/net/tcp, state 06)."""
    for line in Path("/proc/net/tcp").read_text().splitlines()[1:]:
        local, state = line.split()[1], line.split()[3]
        if int(local.split(":")[1], 16) == port and state == "06":
            return True
    return False


def test_serve_starts_again_at_once_after_ctrl_c(tmp_path):
    port, db = _free_port(), tmp_path / "p.db"
    first = _start(port, db)
    conn = _connect_when_up(port, first)  # kept open: the service closes it as it stops
    err1 = _stop(first)
    conn.close()
    assert _time_wait_on(port), "the stop left no connection in TIME_WAIT: nothing was tested"
    second = _start(port, db)
    try:
        _connect_when_up(port, second).close()
    finally:
        err2 = _stop(second)
    assert "is in use" not in err2, err2
    assert f"database: sqlite:///{db}" in err1 and f"database: sqlite:///{db}" in err2
    assert "first start" in err1 and "first start" not in err2
    assert "pendant tokens create admin" in err2, err2


def test_a_real_listener_still_refuses_the_port(tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        proc = _start(port, tmp_path / "p.db")
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and f"port {port} on 127.0.0.1 is in use" in err, err
