"""The SQLite writers' queue: whose turn it is to take the database's write lock.

SQLite has one write lock per database file (``BEGIN IMMEDIATE``, across processes). A writer
that finds it taken polls in SQLite's busy handler (sleeps of 1, 2, 5, ... 100 ms), which is
most of a p99 under load. So the writers of one database queue for it instead, and the next
goes as soon as the holder lets go:

- **in the process**, a first-come first-served hand-over: the holder hands its turn straight
  to the next waiter, a thread (woken through its own lock) or an event-loop task (woken
  through its future, without a thread);
- **across the processes of a host**, an exclusive ``flock`` on ``<db>.writer.lock``, taken at
  the start of each turn and let go at its end. Keeping it for a run of a process's writers
  (fewer hand-overs between processes) was slower: a process's writers run one after another
  on its event loop, so the other process idled meanwhile (4 turns in a row: 290-446 req/s of
  touch-ups against 474-858 for one, ``benchmarks/README.md``).

The queue orders writers and protects nothing: the data stays guarded by ``BEGIN IMMEDIATE``,
so a writer that does not queue (a job worker, the CLI) is still correct, it only polls. The
kernel drops a ``flock`` with the process that held it (kill -9 included).
"""

from __future__ import annotations

import asyncio
import contextvars
import fcntl
import functools
import os
import threading
import weakref
from collections import deque
from collections.abc import Callable
from typing import Any

from sqlalchemy import Engine


