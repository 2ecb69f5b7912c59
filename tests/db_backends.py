"""The database the tests run on: a SQLite file, or a real PostgreSQL server.

``PENDANT_TEST_BACKEND=postgresql`` (set by ``tests/run`` for its second pass, inside Debian's
``pg_virtualenv``, which exports PGHOST, PGPORT, PGUSER, PGPASSWORD) makes :func:`fresh_url`
return a new PostgreSQL database per test, copied from a template migrated once per test
process (``CREATE DATABASE ... TEMPLATE``). Otherwise it is a SQLite file in the test's
temporary directory, a copy of a file migrated once per test process. Either way Alembic runs
once per process (per pytest-xdist worker), not once per test; ``migrated=False`` gives an
empty database, for the tests of the migrations themselves (and of workers racing on them).
:func:`pg_available` tells whether a PostgreSQL server is reachable (the multi-process tests
then run on both backends).

A test (or a fixture it uses) that calls :func:`fresh_url` or :func:`backends` is marked
``db`` by ``tests/conftest.py``: the PostgreSQL pass runs those.
"""

from __future__ import annotations

import atexit
import itertools
import os
import shutil
import sqlite3
import tempfile
import uuid
from pathlib import Path
from urllib.parse import quote

BACKEND = os.environ.get("PENDANT_TEST_BACKEND", "sqlite")
TEMPLATE = f"pendant_tpl_{os.getpid()}"
_counter = itertools.count()
_template_ready = False
_sqlite_template: Path | None = None


def pg_available() -> bool:
    """A PostgreSQL server is configured (PGHOST/PGPORT, as pg_virtualenv exports) and psycopg
    is installed."""
    if not os.environ.get("PGHOST") and not os.environ.get("PGPORT"):
        return False
    try:
        import psycopg  # noqa: F401
    except ImportError:
        return False
    return True


def _pg(dbname: str) -> str:
    user = quote(os.environ.get("PGUSER", "postgres"))
    password = os.environ.get("PGPASSWORD")
    auth = user + (f":{quote(password)}" if password else "")
    host = os.environ.get("PGHOST", "localhost")
    port = os.environ.get("PGPORT", "5432")
    return f"postgresql+psycopg://{auth}@{host}:{port}/{dbname}"


def _admin(sql: str) -> None:
    import psycopg

    with psycopg.connect(dbname=os.environ.get("PGDATABASE", "postgres"),
                         autocommit=True) as conn:
        conn.execute(sql)


def fresh_pg_url(migrated: bool = True) -> str:
    """A new, empty PostgreSQL database (``migrated``: a copy of a migrated template)."""
    global _template_ready
    if migrated and not _template_ready:
        from db.session import make_engine, upgrade

        _admin(f"DROP DATABASE IF EXISTS {TEMPLATE}")
        _admin(f"CREATE DATABASE {TEMPLATE}")
        engine = make_engine(_pg(TEMPLATE))
        upgrade(engine)
        engine.dispose()
        _template_ready = True
    name = f"pendant_t{os.getpid()}_{next(_counter)}_{uuid.uuid4().hex[:6]}"
    _admin(f"CREATE DATABASE {name}" + (f" TEMPLATE {TEMPLATE}" if migrated else ""))
    return _pg(name)


def _migrated_sqlite() -> Path:
    """A SQLite file migrated to head, once per process; its copies are the tests' databases."""
    global _sqlite_template
    if _sqlite_template is None:
        from db.session import make_engine, upgrade

        folder = tempfile.mkdtemp(prefix="pendant-tpl-")
        atexit.register(shutil.rmtree, folder, True)
        path = Path(folder) / "template.db"
        engine = make_engine(f"sqlite:///{path}")
        upgrade(engine)
        engine.dispose()
        with sqlite3.connect(path) as con:  # one self-contained file: the WAL folded back in
            con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            con.execute("PRAGMA journal_mode=DELETE")
        _sqlite_template = path
    return _sqlite_template


def fresh_url(tmp_path: Path, backend: str | None = None, migrated: bool = True) -> str:
    """A fresh database of ``backend`` (default: the suite's) for one test: migrated to head
    (a copy of the template), or empty (``migrated=False``)."""
    if (backend or BACKEND) == "postgresql":
        return fresh_pg_url(migrated)
    path = tmp_path / f"pendant-{next(_counter)}.db"
    if migrated:
        shutil.copyfile(_migrated_sqlite(), path)
    return f"sqlite:///{path}"


def backends() -> list[str]:
    """The backends a multi-process test runs on: the suite's PostgreSQL pass runs them on
    PostgreSQL; otherwise SQLite, and PostgreSQL too when a server is reachable."""
    if BACKEND == "postgresql":
        return ["postgresql"]
    return ["sqlite", "postgresql"] if pg_available() else ["sqlite"]
