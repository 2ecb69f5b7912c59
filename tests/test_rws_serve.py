"""``pendant serve --rws-port --kvp-port``: both controller faces start beside REST on its
database, answer the unmodified clients, and stop with the service; mistakes in the flags
are one line naming the flag."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from browser_helpers import free_port

rws = pytest.importorskip("abb_robot_client.rws")
openshowvar = pytest.importorskip("py_openshowvar").openshowvar
ROOT = Path(__file__).resolve().parent.parent


def pendant(*args: str, **kw) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    return subprocess.run([sys.executable, "-m", "server.cli", *args], check=False, capture_output=True,
                          text=True, env=env, timeout=120, **kw)


def wait_listening(port: int, proc: subprocess.Popen, timeout_s: float = 90.0) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else "exited"
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            time.sleep(0.1)
    raise AssertionError(f"nothing listens on {port} after {timeout_s} s")


def test_serve_starts_both_faces(fresh_db, tmp_path: Path) -> None:

    db_url = fresh_db()
    r = pendant("users", "add", "cellpc", "--role", "Expert", "--db", db_url)
    assert r.returncode == 0, r.stderr
    r = pendant("users", "rws-password", "cellpc", "--db", db_url, input="cellpc-rws-secret\n")
    assert r.returncode == 0, r.stderr
    port, rws_port, kvp_port = free_port(), free_port(), free_port()
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "server.cli", "serve", "--db", db_url, "--port", str(port),
         "--job-workers", "0", "--rws-port", str(rws_port), "--rws-controller", "cell-1",
         "--kvp-port", str(kvp_port), "--kvp-user", "cellpc"],
        env=env, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        wait_listening(port, proc)
        wait_listening(rws_port, proc)
        wait_listening(kvp_port, proc)
        c = rws.RWS(f"http://127.0.0.1:{rws_port}", "cellpc", "cellpc-rws-secret")
        c.set_rapid_variable("tool2", "[TRUE,[[0,0,99.5],[1,0,0,0]],[1,[0,0,40],[1,0,0,0],0,0,0]]")
        k = openshowvar("127.0.0.1", kvp_port)
        assert k.read("TOOL_DATA[2]", debug=False) == \
            b"{FRAME: X 0.0, Y 0.0, Z 99.5, A 0.0, B 0.0, C 0.0}"
        k.close()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            assert proc.wait(timeout=60) == 130  # Ctrl-C: "interrupted", the faces stopped too
        finally:
            if proc.poll() is None:
                proc.kill()
            proc.stderr.close()  # type: ignore[union-attr]


def test_kvp_flags_mistakes_name_the_flag(fresh_db, tmp_path: Path) -> None:

    db_url = fresh_db()
    base = ["serve", "--db", db_url, "--port", str(free_port()), "--job-workers", "0",
            "--kvp-port", str(free_port())]
    r = pendant(*base)
    assert r.returncode == 2 and "--kvp-user" in r.stderr
    r = pendant(*base, "--kvp-user", "admin", "--kvp-host", "0.0.0.0")
    assert r.returncode == 2 and "--kvp-allow" in r.stderr
