"""The markers tests/run sorts the suite by (set in tests/conftest.py at collection): ``db``
for a test that opens the suite's database -- it uses the ``fresh_db`` fixture, at any depth
-- ``load`` (and ``serial``) for the load and crash tests; ``slow`` (by hand) runs beside
others."""

from __future__ import annotations

import pytest
from conftest import PROTOCOL_MODULES


def test_a_test_using_the_client_fixture_is_db(request, client):  # noqa: ANN001
    assert client.get("/healthz").status_code == 200
    assert request.node.get_closest_marker("db") is not None


def test_a_test_making_its_own_database_is_db(request, fresh_db):  # noqa: ANN001
    assert fresh_db(migrated=False)
    assert request.node.get_closest_marker("db") is not None


def test_a_test_that_opens_no_database_is_not_db(request, tmp_path, rng):  # noqa: ANN001
    # conftest's rng fixture: no database behind it
    assert request.node.get_closest_marker("db") is None
    assert request.node.get_closest_marker("serial") is None
    assert request.node.get_closest_marker("load") is None


@pytest.mark.load
def test_a_test_marked_load_by_hand_runs_alone(request):  # noqa: ANN001
    assert request.node.get_closest_marker("serial") is not None


@pytest.mark.slow
def test_a_slow_test_runs_beside_others(request):  # noqa: ANN001
    assert request.node.get_closest_marker("serial") is None
    assert request.node.get_closest_marker("load") is None


def test_every_load_module_exists():
    """A renamed load test would silently lose its ``load`` and ``serial`` markers."""
    from pathlib import Path

    from conftest import LOAD_MODULES

    here = Path(__file__).parent
    assert LOAD_MODULES and all((here / name).is_file() for name in LOAD_MODULES)


def test_no_test_returns_early_instead_of_skipping():
    """A test that does not apply says so with ``pytest.skip`` (counted as skipped); a bare
    ``return`` under a condition passes without checking anything."""
    import ast
    from pathlib import Path

    found = []
    for path in sorted(Path(__file__).parent.glob("test_*.py")):
        for fn in ast.walk(ast.parse(path.read_text())):
            if not (isinstance(fn, ast.FunctionDef) and fn.name.startswith("test_")):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.If) and any(
                        isinstance(s, ast.Return) and s.value is None for s in node.body):
                    found.append(f"{path.name}:{node.lineno} {fn.name}")
    assert not found, found


def test_tests_get_their_database_and_fixtures_from_conftest():
    """The ``db`` marker follows the ``fresh_db`` fixture: a test calling ``fresh_url`` itself
    would run in the SQLite pass only; a star import would hide where a fixture comes from."""
    from pathlib import Path

    here = Path(__file__).parent
    found = [f"{p.name}: {what}" for p in sorted(here.glob("*.py"))
             if p.name not in ("conftest.py", "db_backends.py", Path(__file__).name)
             for what in ("fresh_url(", "import *") if what in p.read_text()]
    assert not found, found


def test_the_faces_protocol_tests_are_marked_protocol(request):  # noqa: ANN001
    for name in PROTOCOL_MODULES:  # a renamed module would silently rejoin passes 2 and 3
        assert (request.config.rootpath / "tests" / name).is_file(), name
    assert request.node.get_closest_marker("protocol") is None
