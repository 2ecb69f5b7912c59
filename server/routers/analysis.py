"""Recordings and the simulation-versus-reality analysis (``analysis-report/1``).

- ``POST /recordings``: store a ``robot-recording/1`` document (validated by
  :func:`server.recording.parse_recording`; a bad document is a 422 naming the field).
- ``GET /recordings/{recording_id}``: the stored document.
- ``POST /recordings/{recording_id}/analyze``: run :func:`solvers.analysis.analyze`, store the
  report and return it (with its ``id``).
- ``GET /analysis/{analysis_id}``: a stored report (with its ``id``).

Documents live in the database (``stored_document``, :func:`db.crud.store_document` /
:func:`db.crud.load_document`), so they survive a restart. ``analyze`` holds no transaction
while it computes (up to a second for a large recording, and jogging or a touch-up must not
wait for it): it reads the recording in one short session, analyses outside any session, and
stores the report in a second short writing session.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, Query, Request
from starlette.concurrency import run_in_threadpool

from db.crud import load_document, store_document
from db.session import write_session
from server.deps import SessionDep
from server.recording import parse_recording
from solvers.analysis import analyze

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


def _read(request: Request, collection: str, doc_id: int, loc: str) -> dict[str, Any]:
    with request.app.state.sessionmaker() as db:
        return load_document(db, collection, doc_id, loc)


def _write(request: Request, collection: str, doc: dict[str, Any]) -> int:
    db = write_session(request.app.state.sessionmaker)
    try:
        new_id = store_document(db, collection, doc)
        db.commit()
        return new_id
    except BaseException:
        db.rollback()
        raise
    finally:
        db.close()


@router.post("/recordings/{recording_id}/analyze")
async def analyze_recording(request: Request, recording_id: int,
                            folds: int = Query(5, ge=2, le=20,
                                               description="K of the K-fold cross-validation"),
                            seed: int = Query(0, ge=0, le=2**32 - 1,
                                              description="seed of the fold assignment")
                            ) -> dict[str, Any]:
    """Compare the recording with the rigid model; returns the ``analysis-report/1`` (+ ``id``)."""
    doc = await run_in_threadpool(_read, request, "recordings", recording_id, "recording_id")
    report = await run_in_threadpool(lambda: analyze(parse_recording(doc), folds=folds, seed=seed))
    report["recording_id"] = recording_id
    async with request.app.state.writers:  # the writers' bulkhead (server.deps)
        report["id"] = await run_in_threadpool(_write, request, "analyses", report)
    return report


@router.get("/analysis/{analysis_id}")
def get_analysis(db: SessionDep, analysis_id: int) -> dict[str, Any]:
    """A stored analysis report (as ``analyze`` returned it, with its ``id``)."""
    return {**load_document(db, "analyses", analysis_id, "analysis_id"), "id": analysis_id}
