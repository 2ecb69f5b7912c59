"""Long CLI work shows it is running, on a terminal only (issue 14): ``pendant analyze`` of the
real UR10 recording draws a spinner with the seconds so far on stderr and erases it; piped,
stderr stays empty so scripts and logs see only the report."""

from __future__ import annotations

import os
import pty
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
UR10 = ROOT / "tests" / "data" / "ur10-laser-tracker" / "recording-series-d.json"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
ANALYZE = [sys.executable, "-m", "server.cli", "analyze", str(UR10)]


def test_analyze_on_a_terminal_shows_a_spinner_then_erases_it():
    controller, terminal = pty.openpty()
    run = subprocess.run(ANALYZE, stdout=subprocess.PIPE, stderr=terminal, env=ENV, timeout=600)
    os.close(terminal)
    err = b""
    while True:
        try:
            chunk = os.read(controller, 65536)
        except OSError:  # the terminal's other end is closed: all read
            break
        if not chunk:
            break
        err += chunk
    os.close(controller)
    text = err.decode()
    assert run.returncode == 0, text
    frames = re.findall(r"\r[|/\\-] pendant analyze recording-series-d\.json: working +(\d+\.\d) s", text)
    assert len(frames) >= 2 and float(frames[-1]) > float(frames[0])  # it counts while it works
    assert text.endswith("\r\x1b[K")  # the line is erased: the report alone stays
    assert b"joint" in run.stdout


def test_analyze_piped_prints_the_report_only():
    run = subprocess.run(ANALYZE, capture_output=True, env=ENV, timeout=600)
    assert run.returncode == 0
    assert run.stderr == b"" and b"joint" in run.stdout
