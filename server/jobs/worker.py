"""The job workers: a bounded pool of processes that run the queued jobs (``pendant worker``).

One supervisor process per host (``pendant worker --processes N``; ``pendant serve`` starts
one with ``--job-workers``) claims jobs from the database (:mod:`db.jobs`) and runs each in a
child process of its own, at most N at a time. The child is bounded:

- memory: ``RLIMIT_AS`` (``--job-memory-mb``); a job that needs more fails with 413;
- time: the supervisor kills a child that outlives ``--job-time-s`` (the job fails, 504);
- CPU: one BLAS thread (threadpoolctl) and a nice level of 15, so N workers side by side do
  not oversubscribe the cores and the request path keeps its priority.

The supervisor renews the leases of its running jobs, kills the child of a job whose cancel
was asked, and fails a job whose child died without an answer (naming the signal). Several
supervisors on several hosts share one PostgreSQL queue (``SKIP LOCKED``).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
import socket
import time
from dataclasses import dataclass, field
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from db import jobs
from db.crud import NotFound, StateConflict
from db.session import make_engine, make_sessionmaker
from server.service import transaction

log = logging.getLogger("pendant.worker")

DEFAULT_TIME_S = 600.0
DEFAULT_MEMORY_MB = 2048
NICE = 15  # a job gets ~4 % of a core the request path wants (CFS weights 36 vs 1024)
RENEW_S = 0.5  # lease renewal and the cancel check of running jobs
MEMORY_EXIT = 3  # a job process's exit code: out of memory, too short of it to say so itself


@dataclass(frozen=True)
class Limits:
    """Per-job bounds: wall time (s) and address space (MB)."""

    time_s: float = DEFAULT_TIME_S
    memory_mb: int = DEFAULT_MEMORY_MB


def _memory_limit_error() -> dict[str, Any]:
    return jobs._error(413, "the job needed more memory than its limit allows; split the "
                            "recording or raise --job-memory-mb", (), "memory_limit")


def out_of_memory(exc: BaseException) -> bool:
    """``exc`` is the memory cap: a MemoryError, or SQLite's "out of memory" (SQLITE_NOMEM,
    e.g. while it opens the database under a low ``--job-memory-mb``), also when SQLAlchemy
    wraps it."""
    import sqlite3

    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, MemoryError):
            return True
        if isinstance(seen, sqlite3.Error) and "out of memory" in str(seen).lower():
            return True
        seen = getattr(seen, "orig", None) or seen.__cause__ or seen.__context__
    return False


def _error_of(exc: BaseException) -> dict[str, Any]:
    """The ``{"status", "detail"}`` a route would have answered for ``exc``."""
    if out_of_memory(exc):  # before the imports: at the cap they can fail themselves
        return _memory_limit_error()
    from server.api.errors import body_loc
    from solvers.errors import CalibrationError, KinematicsError

    if isinstance(exc, CalibrationError):
        kind = "kinematics" if isinstance(exc, KinematicsError) else "calibration"
        return jobs._error(422, exc.reason, body_loc(exc.loc), kind)
    if isinstance(exc, NotFound):
        return jobs._error(404, exc.reason, ("path", *exc.loc), "not_found")
    if isinstance(exc, StateConflict):
        return jobs._error(409, exc.reason, exc.loc, "conflict")
    return jobs._error(500, f"internal error ({type(exc).__name__}); see the worker log", (),
                       "internal")


# the job machinery's writes (claim, progress, lease, the result, the end) take the writers'
# turn as every write does: in SQLite's busy handler alone, a job worker's write could wait out
# the busy timeout behind a busy service's writers
job_write = transaction.writer_in_turn


def run_job(sm: sessionmaker[Session], job_id: int, kind: str, params: dict[str, Any],
            worker: str) -> str:
    """Run one claimed job to its end in this process; returns the final state.

    The kind's ``apply`` and the job's "done" are one transaction (nothing half-stored).
    """
    from server.jobs.kinds import KINDS

    def progress(fraction: float, message: str) -> None:
        with job_write(sm) as db:
            jobs.report_progress(db, job_id, worker, fraction, message)

    try:
        if kind not in KINDS:
            raise ValueError(f"unknown job kind {kind!r}")
        apply = KINDS[kind](sm, params, progress)
        with job_write(sm) as db:  # BEGIN IMMEDIATE on SQLite: the writer's transaction
            result = apply(db)
            if jobs.finish(db, job_id, worker, "done", result=result):
                return "done"
            return "lost"  # cancelled or re-claimed meanwhile: its writes were rolled back
    except Exception as exc:  # noqa: BLE001 - every failure becomes the job's error
        if not out_of_memory(exc) and _error_of(exc)["status"] == 500:
            log.exception("job %s (%s) failed", job_id, kind)
        exc.__traceback__ = None  # its frames hold the job's data: free it before reporting
        with job_write(sm) as db:
            jobs.finish(db, job_id, worker, "failed", error=_error_of(exc))
        return "failed"


def drain(sm: sessionmaker[Session], worker: str = "inline") -> int:
    """Run every queued job in this process, one after the other; returns how many ran.

    No limits, no child process: for tests and scripts that want the queue emptied now.
    """
    n = 0
    while True:
        with job_write(sm) as db:
            job = jobs.claim(db, worker)
            if job is None:
                return n
            job_id, kind, params = job.id, job.kind, job.params
        run_job(sm, job_id, kind, params, worker)
        n += 1


def _child(db_url: str, job_id: int, kind: str, params: dict[str, Any], worker: str,
           limits: Limits) -> None:
    """Entry of a job's own process: bound it, then run the job (exit code 0 = answered)."""
    import resource

    from threadpoolctl import threadpool_limits

    code = 1
    try:
        os.nice(NICE)
        cap = int(limits.memory_mb) * 2**20
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
        threadpool_limits(limits=1)
        engine = make_engine(db_url)
        run_job(make_sessionmaker(engine), job_id, kind, params, worker)
        engine.dispose()
        code = 0
    except MemoryError:  # at the cap before the job ran, or while reporting: the supervisor says 413
        code = MEMORY_EXIT
    except BaseException as exc:  # noqa: BLE001 - the supervisor reports a child that did not answer
        if out_of_memory(exc):  # SQLite could not open the database under the cap
            code = MEMORY_EXIT
        else:
            log.exception("job %s: its process failed", job_id)
    finally:
        os._exit(code)


