"""How a write runs, whichever face: one writer's transaction, the controller locked, audited.

Every operation that changes rows runs in one transaction that

- is a **writer's** from its first statement (:func:`writer`): SQLite ``BEGIN IMMEDIATE``
  (the database's write lock, across processes, waited for in SQLite's busy handler,
  ``db.session``); on PostgreSQL its ``BEGIN`` is followed at once by ``SELECT ... FOR
  UPDATE`` of the controller's row (:func:`_lock_at_begin`), so every read-modify-write of one
  controller runs after the previous one committed;
- on SQLite, takes the database's **writers' turn** (:func:`writers_turn`): SQLite has one
  writer at a time anyway, and a writer that loses ``BEGIN IMMEDIATE`` waits in SQLite's busy
  handler, which sleeps 1, 2, 5, 10 ... up to 100 ms between tries and so hardly ever finds
  the lock free while another process's writers follow each other without a gap (a
  ``pendant users revoke`` beside a service under jog load waited seconds). The turn is a
  lock within the process and an ``flock`` of the file ``<database>-writers`` across
  processes, whose waiter the kernel wakes as soon as the holder lets go. On PostgreSQL the
  same function lets at most :data:`PG_WRITERS` writers of a process at a time hold a
  connection;
- ends with :func:`commit`: the operation's ``op.<name>`` audit record when it changed rows no
  row hook recorded (``server.auth.audit.operation``), then the commit; rolled back on any
  error.

:func:`writing` is all three for a face that opens its own transaction (OPC UA, RWS, KVP, the
CLI, a route computing outside the request's transaction). The REST request path
(``server.api.deps``) keeps its request-scoped session and its Idempotency-Key claim, and
uses the same pieces: :func:`writer`, :func:`writers_turn`, :func:`commit`.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import threading
from collections.abc import Iterator
from typing import Any

from sqlalchemy import event
from sqlalchemy.orm import Session, sessionmaker

from db import crud
from db.session import BUSY_TIMEOUT_MS, PG_POOL_SIZE, write_session
from server.auth import audit

LOCK_ON_BEGIN = "pendant_lock_controller"  # Session.info: the controller to lock at BEGIN
WRITER = "pendant_writer"  # Session.info: a writer's session (BEGIN IMMEDIATE)

Maker = sessionmaker[Session]


def _lock_at_begin(db: Session, _transaction: object, connection: Any) -> None:
    """``after_begin`` of a writer's session: lock its controller's row first (PostgreSQL;
    SQLite's ``BEGIN IMMEDIATE`` has already locked the database)."""
    cid = db.info.pop(LOCK_ON_BEGIN, None)
    if cid is not None and connection.dialect.name != "sqlite":
        crud.lock_controller(connection, cid)


def install(make_session: Maker) -> None:
    """The row lock at BEGIN for the writers' sessions of ``make_session`` (idempotent)."""
    if not event.contains(make_session, "after_begin", _lock_at_begin):
        event.listen(make_session, "after_begin", _lock_at_begin)


def writer(make_session: Maker, controller_id: int | None = None) -> Session:
    """A writer's session of ``make_session`` (``BEGIN IMMEDIATE`` on SQLite) whose transaction
    begins by locking ``controller_id``'s row (PostgreSQL), whichever statement comes first."""
    install(make_session)
    db = write_session(make_session)
    db.info[WRITER] = True
    if controller_id is not None:
        db.info[LOCK_ON_BEGIN] = controller_id
    return db


class _SqliteTurn:
    """The writers' turn of one SQLite database: a lock among this process's threads, then an
    ``flock`` of ``<database>-writers`` (none for an in-memory database) among processes.
    The file is opened once per process (a forked child opens its own: a descriptor inherited
    across ``fork`` shares its lock with the parent's)."""

    def __init__(self, database: str | None) -> None:
        self.path = (f"{database}-writers" if database and database != ":memory:"
                     and not database.startswith("file:") else None)
        self.threads = threading.Lock()
        self._fd: int | None = None
        self._pid = 0

    def _file(self) -> int:
        if self._fd is None or self._pid != os.getpid():
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
            self._pid = os.getpid()
        return self._fd

    @contextlib.contextmanager
    def held(self, timeout_s: float) -> Iterator[None]:
        if not self.threads.acquire(timeout=timeout_s):
            raise DatabaseBusy(timeout_s)
        try:
            if self.path is None:
                yield
                return
            fd = self._file()
            # waits as long as another process's writer's transaction lasts (as SQLite's own
            # lock would make it wait); this process's other writers wait on ``threads``
            fcntl.flock(fd, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            self.threads.release()


_SQLITE_TURNS: dict[str, _SqliteTurn] = {}  # database URL -> its writers' turn
_TURNS_LOCK = threading.Lock()
PG_WRITERS = PG_POOL_SIZE - 3  # a process's PostgreSQL writers at once: 3 connections for reads
_PG_WRITERS = threading.BoundedSemaphore(PG_WRITERS)
TURN_TIMEOUT_S = BUSY_TIMEOUT_MS / 1000  # a writer waits this long for its turn, then 503


@contextlib.contextmanager
def writers_turn(db: Session) -> Iterator[None]:
    """This process's turn to write ``db``'s database, held until the block ends (the
    transaction committed or rolled back). Nothing for a reader's session, nor when the
    session's transaction has begun already (it may hold SQLite's write lock, and waiting for a
    turn while holding it would deadlock with the thread whose turn it is).

    SQLite: one writer at a time among this process's threads and the processes that write
    the database with pendant (the database has one writer anyway), in the order the kernel
    wakes them; a writer that is not pendant's still meets these in SQLite's busy handler.
    PostgreSQL: at most :data:`PG_WRITERS` writers of the process at once. A writer holds one
    of the process's pooled connections while it waits for its controller's row lock; without
    a limit, writers queued on one busy controller (behind a long restore) would hold every
    connection and the process's reads would wait for one."""
    if not db.info.get(WRITER) or db.in_transaction():
        yield
        return
    bind = db.get_bind()
    # a writer queued behind one that waits for another process (a long restore) gives up
    # after as long as SQLite's own busy handler would wait, freeing its thread (503)
    if bind.dialect.name == "sqlite":
        key = str(bind.url)
        with _TURNS_LOCK:
            turn = _SQLITE_TURNS.get(key)
            if turn is None:
                turn = _SQLITE_TURNS[key] = _SqliteTurn(bind.url.database)
        with turn.held(TURN_TIMEOUT_S):
            yield
        return
    if not _PG_WRITERS.acquire(timeout=TURN_TIMEOUT_S):
        raise DatabaseBusy(TURN_TIMEOUT_S)
    try:
        yield
    finally:
        _PG_WRITERS.release()


class DatabaseBusy(Exception):
    """The database stayed locked by another writer for ``waited_s`` (a 503 on REST)."""

    def __init__(self, waited_s: float) -> None:
        super().__init__(f"the database was locked by another writer for {waited_s:g} s")
        self.waited_s = waited_s


def commit(db: Session, operation: str, **ids: int | None) -> None:
    """Commit, with the operation's audit record (``op.<operation>``, naming ``ids``:
    controller_id, session_id) when it changed rows no row hook recorded: every write leaves
    one."""
    audit.operation(db, operation, **ids)
    db.commit()


@contextlib.contextmanager
def writing(make_session: Maker, controller_id: int | None = None, *, operation: str,
            who: dict[str, Any] | None = None, **ids: int | None) -> Iterator[Session]:
    """One write, whichever face: a writer's session (:func:`writer`, ``controller_id``'s row
    locked), in this process's turn (:func:`writers_turn`), committed with the operation's audit
    record (:func:`commit`) when the block ends, rolled back if it raises. ``who`` (an
    :func:`server.auth.audit.actor`) is whom the audit names; without it, the current actor.

    ``with writing(maker, cid, operation="commit_frame", who=caller) as db: edit_slot(db, ...)``
    """
    acting = audit.acting_as(who) if who is not None else contextlib.nullcontext()
    with acting, writer(make_session, controller_id) as db, writers_turn(db):
        try:
            yield db
            commit(db, operation, controller_id=controller_id, **ids)
        except BaseException:
            db.rollback()
            raise
