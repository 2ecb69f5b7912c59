"""Jobs: cancel one (the heavy work the service answers 202 to and runs in its workers).

A job is queued by the operation that needs it (:func:`server.service.recordings.queue_analysis`,
:func:`server.service.backup.restore_later`); the queue itself, its claims and its own
transactions are :mod:`db.jobs`.
"""

from __future__ import annotations

from sqlalchemy.orm import Session

from db import jobs
from db.models import Job


def cancel_job(db: Session, job_id: int) -> Job:
    """Cancel a job: a queued one at once, a running one by asking its worker (which kills the
    process running it, within a second). A finished job stays as it is."""
    return jobs.cancel(db, job_id)
