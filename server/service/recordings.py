"""Recordings and their analyses: store a ``robot-recording/1``, queue its analysis.

A recording is a stored document (``stored_document``, :func:`db.crud.store_document`); its
analysis runs off the request path, as a job (``server.jobs.kinds.run_analysis`` in a
``pendant worker`` process), so a flood of analyses queues up and never stalls jogging,
touch-ups or reads.
"""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from db import jobs
from db.crud import NotFound, exists_document, store_document
from db.models import Job
from server.formats.recording import parse_recording
from solvers.recording import RecordingData


def store_recording(db: Session, doc: dict[str, Any]) -> int:
    """Store a recording pendant made itself (a simulated measurement of a plan); its id."""
    return store_document(db, "recordings", doc)


def add_recording(db: Session, doc: dict[str, Any]) -> tuple[int, RecordingData]:
    """Store a client's recording, checked first (CalibrationError naming the field if it is
    not a ``robot-recording/1``); its id and the recording read."""
    rec = parse_recording(doc)
    return store_recording(db, doc), rec


def queue_analysis(db: Session, recording_id: int, folds: int, seed: int,
                   split: str | None = None) -> Job:
    """Queue the analysis of a stored recording (K-fold cross-validation with ``folds`` and
    ``seed``; ``split`` blocked | random, None: the analysis's default); NotFound naming
    ``recording_id`` if there is none."""
    if not exists_document(db, "recordings", recording_id):
        raise NotFound(("recording_id",), f"no recording {recording_id}")
    params: dict[str, Any] = {"recording_id": recording_id, "folds": folds, "seed": seed}
    if split is not None:
        params["split"] = split
    return jobs.enqueue(db, "analysis", params)
