"""Engine, sessions and the schema step.

SQLite runs in WAL mode; SQLAlchemy's pysqlite recipe hands transactions to SQLite itself so a
writing request can start with ``BEGIN IMMEDIATE`` (it takes the database's write lock first,
across processes, before it reads what it will change). PostgreSQL writers lock the rows they
change with ``SELECT ... FOR UPDATE`` instead (see :func:`lock_for_write`).

Migrations are a step of their own (``pendant db upgrade``): :func:`upgrade` runs Alembic
under a database-wide lock (``pg_advisory_lock`` on PostgreSQL, an exclusive ``flock`` on a
file beside the SQLite database), so several processes starting on one fresh database migrate
it once; :func:`schema_status` tells ``serve`` whether the schema is the code's.
"""

from __future__ import annotations

import contextlib
import fcntl
import functools
from collections.abc import Iterator
from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Engine, create_engine, event, text
from sqlalchemy.orm import Session, sessionmaker

DB_DIR = Path(__file__).resolve().parent
WRITE = {"sqlite_begin": "BEGIN IMMEDIATE"}  # execution options of a writing session
BUSY_TIMEOUT_MS = 30000  # how long a SQLite statement waits for a lock held by another writer
PG_POOL_SIZE = 10  # PostgreSQL connections a process keeps open (docs/deploy.md)
POOL_TIMEOUT_S = 30.0  # how long a request waits for a free connection of its process (503)
MIGRATION_LOCK_ID = 0x70656E64  # "pend": the pg_advisory_lock key of the schema step


def make_engine(url: str) -> Engine:
    """An engine for ``url``; SQLite gets WAL, foreign keys and a busy timeout per connection."""
    is_sqlite = url.startswith("sqlite")
    connect_args = ({"check_same_thread": False, "timeout": BUSY_TIMEOUT_MS / 1000}
                    if is_sqlite else {})
    # PostgreSQL: a process opens up to PG_POOL_SIZE connections and keeps them; a request
    # finding them all busy waits for one. No overflow connections: SQLAlchemy closes each as
    # it is returned, and a new backend costs PostgreSQL a fork and a SCRAM login; with 5
    # kept and 10 overflowing, at 100 touch-ups/s beside 300 reads/s, that churn took half a
    # core of the VM's two (benchmarks/plant.py, README "Measured")
    engine = create_engine(url, connect_args=connect_args,
                           pool_size=30 if is_sqlite else PG_POOL_SIZE,
                           max_overflow=10 if is_sqlite else 0, pool_timeout=POOL_TIMEOUT_S,
                           pool_pre_ping=not is_sqlite)
    if is_sqlite:
        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn, _record) -> None:  # noqa: ANN001
            dbapi_conn.isolation_level = None  # pysqlite emits no BEGIN of its own: _begin does
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=NORMAL")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
            cur.close()

        @event.listens_for(engine, "begin")
        def _begin(conn) -> None:  # noqa: ANN001
            # a writer takes SQLite's write lock now (BEGIN IMMEDIATE), not at its first
            # write: so what it read cannot be changed by another process before it writes;
            # it waits for the lock in SQLite's busy handler (BUSY_TIMEOUT_MS)
            conn.exec_driver_sql(conn.get_execution_options().get("sqlite_begin", "BEGIN"))
    return engine


def open_pool(engine: Engine) -> None:
    """PostgreSQL: open the process's :data:`PG_POOL_SIZE` connections now. A service process
    does it at start, not in its first busy second, where each new connection (a backend
    forked, a SCRAM login) held requests up while the load had already begun. SQLite: nothing
    (a connection is a file opened)."""
    if engine.dialect.name != "postgresql":
        return
    connections = [engine.connect() for _ in range(PG_POOL_SIZE)]
    for c in connections:
        c.close()  # back to the pool, which keeps PG_POOL_SIZE


def make_sessionmaker(engine: Engine) -> sessionmaker[Session]:
    return sessionmaker(bind=engine, expire_on_commit=False)


@functools.lru_cache(maxsize=64)
def write_engine(engine: Engine) -> Engine:
    """``engine`` whose transactions are a writer's (``BEGIN IMMEDIATE`` on SQLite)."""
    return engine.execution_options(**WRITE)


