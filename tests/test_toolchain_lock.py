"""The test toolchain's lock (issue 22, item 6): ``tests/run`` installs from
``tests/requirements.lock``, so it must pin every package pyproject names, at a version
pyproject allows; otherwise a fresh machine gets whatever upstream released that day."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from packaging.requirements import Requirement
from packaging.version import Version

ROOT = Path(__file__).resolve().parent.parent


def _pins() -> dict[str, list[tuple[Version, str]]]:
    """name -> [(version, marker text)] of every ``name==version`` line of the lock."""
    pins: dict[str, list[tuple[Version, str]]] = {}
    for line in (ROOT / "tests" / "requirements.lock").read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9_.-]+)==([^ ;]+)\s*(?:;\s*(.*))?$", line)
        if m:
            name = re.sub(r"[-_.]+", "-", m.group(1)).lower()
            pins.setdefault(name, []).append((Version(m.group(2)), m.group(3) or ""))
    return pins


def _pyproject_requirements() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return [Requirement(r) for r in project["dependencies"] + project["optional-dependencies"]["test"]]


def test_the_lock_pins_every_requirement_within_pyprojects_range() -> None:
    pins = _pins()
    for req in _pyproject_requirements():
        name = re.sub(r"[-_.]+", "-", req.name).lower()
        assert name in pins, f"{req.name} is in pyproject.toml but not pinned in tests/requirements.lock"
        for version, marker in pins[name]:
            assert req.specifier.contains(version, prereleases=True), (
                f"tests/requirements.lock pins {req.name}=={version} ({marker or 'every Python'}), "
                f"outside pyproject's {req.specifier}")


def test_tests_run_installs_from_the_lock() -> None:
    run = (ROOT / "tests" / "run").read_text()
    install = [line for line in run.splitlines() if re.match(r"\s*python3 -m pip install", line)]
    assert install and all("-c tests/requirements.lock" in line for line in install), install
