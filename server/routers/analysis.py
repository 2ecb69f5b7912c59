"""Recordings and the simulation-versus-reality analysis (``analysis-report/1``).

- ``POST /recordings``: store a ``robot-recording/1`` document (validated by
  :func:`server.recording.parse_recording`; a bad document is a 422 naming the field).
- ``GET /recordings/{recording_id}``: the stored document.
- ``POST /recordings/{recording_id}/analyze``: run :func:`solvers.analysis.analyze`, store the
  report and return it (with its ``id``).
- ``GET /analysis/{analysis_id}``: a stored report.

Storage is kept behind two functions, :func:`store` and :func:`load`, so the router does not
depend on a DB schema: they keep the documents in the app's memory (``app.state``) until the
DB grows recording/report tables; swapping them is the only change needed.
"""

from __future__ import annotations

import threading
from typing import Any

from fastapi import APIRouter, Body, Query, Request

from db.crud import NotFound
from server.recording import parse_recording
from solvers.analysis import analyze

router = APIRouter(tags=["Analysis"])

_LOCK = threading.Lock()


def store(request: Request, table: str, doc: dict[str, Any]) -> int:
    """Keep ``doc`` in ``table`` ('recordings' | 'analyses'); returns its new id (1, 2, ...)."""
    with _LOCK:
        tables = getattr(request.app.state, "analysis_store", None)
        if tables is None:
            tables = request.app.state.analysis_store = {"recordings": {}, "analyses": {}}
        rows = tables[table]
        new_id = len(rows) + 1
        rows[new_id] = doc
        return new_id


def load(request: Request, table: str, doc_id: int, loc: str) -> dict[str, Any]:
    """The document ``doc_id`` of ``table``; :class:`NotFound` (404) naming ``loc`` if absent."""
    tables = getattr(request.app.state, "analysis_store", None) or {}
    doc = tables.get(table, {}).get(doc_id)
    if doc is None:
        raise NotFound((loc,), f"no {table[:-1]} {doc_id}")
    return doc


@router.post("/recordings", status_code=201)
def create_recording(request: Request, doc: dict[str, Any] = Body(...)) -> dict[str, Any]:
    """Store a recording (``robot-recording/1``); 422 naming the field if it is not one."""
    rec = parse_recording(doc)
    rid = store(request, "recordings", doc)
    return {"id": rid, "kind": rec.kind, "n_samples": rec.n_samples, "robot": rec.robot.name}


@router.get("/recordings/{recording_id}")
def get_recording(request: Request, recording_id: int) -> dict[str, Any]:
    """The stored recording document."""
    return load(request, "recordings", recording_id, "recording_id")


@router.post("/recordings/{recording_id}/analyze")
def analyze_recording(request: Request, recording_id: int,
                      folds: int = Query(5, ge=2, le=20, description="K of the K-fold cross-validation"),
                      seed: int = Query(0, description="seed of the fold assignment")) -> dict[str, Any]:
    """Compare the recording with the rigid model; returns the ``analysis-report/1`` (+ ``id``)."""
    doc = load(request, "recordings", recording_id, "recording_id")
    report = analyze(parse_recording(doc), folds=folds, seed=seed)
    report["recording_id"] = recording_id
    aid = store(request, "analyses", report)
    report["id"] = aid
    return report


@router.get("/analysis/{analysis_id}")
def get_analysis(request: Request, analysis_id: int) -> dict[str, Any]:
    """A stored analysis report."""
    return load(request, "analyses", analysis_id, "analysis_id")
