"""Jobs: heavy work the service answers with 202 and runs in its worker processes.

- ``GET /jobs/{job_id}``: state (queued, running, done, failed, cancelled), progress (0..1),
  message, and when done the result with a link to it (``links.result``); when failed the
  error as the request would have answered it (``error.status``, ``error.detail``).
- ``POST /jobs/{job_id}/cancel``: a queued job is cancelled at once; a running one as soon as
  its worker sees the request (it kills the process running it, within a second).

Routes that start a job answer :func:`accepted`: 202, ``Location: /jobs/{id}`` and the job.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any, Literal

from fastapi import APIRouter, Request, Response
from pydantic import BaseModel, ConfigDict

from db import jobs
from db.models import Job
from server.api.deps import SessionDep
from server.auth.guard import require
from server.service import jobs as job_service

router = APIRouter(prefix="/jobs", tags=["Jobs"])

# what cancelling a job needs beyond the route's sessions:run: what starting it needed
CANCEL_NEEDS = {"restore": "backup:restore"}
RESULT_LINKS = {
    "analysis": lambda job: f"/analysis/{job.result['analysis_id']}",
    "restore": lambda job: f"/controllers/{job.params['controller_id']}",
}


class JobLinks(BaseModel):
    model_config = ConfigDict(extra="forbid")
    self: str
    cancel: str
    result: str | None = None


class JobOut(BaseModel):
    """A job as the API shows it (its parameters stay inside: a restore's can be megabytes)."""

    model_config = ConfigDict(extra="forbid")
    id: int
    kind: str
    state: Literal["queued", "running", "done", "failed", "cancelled"]
    progress: float
    message: str
    result: dict[str, Any] | None = None
    error: dict[str, Any] | None = None
    created_at: datetime
    started_at: datetime | None = None
    finished_at: datetime | None = None
    links: JobLinks

    @classmethod
    def of(cls, job: Job) -> JobOut:
        result_link = None
        if job.state == "done" and job.kind in RESULT_LINKS:
            result_link = RESULT_LINKS[job.kind](job)
        links = JobLinks(self=f"/jobs/{job.id}", cancel=f"/jobs/{job.id}/cancel",
                         result=result_link)
        return cls(id=job.id, kind=job.kind, state=job.state, progress=job.progress,
                   message=job.message, result=job.result, error=job.error,
                   created_at=job.created_at, started_at=job.started_at,
                   finished_at=job.finished_at, links=links)


def accepted(response: Response, job: Job) -> JobOut:
    """The answer of a route that queued ``job``: 202 with ``Location`` (set the route's
    ``status_code=202``)."""
    response.headers["Location"] = f"/jobs/{job.id}"
    return JobOut.of(job)


@router.get("/{job_id}")
def get_job(job_id: int, db: SessionDep) -> JobOut:
    """A job's state, progress and, when done, its result and the link to it."""
    return JobOut.of(jobs.get(db, job_id))


@router.post("/{job_id}/cancel")
def cancel_job(job_id: int, db: SessionDep, request: Request) -> JobOut:
    """Cancel a job: at once if queued, within a second if running; a finished job stays.
    A restore's job needs ``backup:restore``, as starting it did."""
    need = CANCEL_NEEDS.get(jobs.get(db, job_id).kind)
    if need is not None:
        require(request, need)
    return JobOut.of(job_service.cancel_job(db, job_id))
