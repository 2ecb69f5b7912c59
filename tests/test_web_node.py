"""The web pages' pure helpers (web/ui.js) under ``node --test`` (tests/web/*.test.mjs), so
tests/run covers them: the page logic is tested without Chromium and without a build step.
Skipped, with the reason, only where node is not installed."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_web_helpers_under_node_test():
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed: the web/ui.js tests run under `node --test` (node >= 20)")
    files = sorted(str(p) for p in (ROOT / "tests" / "web").glob("*.test.mjs"))
    assert files, "no tests/web/*.test.mjs"
    # web/ui.js is an ES module without a package.json beside it: node < 20.19 needs the flag
    r = subprocess.run([node, "--experimental-detect-module", "--test", *files], cwd=ROOT,
                       capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 0, r.stdout[-4000:] + r.stderr[-2000:]
    assert "# fail 0" in r.stdout and "# pass 0" not in r.stdout, r.stdout[-2000:]