@dataclass
class _Running:
    job_id: int
    process: Any
    started: float
    cancel_asked: bool = False


@dataclass
class Pool:
    """The supervisor: claims jobs and runs each in a bounded child process, N at a time."""

    db_url: str
    processes: int = 2
    limits: Limits = field(default_factory=Limits)
    poll_s: float = 0.2
    name: str = field(default_factory=lambda: f"{socket.gethostname()}:{os.getpid()}")
    parent_pid: int | None = None  # stop when this process is gone (pendant serve's pool)

    def __post_init__(self) -> None:
        if self.processes < 1:
            raise ValueError("processes must be >= 1")
        self.engine = make_engine(self.db_url)
        self.sm = make_sessionmaker(self.engine)
        self.ctx = multiprocessing.get_context("fork")
        self.running: dict[int, _Running] = {}
        self.stopping = False

    # -------------------------------------------------------------------------- the loop
    def run(self) -> None:
        """Serve the queue until SIGTERM/SIGINT (or ``stop()``); then kill and requeue."""
        self._preload()
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: self.stop())
        log.info("job worker %s: %d processes, %.0f s, %d MB per job", self.name,
                 self.processes, self.limits.time_s, self.limits.memory_mb)
        last_renew = 0.0
        while not self.stopping:
            if self.parent_pid is not None and os.getppid() != self.parent_pid:
                break
            self._reap()
            now = time.monotonic()
            if self.running and now - last_renew >= RENEW_S:
                self._renew()
                last_renew = now
            self._enforce_time()
            started = self._fill()
            if not started:
                time.sleep(self.poll_s)
        self._shutdown()

    def stop(self) -> None:
        self.stopping = True

    def _preload(self) -> None:
        """Import what jobs use once, so every forked child starts warm."""
        import server.service.backup  # noqa: F401
        import server.jobs.kinds  # noqa: F401
        import server.formats.recording  # noqa: F401
        import solvers.analysis  # noqa: F401

    def _fill(self) -> bool:
        """Claim and start jobs while a process is free; True if one was started."""
        started = False
        while len(self.running) < self.processes and not self.stopping:
            with job_write(self.sm) as db:
                job = jobs.claim(db, self.name)
                if job is None:
                    break
                job_id, kind, params = job.id, job.kind, job.params
            self.engine.dispose()  # no pooled connection crosses the fork
            p = self.ctx.Process(target=_child, name=f"pendant-job-{job_id}", daemon=True,
                                 args=(self.db_url, job_id, kind, params, self.name, self.limits))
            p.start()
            self.running[job_id] = _Running(job_id, p, time.monotonic())
            started = True
        return started

    def _reap(self) -> None:
        """Forget finished children; fail the job of a child that died without answering."""
        for job_id, r in list(self.running.items()):
            if r.process.is_alive():
                continue
            r.process.join()
            del self.running[job_id]
            code = r.process.exitcode
            if r.cancel_asked:
                self._end(job_id, "cancelled")
            elif code == MEMORY_EXIT:
                self._end(job_id, "failed", _memory_limit_error())
            elif code != 0:
                why = (f"killed by signal {signal.Signals(-code).name}" if code and code < 0
                       else f"exit code {code}")
                self._end(job_id, "failed", jobs._error(
                    500, f"the job's process died ({why}); see the worker log", (), "worker"))

    def _end(self, job_id: int, state: str, error: dict[str, Any] | None = None) -> None:
        with job_write(self.sm) as db:
            jobs.finish(db, job_id, self.name, state, error=error)

    def _renew(self) -> None:
        with job_write(self.sm) as db:
            asked = jobs.renew(db, list(self.running), self.name)
        for job_id in asked:
            r = self.running.get(job_id)
            if r is not None and not r.cancel_asked:
                r.cancel_asked = True
                r.process.kill()

    def _enforce_time(self) -> None:
        now = time.monotonic()
        for job_id, r in list(self.running.items()):
            if now - r.started > self.limits.time_s and r.process.is_alive():
                r.process.kill()
                r.process.join()
                del self.running[job_id]
                self._end(job_id, "failed", jobs._error(
                    504, f"the job ran longer than its limit of {self.limits.time_s:g} s and was "
                         "stopped", (), "time_limit"))

    def _shutdown(self) -> None:
        """Kill the running children and put their jobs back in the queue for another worker."""
        for r in self.running.values():
            r.process.kill()
            r.process.join()
        if self.running:
            with job_write(self.sm) as db:
                jobs.release(db, list(self.running), self.name)
        self.running.clear()
        self.engine.dispose()
