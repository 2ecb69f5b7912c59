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
  processes, whose waiter the kernel wakes as soon as the holder lets go; a writer gives up
  after :data:`TURN_TIMEOUT_S` (a 503), as long as SQLite's busy handler waits. On PostgreSQL the
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
import logging
import os
import threading
import time
from collections.abc import Iterator
from typing import Any

from sqlalchemy import event
from sqlalchemy.exc import OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeout
from sqlalchemy.orm import Session, sessionmaker

from db import crud
from db import session as db_session
from db.session import BUSY_TIMEOUT_MS, PG_POOL_SIZE, write_session
from server.auth import audit

LOCK_ON_BEGIN = "pendant_lock_controller"  # Session.info: the controller to lock at BEGIN
WRITER = "pendant_writer"  # Session.info: a writer's session (BEGIN IMMEDIATE)

Maker = sessionmaker[Session]
log = logging.getLogger("pendant.transaction")


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
    ``flock`` of ``<database>-writers`` among processes (none for an in-memory database, nor
    where the file cannot be made: then writers of other processes meet in SQLite's busy
    handler, as before).

    Each turn opens the file anew: an ``flock`` belongs to an open file description, so
    neither a descriptor inherited across ``fork`` nor a wait given up (below) can hold or
    release another turn's lock. A turn that finds the file locked waits in the kernel, which
    wakes it as soon as the holder is done; after ``timeout_s`` in all it gives up with
    :class:`DatabaseBusy` (a 503), and the waiting thread it leaves behind releases the lock
    the moment it gets it. The file is opened for reading only (``flock`` needs no more), so
    one made by a ``pendant`` command run as root does not lock the service out of it."""

    def __init__(self, database: str | None) -> None:
        self.path = (os.path.abspath(f"{database}-writers") if database
                     and database != ":memory:" and not database.startswith("file:") else None)
        self.threads = threading.Lock()

    def _open(self) -> int | None:
        """A new descriptor of the lock file, None if it cannot be had (logged once)."""
        assert self.path is not None
        try:
            fd = os.open(self.path, os.O_RDONLY | os.O_CREAT | os.O_CLOEXEC, 0o644)
            _LOCK_FDS.add(fd)
            return fd
        except OSError as err:
            if self.path not in _UNLOCKABLE:
                _UNLOCKABLE.add(self.path)
                log.warning("writers of other processes take turns in SQLite's busy handler: "
                            "cannot open %s (%s)", self.path, err.strerror)
            return None

    @staticmethod
    def _lock(fd: int, timeout_s: float) -> bool:
        """True once ``fd`` is locked, within ``timeout_s``; False if not, and then ``fd`` is
        closed (at once, or by the waiting thread once the lock it waits for is its)."""
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            pass
        except OSError:
            _close(fd)
            return False
        done, guard = threading.Event(), threading.Lock()
        state = {"abandoned": False, "locked": False}

        def wait() -> None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX)
                locked = True
            except OSError:
                locked = False
            with guard:
                state["locked"] = locked
                if state["abandoned"]:
                    _close(fd)  # and the lock it just got with it
                    return
                done.set()

        threading.Thread(target=wait, name="writers-turn-wait", daemon=True).start()
        done.wait(timeout_s)
        with guard:
            if not done.is_set():
                state["abandoned"] = True
                return False
        if not state["locked"]:
            _close(fd)
        return bool(state["locked"])

    @contextlib.contextmanager
    def held(self, timeout_s: float) -> Iterator[None]:
        deadline = time.monotonic() + timeout_s
        if not self.threads.acquire(timeout=timeout_s):
            raise DatabaseBusy(timeout_s)
        try:
            fd = None if self.path is None else self._open()
            if fd is None:
                yield
                return
            if not self._lock(fd, max(0.0, deadline - time.monotonic())):
                raise DatabaseBusy(timeout_s)
            try:
                yield
            finally:
                _close(fd)  # and with it the lock
        finally:
            self.threads.release()


_UNLOCKABLE: set[str] = set()  # lock files that could not be opened (warned once each)
_LOCK_FDS: set[int] = set()  # this process's open descriptors of lock files


def _close(fd: int) -> None:
    _LOCK_FDS.discard(fd)
    os.close(fd)


def _after_fork_in_child() -> None:
    """A forked child (a job's process) starts with no turn: its copies of the parent's lock
    descriptors would keep a lock the parent lets go held for as long as the child runs, and
    a thread lock the parent held at the fork would stay held for good."""
    for fd in list(_LOCK_FDS):
        _LOCK_FDS.discard(fd)
        try:
            os.close(fd)
        except OSError:
            pass
    global _TURNS_LOCK
    _TURNS_LOCK = threading.Lock()
    for turn in _SQLITE_TURNS.values():
        turn.threads = threading.Lock()


_SQLITE_TURNS: dict[str, _SqliteTurn] = {}  # database URL -> its writers' turn
_TURNS_LOCK = threading.Lock()
os.register_at_fork(after_in_child=_after_fork_in_child)
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


LOST = ("the connection to the database was lost during this request (a restart or "
        "failover); a write it was committing may or may not have been: read before writing "
        "again")


def unavailable(exc: BaseException) -> str | None:
    """Why the database could not serve the request that raised ``exc``, said for the person
    who retries it (a 503 with ``Retry-After`` on REST and RWS, a refusal on KVP, the
    connection kept), or None when ``exc`` is not about the database's availability:

    - another writer held the database past :data:`TURN_TIMEOUT_S` (:class:`DatabaseBusy`)
      or SQLite's busy timeout ("database is locked");
    - every pooled connection of the process stayed busy (the pool's timeout), or PostgreSQL
      has no connection left (its ``max_connections``);
    - no connection could be made (PostgreSQL down, starting up or shutting down: the error
      carries no statement);
    - the connection was lost during the request (a restart or failover): a write being
      committed then may or may not have been, and the answer says so (:data:`LOST`).
    """
    if isinstance(exc, DatabaseBusy):
        return f"{exc}; nothing was written: retry"
    if isinstance(exc, PoolTimeout):
        return (f"every database connection of this process stayed busy for "
                f"{db_session.POOL_TIMEOUT_S:g} s; nothing was written: retry")
    if not isinstance(exc, OperationalError):
        return None
    if exc.connection_invalidated:
        return LOST
    if exc.statement is None:  # no connection to begin with: PostgreSQL down, starting up
        reason = str(exc.orig).strip().splitlines()[0] if exc.orig is not None else ""
        return f"the database cannot be reached now ({reason}); nothing was written: retry"
    if "database is locked" in str(exc.orig):  # SQLite's busy timeout ran out
        return (f"the database was locked by another writer for "
                f"{db_session.BUSY_TIMEOUT_MS / 1000:g} s; nothing was written: retry")
    if any(m in str(exc.orig) for m in ("too many clients",  # max_connections reached
                                        "remaining connection slots are reserved")):
        return "the database has no connection free (its max_connections); nothing was " \
               "written: retry"
    return None


def retry_reason(exc: BaseException) -> str:
    """:func:`unavailable`'s reason for ``exc``, for a face's ``except Exception`` that answers
    it with its protocol's "retry"; anything else is raised again, as it was."""
    why = unavailable(exc)
    if why is None:
        raise exc
    return why


def commit(db: Session, operation: str, **ids: int | None) -> None:
    """Commit, with the operation's audit record (``op.<operation>``, naming ``ids``:
    controller_id, session_id) when it changed rows no row hook recorded: every write leaves
    one."""
    audit.operation(db, operation, **ids)
    db.commit()


@contextlib.contextmanager
def writer_in_turn(make_session: Maker, controller_id: int | None = None) -> Iterator[Session]:
    """A writer's session (:func:`writer`) in the writers' turn (:func:`writers_turn`); the
    caller commits. :func:`writing` adds the operation's audit record; the writes that are no
    operation (a job's claim and lease, an Idempotency-Key's stored answer, a browser login's
    last command) use this alone."""
    with writer(make_session, controller_id) as db, writers_turn(db):
        yield db


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
    with acting, writer_in_turn(make_session, controller_id) as db:
        try:
            yield db
            commit(db, operation, controller_id=controller_id, **ids)
        except BaseException:
            db.rollback()
            raise
