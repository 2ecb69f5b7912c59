"""The markers tests/run sorts the suite by (set in tests/conftest.py at collection): ``db``
for a test that opens the suite's database -- through a fixture at any depth, a helper of
tests/, or a direct call of db_backends -- ``load`` (and ``serial``) for the
load and crash tests."""

from __future__ import annotations

from api_helpers import client, db_url  # noqa: F401  (fixtures)


def the_database(tmp_path):  # noqa: ANN001, ANN201
    """A helper of this module that opens the suite's database."""
    from db_backends import fresh_url

    return fresh_url(tmp_path)


def test_a_test_using_the_client_fixture_is_db(request, client):  # noqa: ANN001, F811
    assert request.node.get_closest_marker("db") is not None


def test_a_test_calling_a_helper_that_opens_the_database_is_db(request, tmp_path):  # noqa: ANN001
    assert the_database(tmp_path)
    assert request.node.get_closest_marker("db") is not None


def test_a_test_that_opens_no_database_is_not_db(request, tmp_path, rng):  # noqa: ANN001
    # conftest's rng fixture: no database behind it
    assert request.node.get_closest_marker("db") is None
    assert request.node.get_closest_marker("serial") is None
    assert request.node.get_closest_marker("load") is None


def test_every_load_module_exists():
    """A renamed load test would silently lose its ``load`` and ``serial`` markers."""
    from pathlib import Path

    from conftest import LOAD_MODULES

    here = Path(__file__).parent
    assert LOAD_MODULES and all((here / name).is_file() for name in LOAD_MODULES)
