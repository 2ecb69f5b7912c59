"""Recordings and the simulation-versus-reality analysis (``analysis-report/1``).

- ``POST /recordings``: store a ``robot-recording/1`` document (validated by
  :func:`server.recording.parse_recording`; a bad document is a 422 naming the field).
- ``GET /recordings/{recording_id}``: the stored document.
- ``POST /recordings/{recording_id}/analyze``: queue a job (202, ``Location: /jobs/{id}``)
  that runs :func:`solvers.analysis.analyze` in a worker process and stores the report.
- ``GET /analysis/{analysis_id}``: a stored report (with its ``id``).

Documents live in the database (``stored_document``, :func:`db.crud.store_document` /
:func:`db.crud.load_document`), so they survive a restart. The analysis runs off the request path
(``server.job_kinds.run_analysis`` in a ``pendant worker`` process, bounded in time and
memory): a flood of analyses queues up and never stalls jogging, touch-ups or reads.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, Query, Response

from db import jobs
from db.crud import NotFound, exists_document, load_document, store_document
from server.deps import SessionDep
from server.recording import parse_recording
from server.routers.jobs import JobOut, accepted

router = APIRouter(tags=["Analysis"])


@router.post("/recordings", status_code=201)
def create_recording(db: SessionDep, doc: dict[str, Any] = Body(...)) -> dict[str, Any]:
    """Store a recording (``robot-recording/1``); 422 naming the field if it is not one."""
    rec = parse_recording(doc)
    rid = store_document(db, "recordings", doc)
    return {"id": rid, "kind": rec.kind, "n_samples": rec.n_samples, "robot": rec.robot.name}


@router.get("/recordings/{recording_id}")
def get_recording(db: SessionDep, recording_id: int) -> dict[str, Any]:
    """The stored recording document."""
    return load_document(db, "recordings", recording_id, "recording_id")


@router.post("/recordings/{recording_id}/analyze", status_code=202)
def analyze_recording(response: Response, db: SessionDep, recording_id: int,
                      folds: int = Query(5, ge=2, le=20,
                                         description="K of the K-fold cross-validation"),
                      seed: int = Query(0, ge=0, le=2**32 - 1,
                                        description="seed of the fold assignment")) -> JobOut:
    """Queue the analysis of the recording (a job): 202 and ``Location: /jobs/{id}``.

    The job's result is ``{"analysis_id": N}`` and ``links.result`` is ``/analysis/N``, the
    ``analysis-report/1``. A recording the analysis cannot use fails the job with the 422 the
    analysis gives (``error.status``, ``error.detail``)."""
    if not exists_document(db, "recordings", recording_id):
        raise NotFound(("recording_id",), f"no recording {recording_id}")
    job = jobs.enqueue(db, "analysis", {"recording_id": recording_id, "folds": folds,
                                        "seed": seed})
    return accepted(response, job)


@router.get("/analysis/{analysis_id}")
def get_analysis(db: SessionDep, analysis_id: int) -> dict[str, Any]:
    """A stored analysis report (as ``analyze`` returned it, with its ``id``)."""
    return {**load_document(db, "analyses", analysis_id, "analysis_id"), "id": analysis_id}
