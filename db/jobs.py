"""The job queue in the database: enqueue, claim, progress, cancel, finish.

A job is a row of ``job`` (:class:`db.models.Job`). The API enqueues one and answers 202;
any worker process on any host that reaches the database claims it:

- PostgreSQL: ``SELECT ... FOR UPDATE SKIP LOCKED``, so workers never wait for each other
  and never take the same job;
- SQLite: the claim runs in an immediate transaction (``BEGIN IMMEDIATE`` takes the write
  lock before the read), so two claimers cannot read the same queued row.

A running job holds a lease (``lease_until``) that its worker renews; a job whose worker died
(host lost, process killed) is claimed again once its lease has run out, at most
``MAX_ATTEMPTS`` times. Cancel is a flag on a running job (the worker kills the process that
runs it) and an immediate state change on a queued one.

Functions take a SQLAlchemy ``Session`` and commit themselves: each is one short transaction.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import or_, select, update
from sqlalchemy.orm import Session

from db.crud import MAX_ID, NotFound
from db.models import Job, utcnow
from db.session import WRITE

STATES = ("queued", "running", "done", "failed", "cancelled")
FINAL = ("done", "failed", "cancelled")
LEASE_S = 30.0  # a running job's worker renews its lease well within this
MAX_ATTEMPTS = 3  # a job whose worker died this often fails instead of being claimed again


def enqueue(db: Session, kind: str, params: dict[str, Any]) -> Job:
    """A new queued job in ``db``'s transaction (flushed: it has its id). The workers see it
    once the caller commits, with the rest of the operation that queued it: an operation that
    fails after queueing a job queues nothing."""
    job = Job(kind=kind, params=params, state="queued", progress=0.0, message="queued")
    db.add(job)
    db.flush()
    return job


def get(db: Session, job_id: int) -> Job:
    """The job ``job_id``; NotFound naming ``job_id`` if there is none."""
    job = db.get(Job, job_id) if 1 <= job_id <= MAX_ID else None
    if job is None:
        raise NotFound(("job_id",), f"no job {job_id}")
    return job


def _begin_immediate(db: Session) -> None:
    """On SQLite, begin this transaction as a writer (``BEGIN IMMEDIATE``, db.session.WRITE):
    the write lock is taken before the read. A no-op on PostgreSQL and inside a transaction."""
    if not db.in_transaction():
        db.connection(execution_options=WRITE)


def claim(db: Session, worker: str, now: datetime | None = None) -> Job | None:
    """The oldest claimable job, now running under ``worker``; None if there is none.

    Claimable: queued, or running with a lease that ran out (its worker died). A job that
    has been claimed ``MAX_ATTEMPTS`` times already is failed instead (it kills workers).
    """
    now = now or utcnow()
    _begin_immediate(db)
    stmt = (select(Job)
            .where(or_(Job.state == "queued",
                       (Job.state == "running") & (Job.lease_until < now)))
            .order_by(Job.id).limit(1)
            .with_for_update(skip_locked=True))
    while True:
        job = db.scalars(stmt).first()
        if job is None:
            db.commit()
            return None
        if job.attempts >= MAX_ATTEMPTS:
            _finish(job, "failed", now, error=_error(
                500, f"its worker died {job.attempts} times (killed, or the host was lost); "
                     "not tried again"))
            continue
        job.state, job.worker, job.attempts = "running", worker, job.attempts + 1
        job.started_at, job.lease_until = now, now + timedelta(seconds=LEASE_S)
        job.message = "started"
        db.commit()
        return job


def renew(db: Session, job_ids: list[int], worker: str) -> list[int]:
    """Extend the leases of ``worker``'s running jobs; returns those whose cancel was asked."""
    if not job_ids:
        return []
    now = utcnow()
    db.execute(update(Job).where(Job.id.in_(job_ids), Job.worker == worker,
                                 Job.state == "running")
               .values(lease_until=now + timedelta(seconds=LEASE_S)))
    asked = db.scalars(select(Job.id).where(Job.id.in_(job_ids),
                                            Job.cancel_requested.is_(True))).all()
    db.commit()
    return list(asked)


def report_progress(db: Session, job_id: int, worker: str, progress: float, message: str) -> None:
    """Record how far the job is (0..1) and what it is doing."""
    db.execute(update(Job).where(Job.id == job_id, Job.worker == worker, Job.state == "running")
               .values(progress=max(0.0, min(1.0, progress)), message=message[:200]))
    db.commit()


def _error(status: int, msg: str, loc: tuple = (), kind: str = "job") -> dict[str, Any]:
    return {"status": status, "detail": [{"loc": list(loc), "msg": msg, "type": kind}]}


def _finish(job: Job, state: str, now: datetime, result: dict[str, Any] | None = None,
            error: dict[str, Any] | None = None) -> None:
    job.state, job.finished_at, job.lease_until = state, now, None
    job.result, job.error = result, error
    if state == "done":
        job.progress, job.message = 1.0, "done"
    elif state == "cancelled":
        job.message = "cancelled"
    else:
        job.message = (error or {}).get("detail", [{}])[0].get("msg", "failed")[:200]


def finish(db: Session, job_id: int, worker: str, state: str,
           result: dict[str, Any] | None = None, error: dict[str, Any] | None = None) -> bool:
    """End ``worker``'s running job as ``state``; False if it is no longer that worker's.

    The caller's own writes (e.g. the stored analysis report) go in the same transaction:
    the job is done exactly when its result is stored. Outside such a transaction it begins
    as a writer: a deferred one that read the job and then found another writer's commit (the
    supervisor renewing leases) would fail its UPDATE at once with "database is locked" (WAL:
    a read snapshot cannot become a write), SQLite's busy timeout unused.
    """
    assert state in FINAL, state
    _begin_immediate(db)
    job = db.scalars(select(Job).where(Job.id == job_id).with_for_update()).first()
    if job is None or job.state != "running" or job.worker != worker:
        db.rollback()
        return False
    _finish(job, state, utcnow(), result, error)
    db.commit()
    return True


def fail(db: Session, job_id: int, worker: str, status: int, msg: str, loc: tuple = (),
         kind: str = "job") -> bool:
    """End the job as failed with ``{"status", "detail": [{"loc", "msg", "type"}]}``."""
    return finish(db, job_id, worker, "failed", error=_error(status, msg, loc, kind))


def cancel(db: Session, job_id: int) -> Job:
    """Cancel a job: a queued one at once, a running one by asking its worker (which kills the
    process running it). A finished job stays as it is. In ``db``'s transaction: the caller
    commits (with its audit record)."""
    if not 1 <= job_id <= MAX_ID:
        raise NotFound(("job_id",), f"no job {job_id}")
    _begin_immediate(db)
    job = db.scalars(select(Job).where(Job.id == job_id).with_for_update()).first()
    if job is None:
        raise NotFound(("job_id",), f"no job {job_id}")
    if job.state == "queued":
        _finish(job, "cancelled", utcnow())
    elif job.state == "running":
        job.cancel_requested = True
        job.message = "cancel requested"
    db.flush()  # committed by the caller, with its audit record
    return job




def release(db: Session, job_ids: list[int], worker: str) -> None:
    """Put ``worker``'s running jobs back in the queue (the worker is shutting down)."""
    db.execute(update(Job).where(Job.id.in_(job_ids), Job.worker == worker, Job.state == "running")
               .values(state="queued", worker=None, lease_until=None, message="requeued",
                       attempts=Job.attempts - 1))
    db.commit()
