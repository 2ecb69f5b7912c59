"""How a write runs, whichever face: one writer's transaction, the controller locked, audited.

Every operation that changes rows runs in one transaction that

- is a **writer's** from its first statement (:func:`writer`): SQLite ``BEGIN IMMEDIATE``
  (the database's write lock, across processes, waited for in SQLite's busy handler,
  ``db.session``); on PostgreSQL its ``BEGIN`` is followed at once by ``SELECT ... FOR
  UPDATE`` of the controller's row (:func:`_lock_at_begin`), so every read-modify-write of one
  controller runs after the previous one committed;
- on SQLite, takes this process's **turn** (:func:`writers_turn`): SQLite has one writer at a
  time anyway, and a thread that loses ``BEGIN IMMEDIATE`` to a thread of its own process
  would otherwise wait in SQLite's busy handler, which sleeps 1, 2, 5, 10 ... up to 100 ms
  between tries; on the turn it runs as soon as the other commits. Writers of other processes
  (a second worker, the CLI, a job) still meet in the busy handler. On PostgreSQL the same
  function lets at most :data:`PG_WRITERS` writers of a process at a time hold a connection;
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


_SQLITE_TURNS: dict[str, threading.Lock] = {}  # database URL -> its writers' turn, per process
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

    SQLite: one writer of the process at a time (the database has one writer anyway).
    PostgreSQL: at most :data:`PG_WRITERS` writers of the process at once. A writer holds one
    of the process's pooled connections while it waits for its controller's row lock; without
    a limit, writers queued on one busy controller (behind a long restore) would hold every
    connection and the process's reads would wait for one."""
    if not db.info.get(WRITER) or db.in_transaction():
        yield
        return
    bind = db.get_bind()
    if bind.dialect.name == "sqlite":
        key = str(bind.url)
        with _TURNS_LOCK:
            turn = _SQLITE_TURNS.setdefault(key, threading.Lock())
    else:
        turn = _PG_WRITERS
    # as long as SQLite's own busy handler waits: a writer queued behind one that waits for
    # another process (a long restore) gives up as SQLite would, freeing its thread
    if not turn.acquire(timeout=TURN_TIMEOUT_S):
        raise DatabaseBusy(TURN_TIMEOUT_S)
    try:
        yield
    finally:
        turn.release()


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
