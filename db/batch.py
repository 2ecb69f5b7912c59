"""Short writers in batches: one transaction, one lock and one commit for all that waited.

A touch-up's own work is a few tenths of a millisecond; what it cost around that was its
transaction: a thread, a pooled connection, ``BEGIN``, the lock, each statement's round trip
and the commit. Every writer of a controller takes the same lock (PostgreSQL: the
controller's row; SQLite: the database), so how many a second get through is one over the
time each holds it. So the short writers that wait together (``server.deps.short``: the
touch-up) run as a batch:

- :class:`SQLiteBatch`: the writers of the process, on its event loop, with the writers'
  turn (``db.writers.WriterQueue``), in one ``BEGIN IMMEDIATE`` transaction;
- :class:`ControllerBatch`: PostgreSQL, the writers of one controller, in one thread, in one
  transaction that locks the controller's row first.

In the batch's transaction the controller and its writers' sessions are read first, in one
round trip on PostgreSQL (``db.rows.read_locked``; the points of a session the process holds
at its current version are not read again: ``db.rows.SessionCache``). Its writers read them
from there (``db.rows.Locked``) and change them in place. Each writer's own rows (its
session, its point) are set aside as it runs; they and the controller, written once, go
together before the commit, in one round trip on PostgreSQL (``db.touch_up.write_locked``,
``db.pipeline``).

A writer that fails without having written (a 4xx: a wrong step, a stale ``If-Match``) leaves
the transaction as it was: the batch goes on. One that fails after a write rolls the whole
transaction back, and the batch runs again without it (:func:`in_one_transaction`): nothing
a failed writer wrote is committed, and no answer leaves before the commit.

A batch orders writers and guards nothing that the database's lock does not: a writer
outside it (another process, host, or route) waits for the same lock.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import anyio.to_thread
from sqlalchemy import Connection, Engine, event
from sqlalchemy.exc import OperationalError

from db import rows
from db.session import NO_WAIT_AT_BEGIN
from db.touch_up import write_locked
from db.writers import Batch, WriterQueue

Outcome = tuple[bool, Any]  # (True, result) or (False, the exception it raised)


class _Undo(Exception):
    """A writer failed after it wrote: the batch's transaction is rolled back."""


def _count_write(conn: Connection, _cursor: Any, statement: str, *_: Any) -> None:
    """``before_cursor_execute`` of every engine (SQLAlchemy 2.0.34 has no events of one
    ``Connection``): a statement that is not a read, sent in a batch, is counted there."""
    locked = conn.info.get(rows.LOCKED)
    if locked is not None and not statement.lstrip()[:6].upper().startswith("SELECT"):
        locked.written += 1


if not event.contains(Engine, "before_cursor_execute", _count_write):
    event.listen(Engine, "before_cursor_execute", _count_write)


def _written(locked: rows.Locked) -> int:
    """How many writes the batch has sent or set aside so far."""
    return locked.written + len(locked.pending)


def _one_pass(engine: Engine, controller_id: int | None,
              jobs: Sequence[Callable[[Connection], Any]], reads: Sequence[Any],
              todo: list[int], outcomes: list[Outcome | None]) -> None:
    with engine.connect() as conn:
        locked = rows.Locked()
        with conn.begin():  # committed as the block ends, rolled back if it raises
            conn.info[rows.LOCKED] = locked
            try:
                rows.read_locked(conn, controller_id, [reads[i] for i in todo] if reads else ())
                for i in todo:
                    before = _written(locked)
                    try:
                        outcomes[i] = (True, jobs[i](conn))
                    except Exception as exc:  # the writer's own error (a 4xx, a 500)
                        outcomes[i] = (False, exc)
                        if _written(locked) != before:
                            raise _Undo from exc
                write_locked(conn, locked)
            finally:
                conn.info.pop(rows.LOCKED, None)
        rows.session_cache(conn).put(locked.sessions.values())  # as committed