@functools.lru_cache(maxsize=64)
def read_engine(engine: Engine) -> Engine:
    """``engine`` for a session that only reads. On PostgreSQL in autocommit: each statement
    runs on its own snapshot, as it does inside a READ COMMITTED transaction anyway, without
    the BEGIN and COMMIT round trips (two of a one-row read's three). SQLite keeps its
    transaction: there a read's statements share one snapshot, and nothing goes over a wire."""
    if engine.dialect.name == "postgresql":
        return engine.execution_options(isolation_level="AUTOCOMMIT")
    return engine


def read_session(maker: sessionmaker[Session]) -> Session:
    """A session of ``maker`` for a request that only reads (:func:`read_engine`)."""
    return maker(bind=read_engine(maker.kw["bind"]))


def write_session(maker: sessionmaker[Session]) -> Session:
    """A session whose transaction is a writer's: ``BEGIN IMMEDIATE`` on SQLite."""
    return maker(bind=write_engine(maker.kw["bind"]))


def is_postgres(db: Session | Engine) -> bool:
    bind = db.get_bind() if isinstance(db, Session) else db
    return bind.dialect.name == "postgresql"


# ------------------------------------------------------------------------------- schema

def alembic_config(url: str) -> Config:
    cfg = Config(str(DB_DIR / "alembic.ini"))
    cfg.set_main_option("script_location", str(DB_DIR / "migrations"))
    cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


def _url(engine: Engine) -> str:
    return engine.url.render_as_string(hide_password=False)


def head_revision(engine: Engine) -> str:
    return ScriptDirectory.from_config(alembic_config(_url(engine))).get_current_head()


def current_revision(engine: Engine) -> str | None:
    """The database's Alembic revision (None when it has no schema yet)."""
    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def schema_status(engine: Engine) -> tuple[str | None, str]:
    """(the database's Alembic revision or None when empty, the code's head revision)."""
    return current_revision(engine), head_revision(engine)


@contextlib.contextmanager
def migration_lock(engine: Engine) -> Iterator[None]:
    """One schema step at a time per database: ``pg_advisory_lock`` on PostgreSQL (held by a
    connection, released when it ends), an exclusive ``flock`` on ``<db>.migrate.lock`` beside
    a SQLite file (an in-memory database belongs to one process anyway)."""
    if engine.dialect.name == "postgresql":
        with engine.connect() as conn:
            conn.execute(text("SELECT pg_advisory_lock(:k)"), {"k": MIGRATION_LOCK_ID})
            conn.commit()
            try:
                yield
            finally:
                conn.execute(text("SELECT pg_advisory_unlock(:k)"), {"k": MIGRATION_LOCK_ID})
                conn.commit()
        return
    path = engine.url.database
    if engine.dialect.name != "sqlite" or not path or path == ":memory:":
        yield
        return
    with open(f"{path}.migrate.lock", "a+b") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def run_migrations(engine: Engine) -> None:
    """Bring the schema to the newest Alembic revision (``alembic upgrade head``), unlocked.

    SQLite: with foreign keys off for the run, then checked. A revision that SQLite cannot
    ALTER makes a table anew, copies its rows, drops the old table and renames the new one
    (Alembic's batch mode, SQLite's own 12-step procedure); with foreign keys on, that DROP
    deletes every row referring to the table by cascade. SQLite ignores the pragma inside a
    transaction: it is set on the connection before the migration's transaction begins, and
    put back after. A dangling reference found at the end rolls the whole upgrade back."""
    cfg = alembic_config(_url(engine))
    sqlite = engine.dialect.name == "sqlite"
    with engine.connect() as connection:
        raw = connection.connection.driver_connection if sqlite else None
        if raw is not None:
            raw.execute("PRAGMA foreign_keys=OFF")  # autocommit: outside any transaction
        try:
            with connection.begin():
                cfg.attributes["connection"] = connection
                command.upgrade(cfg, "head")
                if raw is not None:
                    dangling = connection.exec_driver_sql("PRAGMA foreign_key_check").fetchall()
                    if dangling:
                        raise RuntimeError(f"the migration left rows referring to rows that are "
                                           f"gone (table, rowid, parent): {dangling[:5]}")
        finally:
            if raw is not None:
                raw.execute("PRAGMA foreign_keys=ON")


def upgrade(engine: Engine) -> tuple[str | None, str]:
    """``pendant db upgrade``: migrate to head under :func:`migration_lock`; (from, to)."""
    with migration_lock(engine):
        current, head = schema_status(engine)
        if current != head:
            run_migrations(engine)
        return current, head
