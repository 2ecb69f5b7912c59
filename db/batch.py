"""PostgreSQL: the short writers of one controller, in one transaction under its row lock.

Every writer of a controller locks the controller's row (``SELECT ... FOR UPDATE``), so the
writers of one controller run one after another, across processes and hosts: how many a
second get through is one over the time each holds the lock. One touch-up on its own held it
for five of its eight round trips (pool ping, ``BEGIN``, the locked read, the session, three
writes, the commit) in a thread that had to win the GIL back from the event loop after
each one.

So the short writers of a controller (``server.deps.short``: the touch-up) that wait in this
process run as a batch (:class:`ControllerBatch`): one thread, one pooled connection, one
transaction, one row lock and one commit for all of them. The controller is read once
(:class:`db.rows.Locked`), each writer reads it from there and changes it in place, and it is
written once, before the commit (``db.touch_up.write_locked``). What each writer writes of its
own (its session, its point) it writes as it runs.

A writer that fails without having written (a 4xx: a wrong step, a stale ``If-Match``) leaves
the transaction as it was: the batch goes on. One that fails after a write rolls the whole
transaction back, and the batch runs again without it (:func:`in_one_transaction`): nothing
a failed writer wrote is committed, and no answer leaves before the commit.

It orders writers and guards nothing that the row lock does not: a writer outside the batch
(another process, host, or route) waits for the same row lock.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import anyio.to_thread
from sqlalchemy import Connection, Engine, event

from db import rows
from db.crud import NotFound
from db.touch_up import write_locked
from db.writers import Batch

Outcome = tuple[bool, Any]  # (True, result) or (False, the exception it raised)


class _Undo(Exception):
    """A writer failed after it wrote: the batch's transaction is rolled back."""


def _count_writes(conn: Connection) -> list[int]:
    """A counter of the statements ``conn`` sends that are not reads."""
    count = [0]

    def counted(_conn: Any, _cursor: Any, statement: str, *_: Any) -> None:
        if not statement.lstrip()[:6].upper().startswith("SELECT"):
            count[0] += 1

    event.listen(conn, "before_cursor_execute", counted)
    return count


def _written(writes: list[int], locked: rows.Locked | None) -> int:
    """How many writes the batch has sent or set aside so far."""
    return writes[0] + (0 if locked is None else len(locked.pending))


def _one_pass(engine: Engine, controller_id: int, jobs: Sequence[Callable[[Connection], Any]],
              todo: list[int], outcomes: list[Outcome | None]) -> None:
    with engine.connect() as conn:
        writes = _count_writes(conn)
        with conn.begin():  # committed as the block ends, rolled back if it raises
            try:
                locked = rows.Locked(rows.controller(conn, controller_id, lock=True))
            except NotFound:
                locked = None  # each writer says so itself
            conn.info[rows.LOCKED] = locked
            try:
                for i in todo:
                    before = _written(writes, locked)
                    try:
                        outcomes[i] = (True, jobs[i](conn))
                    except Exception as exc:  # the writer's own error (a 4xx, a 500)
                        outcomes[i] = (False, exc)
                        if _written(writes, locked) != before:
                            raise _Undo from exc
                if locked is not None:
                    write_locked(conn, locked)
            finally:
                conn.info.pop(rows.LOCKED, None)


def in_one_transaction(engine: Engine, controller_id: int,
                       jobs: Sequence[Callable[[Connection], Any]]) -> list[Outcome]:
    """Run ``jobs`` (each a function of the connection) one after another in one transaction
    that first locks controller ``controller_id``'s row, and commit: each one's outcome.

    A job that raises after it wrote rolls the transaction back; the others run again in a
    new one (each pass drops one such job, so this ends). An error of the commit itself
    raises, for every job."""
    outcomes: list[Outcome | None] = [None] * len(jobs)
    while True:
        todo = [i for i, o in enumerate(outcomes) if o is None or o[0]]
        try:
            _one_pass(engine, controller_id, jobs, todo, outcomes)
        except _Undo:
            continue
        return outcomes  # type: ignore[return-value]


class ControllerBatch(Batch):
    """The short writers of one controller in this process (see the module's docstring): the
    leader takes the controller's turn (``turn``, the ``asyncio.Lock`` its other writers of
    this process queue on), runs the waiting writers in a thread with
    :func:`in_one_transaction`, and settles their futures after the commit."""

    def __init__(self, engine: Engine, controller_id: int, turn: asyncio.Lock) -> None:
        super().__init__()
        self.engine, self.controller_id, self.turn = engine, controller_id, turn

    async def _take(self) -> None:
        await self.turn.acquire()

    def _give(self) -> None:
        self.turn.release()

    async def _run(self, jobs: deque[tuple[Callable[..., Any], asyncio.Future]]) -> None:
        live = [(job, future) for job, future in jobs if not future.done()]
        jobs.clear()
        try:  # the thread is waited for even if this task is cancelled (anyio's default)
            outcomes = await anyio.to_thread.run_sync(
                in_one_transaction, self.engine, self.controller_id, [job for job, _ in live])
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
