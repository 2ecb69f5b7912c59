"""Every benchmark's imports resolve: a name moved in the code breaks the command that
re-measures a figure in the docs, and nothing else runs those commands (they take minutes).

Each ``import`` and ``from … import`` in ``benchmarks/*.py`` (function-local ones included,
where most of them are) is looked up without running the benchmark."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BENCHMARKS = sorted((ROOT / "benchmarks").glob("*.py"))
OWN = {"server", "db", "solvers", "emulator", "formats", "benchmarks"}  # the project's packages


def own_imports(path: Path) -> list[tuple[int, str, str | None]]:
    """(line, module, name or None) of each import of the project's own modules in ``path``."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module.split(".")[0] in OWN:
                out += [(node.lineno, node.module, a.name) for a in node.names]
        elif isinstance(node, ast.Import):
            out += [(node.lineno, a.name, None) for a in node.names
                    if a.name.split(".")[0] in OWN]
    return out


def test_the_benchmarks_import_the_project() -> None:
    assert BENCHMARKS and sum(len(own_imports(p)) for p in BENCHMARKS) > 10


@pytest.mark.parametrize("path", BENCHMARKS, ids=lambda p: p.name)
def test_a_benchmarks_imports_resolve(path: Path) -> None:
    sys.path.insert(0, str(ROOT))
    try:
        for line, module, name in own_imports(path):
            where = f"{path.name}:{line}"
            assert importlib.util.find_spec(module) is not None, f"{where}: no module {module}"
            if name is None:
                continue
            imported = importlib.import_module(module)
            submodule = (hasattr(imported, "__path__")
                         and importlib.util.find_spec(f"{module}.{name}") is not None)
            assert submodule or hasattr(imported, name), f"{where}: {module} has no {name}"
    finally:
        sys.path.remove(str(ROOT))
