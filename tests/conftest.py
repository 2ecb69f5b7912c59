"""Shared fixtures: the robot library, a seeded random generator, and for the browser
tests a live service on a temporary SQLite file with Debian's Chromium.

Markers sort the suite for ``tests/run`` (they are set here, at collection, not by hand):

- ``db``: the test opens the suite's database, so the PostgreSQL pass runs it
  (``-m db``). A test is ``db`` when it uses the :func:`fresh_db` fixture, at any depth (the
  ``db_url``, ``client`` and ``site`` fixtures do): the one way a test gets the suite's
  database, so a new test is picked up without a list to keep. Tests that never open a
  database (solvers, formats, analysis statistics, doctests) and tests that name their own
  SQLite file run in the SQLite pass only: on PostgreSQL they would prove the same thing
  again. ``@pytest.mark.db`` marks one by hand.
- ``load``: the load and crash tests (``LOAD_MODULES``, and ``@pytest.mark.load`` by hand):
  several uvicorn workers, SIGKILLs, a 45-analyses flood with a latency bound, revocations
  under a jog load. They are also ``serial``; the lowest-versions pass leaves them out
  (``tests/run`` says why).
- ``slow`` (by hand): a test whose cost is size or trials (20 000 history rows, Monte Carlo
  coverage): it repeats calls that smaller tests make, so the lowest-versions pass leaves it
  out; passes 1 and 2 run it, beside other tests.
- ``protocol``: a face's wire protocol and process handling as an outside party meets them
  (``PROTOCOL_MODULES``: node-opcua against the OPC UA face, the face's certificate
  handshakes, ``serve``'s flags and restarts, an attacker's probes of the OPC UA, RWS and KVP
  faces: sessions, channels, Digest replays, sockets). What they prove does not depend on the database
  (each face's reads and writes run on PostgreSQL in that face's other tests) nor on a library
  floor the other tests do not reach (test_opcua.py opens encrypted channels,
  test_auth_certificates.py reads certificates): passes 2 and 3 leave them out.
- ``serial``: a test that loads the machine itself or measures it (the ``load`` tests, and
  ``@pytest.mark.serial`` where a test says so). When pytest-xdist runs the suite in several
  processes (``tests/run``: ``-n auto``) a serial test runs alone: it waits until the other
  processes' current tests end, and they wait until it ends (:func:`pytest_runtest_protocol`).
"""

from __future__ import annotations

import contextlib
import fcntl
from pathlib import Path

import numpy as np
import pytest

from solvers.robots import ROBOTS


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture(params=sorted(ROBOTS))
def robot(request):
    """Every arm of the library in turn."""
    return ROBOTS[request.param]


@pytest.fixture(scope="session")
def fresh_db(tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201
    """The one door to the suite's database: ``fresh_db(name="db", backend=None,
    migrated=True)`` makes a fresh one (a SQLite file, or PostgreSQL in the suite's PostgreSQL
    pass) and gives its URL. A test that uses this fixture, at any depth, is marked ``db``."""
    from db_backends import fresh_url

    def make(name: str = "db", backend: str | None = None, migrated: bool = True) -> str:
        return fresh_url(tmp_path_factory.mktemp(name), backend, migrated)

    return make


@pytest.fixture
def db_url(fresh_db) -> str:  # noqa: ANN001
    """A fresh database for one test (see :func:`fresh_db`)."""
    return fresh_db()


@pytest.fixture
def client(db_url: str):  # noqa: ANN201
    """A TestClient of the real app on :func:`db_url`, as the Administrator."""
    from api_helpers import make_client

    with make_client(db_url) as c:
        yield c


@pytest.fixture(scope="module")
def site(fresh_db):  # noqa: ANN001, ANN201
    """The real service (uvicorn, loopback, free port) on a fresh database per module."""
    from browser_helpers import serve

    with serve(fresh_db("site")) as url:
        yield url


@pytest.fixture(scope="module")
def chromium():  # noqa: ANN201
    """Headless Debian Chromium under Playwright (never a downloaded browser)."""
    from browser_helpers import browser

    with browser() as b:
        yield b


# ------------------------------------------------------------------- the markers of tests/run

TESTS_DIR = Path(__file__).resolve().parent
LOAD_MODULES = frozenset({"test_workers.py", "test_jobs_flood.py"})
PROTOCOL_MODULES = frozenset({"test_opcua_node.py", "test_opcua_security.py",
                              "test_rws_serve.py", "test_serve_restart.py",
                              "test_opcua_attack_findings.py", "test_faces_attack_findings.py"})


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "db: opens the suite's database (the PostgreSQL pass "
                                       "runs it); set by tests/conftest.py")
    config.addinivalue_line("markers", "load: a load or crash test (also serial); set by "
                                       "tests/conftest.py for LOAD_MODULES, or by hand")
    config.addinivalue_line("markers", "slow: costs size or trials, repeating calls smaller "
                                       "tests make (left out of the lowest-versions pass)")
    config.addinivalue_line("markers", "protocol: a face's wire protocol or process handling "
                                       "as an outside party meets them (passes 1 only); set "
                                       "by tests/conftest.py for PROTOCOL_MODULES")
    config.addinivalue_line("markers", "serial: runs on its own, not beside other tests "
                                       "(under pytest-xdist)")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.get_closest_marker("db") is None and "fresh_db" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.db)
        if item.path.name in LOAD_MODULES and item.get_closest_marker("load") is None:
            item.add_marker(pytest.mark.load)
        if item.path.name in PROTOCOL_MODULES:
            item.add_marker(pytest.mark.protocol)
        if item.get_closest_marker("load") is not None and item.get_closest_marker("serial") is None:
            item.add_marker(pytest.mark.serial)


# ------------------------------------------------------------- serial tests under pytest-xdist

@contextlib.contextmanager
def _flock(path: Path, mode: int):  # noqa: ANN202
    with open(path, "a+b") as f:
        fcntl.flock(f, mode)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):  # noqa: ANN201
    """Under pytest-xdist: a ``serial`` test holds the run's lock exclusively, every other
    test holds it shared, so a serial test (its fixtures' setup and teardown included) runs
    with no other test beside it. The gate (held by a serial test while it waits, passed
    through by the others) keeps a stream of short tests on the other processes from starving
    it. The wait comes before pytest-timeout's clock starts (this wrapper runs first). Without
    xdist: nothing to do."""
    workerinput = getattr(item.config, "workerinput", None)
    if workerinput is None:
        yield
        return
    # the run's temporary folder (each xdist process has its basetemp inside it)
    folder = item.config._tmp_path_factory.getbasetemp().parent  # noqa: SLF001
    gate = folder / f"serial-{workerinput['testrunuid']}.gate"
    run = gate.with_suffix(".run")
    if item.get_closest_marker("serial") is not None:
        with _flock(gate, fcntl.LOCK_EX), _flock(run, fcntl.LOCK_EX):
            yield
        return
    with _flock(gate, fcntl.LOCK_EX):
        pass
    with _flock(run, fcntl.LOCK_SH):
        yield