def in_one_transaction(engine: Engine, controller_id: int | None,
                       jobs: Sequence[Callable[[Connection], Any]],
                       reads: Sequence[Any] = ()) -> list[Outcome]:
    """Run ``jobs`` (each a function of the connection) one after another in one transaction
    of ``engine`` (that first locks controller ``controller_id``'s row, if given, then reads
    the sessions ``reads`` names, one per job or None, in one query), and commit: each one's
    outcome.

    A job that raises after it wrote rolls the transaction back; the others run again in a
    new one (each pass drops one such job, so this ends). An error of the commit itself
    raises, for every job."""
    outcomes: list[Outcome | None] = [None] * len(jobs)
    while True:
        todo = [i for i, o in enumerate(outcomes) if o is None or o[0]]
        try:
            _one_pass(engine, controller_id, jobs, reads, todo, outcomes)
        except _Undo:
            continue
        return outcomes  # type: ignore[return-value]


class OneTransaction(Batch):
    """A :class:`db.writers.Batch` whose writers (functions of the connection) run in one
    transaction (:func:`in_one_transaction`); :meth:`_outcomes` says where."""

    async def _outcomes(self, jobs: list[Callable[[Connection], Any]],
                        reads: list[Any]) -> list[Outcome]:
        raise NotImplementedError

    async def _run(self, jobs: deque[tuple[Callable[..., Any], asyncio.Future]]) -> None:
        live = [(job, future) for job, future in jobs if not future.done()]
        jobs.clear()
        try:
            outcomes = await self._outcomes([job for job, _ in live],
                                            [getattr(job, "reads", None) for job, _ in live])
        except BaseException as exc:
            for _, future in live:
                if not future.done():
                    future.set_exception(exc if isinstance(exc, Exception) else
                                         RuntimeError(f"the writers' batch ended: {exc!r}"))
            if not isinstance(exc, Exception):
                raise
            return
        for (_, future), (ok, value) in zip(live, outcomes):
            if not future.done():
                if ok:
                    future.set_result(value)
                else:
                    future.set_exception(value)


class ControllerBatch(OneTransaction):
    """PostgreSQL: the short writers of one controller in this process (see the module's
    docstring): the leader takes the controller's turn (``turn``, the ``asyncio.Lock`` its
    other writers of this process queue on) and runs the waiting writers in a thread, in one
    transaction that locks the controller's row first."""

    def __init__(self, engine: Engine, controller_id: int, turn: asyncio.Lock) -> None:
        super().__init__()
        self.engine, self.controller_id, self.turn = engine, controller_id, turn

    async def _take(self) -> None:
        await self.turn.acquire()

    def _give(self) -> None:
        self.turn.release()

    async def _outcomes(self, jobs: list[Callable[[Connection], Any]],
                        reads: list[Any]) -> list[Outcome]:
        # the thread is waited for even if this task is cancelled (anyio's default)
        return await anyio.to_thread.run_sync(in_one_transaction, self.engine,
                                              self.controller_id, jobs, reads)


IN_A_THREAD = object()  # a SQLiteBatch writer's result when SQLite's lock is held elsewhere


class SQLiteBatch(OneTransaction):
    """SQLite: the short writers of this process's event loop. The leader takes the writers'
    turn (``db.writers.WriterQueue``: first in the process, then the host's ``flock``) and
    runs them on the event loop, in one transaction of ``engine`` (a writer's:
    ``BEGIN IMMEDIATE``), so the database's lock is held for their work only.

    ``BEGIN IMMEDIATE`` does not wait there: a writer that does not queue (a job worker, the
    events dispatcher, the CLI) may hold SQLite's lock, and then each writer's result is
    :data:`IN_A_THREAD` (it runs again on its own, in a thread, where its ``BEGIN`` may
    wait), never a wait on the loop."""

    def __init__(self, queue: WriterQueue, engine: Engine) -> None:
        super().__init__()
        self.queue, self.engine = queue, engine

    async def _take(self) -> None:
        await self.queue.acquire_async()

    def _give(self) -> None:
        self.queue.release()

    async def _outcomes(self, jobs: list[Callable[[Connection], Any]],
                        reads: list[Any]) -> list[Outcome]:
        no_wait = NO_WAIT_AT_BEGIN.set(True)
        try:
            return in_one_transaction(self.engine, None, jobs, reads)
        except OperationalError as exc:
            if "locked" not in str(exc.orig):
                raise
            return [(True, IN_A_THREAD)] * len(jobs)  # nothing was committed
        finally:
            NO_WAIT_AT_BEGIN.reset(no_wait)