class WriterQueue:
    """The writers of one SQLite database in this process (see the module's docstring)."""

    def __init__(self, path: str | None) -> None:
        self.path = path
        self._mutex = threading.Lock()  # guards the fields below, held for microseconds
        self._held = False  # a writer of this process has the turn
        self._waiters: deque[Any] = deque()  # threading.Lock or (loop, future), first first
        self._flocked = False  # the turn's holder has the flock (only the holder changes it)
        self._fd: int | None = None

    # ---------------------------------------------------------------- the turn in the process
    def _enter(self, waiter: Any) -> bool:
        """Take the turn if it is free (True), else queue ``waiter`` (False)."""
        with self._mutex:
            if not self._held:
                self._held = True
                return True
            self._waiters.append(waiter)
            return False

    def _leave(self, waiter: Any) -> None:
        """A waiter that stops waiting (interrupted, cancelled): out of the queue, or, if the
        turn was handed to it meanwhile, the turn passed on."""
        with self._mutex:
            queued = waiter in self._waiters
            if queued:
                self._waiters.remove(waiter)
        if not queued:
            self.release()

    def release(self) -> None:
        """End the holder's turn (the flock is let go): hand it to the next waiter of this
        process, or free it."""
        with self._mutex:
            if self._flocked:
                fcntl.flock(self._fd, fcntl.LOCK_UN)  # type: ignore[arg-type]
                self._flocked = False
            nxt = self._waiters.popleft() if self._waiters else None
            if nxt is None:
                self._held = False
                return
        if not isinstance(nxt, tuple):
            nxt.release()
            return
        loop, future = nxt
        try:
            if asyncio._get_running_loop() is loop:
                loop.call_soon(_wake, future)
            else:
                loop.call_soon_threadsafe(_wake, future)
        except RuntimeError:  # its loop is closed: pass the turn on
            self.release()

    # ---------------------------------------------------------------- the flock of the host
    def _fileno(self) -> int:
        if self._fd is None:
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o600)  # type: ignore[arg-type]
        return self._fd

    def _flock(self, wait: bool = True) -> bool:
        """Take the host's flock (the turn's holder only): waiting for it, or not (False if
        another process has it)."""
        if self.path is None or self._flocked:
            return True
        try:
            fcntl.flock(self._fileno(), fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        self._flocked = True
        return True

    # ---------------------------------------------------------------- taking a turn
    def acquire(self) -> None:
        """Wait for the turn in this thread."""
        waiter = threading.Lock()
        waiter.acquire()
        if not self._enter(waiter):
            try:
                waiter.acquire()  # released by the holder: the turn is ours
            except BaseException:  # interrupted (a signal handler raising)
                self._leave(waiter)
                raise
        try:
            self._flock()
        except BaseException:
            self.release()
            raise

    async def acquire_async(self) -> None:
        """Wait for the turn on the event loop: behind this process's writers as a future (no
        thread), for another process's flock in a thread."""
        loop = asyncio.get_running_loop()
        future = loop.create_future()
        if not self._enter((loop, future)):
            try:
                await future
            except asyncio.CancelledError:
                self._leave((loop, future))
                raise
        try:
            flocked_now = self._flock(wait=False)
        except BaseException:
            self.release()
            raise
        if flocked_now:
            return
        flocked = loop.run_in_executor(None, self._flock)  # not abandoned if we are cancelled
        try:
            await asyncio.shield(flocked)
        except BaseException:
            if flocked.done():
                self.release()
            else:  # the thread still waits for the flock: give the turn back once it has it
                flocked.add_done_callback(lambda _: self.release())
            raise


class Batch:
    """Writers that wait for one turn together, then run together (``server.deps.short``): the
    first writer to find no batch forming starts one, a task that takes the turn while the
    writers that come meanwhile join, runs them (:meth:`_run`) and lets the turn go. What
    the turn is and how the writers run is the subclass's (``db.batch``)."""

    def __init__(self) -> None:
        self._jobs: deque[tuple[Callable[..., Any], asyncio.Future]] = deque()
        self._leader: asyncio.Task | None = None

    async def run(self, job: Callable[..., Any], reads: Any = None) -> Any:
        """``job`` in the next batch, with the turn; its result. It runs in the caller's
        context (its context variables: the request's actor for the audit). ``reads``: what
        it will read, for a batch that reads ahead (``db.batch``: its session's id)."""
        loop = asyncio.get_running_loop()
        future = loop.create_future()
        call = functools.partial(contextvars.copy_context().run, job)
        call.reads = reads  # type: ignore[attr-defined]
        self._jobs.append((call, future))
        if self._leader is None:
            # its own context, not the first writer's (each job runs in its writer's context)
            self._leader = loop.create_task(self._lead(), context=contextvars.Context())
        return await future  # cancelled (the client left) before its batch ran: skipped

    async def _take(self) -> None:
        raise NotImplementedError

    def _give(self) -> None:
        raise NotImplementedError

    async def _run(self, jobs: deque[tuple[Callable[..., Any], asyncio.Future]]) -> None:
        """Run ``jobs`` with the turn, settling each one's future; a job left in ``jobs`` when
        this raises goes to the next batch."""
        raise NotImplementedError

    async def _lead(self) -> None:
        jobs: deque = deque()
        try:
            while self._jobs:
                await self._take()
                try:
                    jobs, self._jobs = self._jobs, deque()
                    await self._run(jobs)
                finally:
                    self._give()
                    self._jobs.extendleft(reversed(jobs))  # what a BaseException left undone
        except BaseException as exc:  # the loop is shutting down: the waiting writers fail
            for _, future in self._jobs:
                if not future.done():
                    future.set_exception(RuntimeError(f"the writers' batch ended: {exc!r}"))
            raise
        finally:
            self._leader = None


def _wake(future: asyncio.Future) -> None:
    if not future.done():  # cancelled: its task passes the turn on (acquire_async)
        future.set_result(None)


class WriterTurn:
    """One request's turn in its database's :class:`WriterQueue` (taken at most once): taken
    just before its ``BEGIN IMMEDIATE`` when set as :data:`TURN_AT_BEGIN` (so what a route
    computes before its first query does not hold up the other writers), or explicitly."""

    def __init__(self, queue: WriterQueue) -> None:
        self.queue, self.held = queue, False

    def take(self) -> None:
        if not self.held:
            self.queue.acquire()
            self.held = True

    def give(self) -> None:
        if self.held:
            self.held = False
            self.queue.release()


TURN_AT_BEGIN: contextvars.ContextVar[WriterTurn | None] = contextvars.ContextVar(
    "pendant_turn_at_begin", default=None)  # the turn of the writer running in this thread
_QUEUES: dict[str, WriterQueue] = {}
_QUEUES_LOCK = threading.Lock()


def writer_queue(engine: Engine) -> WriterQueue | None:
    """The :class:`WriterQueue` of a SQLite ``engine`` in this process (None for PostgreSQL,
    whose writers lock rows, not the database)."""
    if engine.dialect.name != "sqlite":
        return None
    path = engine.url.database
    on_disk = bool(path) and path != ":memory:" and not path.startswith("file:")
    key = os.path.abspath(path) if on_disk else f"memory:{id(engine.pool)}"
    with _QUEUES_LOCK:
        if key not in _QUEUES:
            _QUEUES[key] = WriterQueue(f"{key}.writer.lock" if on_disk else None)
        return _QUEUES[key]
