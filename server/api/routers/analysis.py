"""Recordings and the simulation-versus-reality analysis (``analysis-report/1``).

- ``POST /recordings``: store a ``robot-recording/1`` document (validated by
  :func:`server.formats.recording.parse_recording`; a bad document is a 422 naming the field).
- ``GET /recordings/{recording_id}``: the stored document.
- ``POST /recordings/{recording_id}/analyze``: queue a job (202, ``Location: /jobs/{id}``)
  that runs :func:`solvers.analysis.analyze` in a worker process and stores the report.
- ``GET /analysis/{analysis_id}``: a stored report (with its ``id``).
- ``GET /analysis/{analysis_id}/model``: the report's fitted ``robot-model/1`` (a download).
- ``POST /predict``: ``{"model", "recording", "refit_setup"}`` -> ``prediction/1``
  (:func:`solvers.analysis.model.predict`; ``pendant predict``).

Documents live in the database (``stored_document``: :mod:`server.service.recordings` stores
them, :func:`db.crud.load_document` reads them), so they survive a restart. The analysis runs
off the request path (``server.jobs.kinds.run_analysis`` in a ``pendant worker`` process,
bounded in time and memory): a flood of analyses queues up and never stalls jogging, touch-ups
or reads.
"""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Body, Query, Response
from fastapi.responses import JSONResponse
from pydantic import BaseModel, ConfigDict

from db.crud import NotFound, load_document
from server.api.deps import SessionDep
from server.formats.recording import parse_recording
from server.api.routers.jobs import JobOut, accepted
from server.service.recordings import add_recording, queue_analysis

router = APIRouter(tags=["Analysis"])


@router.post("/recordings", status_code=201)
def create_recording(db: SessionDep, doc: dict[str, Any] = Body(...)) -> dict[str, Any]:
    """Store a recording (``robot-recording/1``); 422 naming the field if it is not one."""
    rid, rec = add_recording(db, doc)
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
                                        description="seed of the fold assignment"),
                      split: Literal["blocked", "random"] | None = Query(
                          None, description="blocked (contiguous runs in recorded order) or "
                                            "random; default blocked for tracker recordings "
                                            "ordered in time")) -> JobOut:
    """Queue the analysis of the recording (a job): 202 and ``Location: /jobs/{id}``.

    The job's result is ``{"analysis_id": N}`` and ``links.result`` is ``/analysis/N``, the
    ``analysis-report/1``. A recording the analysis cannot use fails the job with the 422 the
    analysis gives (``error.status``, ``error.detail``)."""
    return accepted(response, queue_analysis(db, recording_id, folds, seed, split))


@router.get("/analysis/{analysis_id}")
def get_analysis(db: SessionDep, analysis_id: int) -> dict[str, Any]:
    """A stored analysis report (as ``analyze`` returned it, with its ``id``)."""
    return {**load_document(db, "analyses", analysis_id, "analysis_id"), "id": analysis_id}


@router.get("/analysis/{analysis_id}/model")
def get_analysis_model(db: SessionDep, analysis_id: int) -> JSONResponse:
    """The fitted ``robot-model/1`` of a stored analysis, as a download
    (``pendant analyze --save-model``); 404 for a report stored before models were kept."""
    rep = load_document(db, "analyses", analysis_id, "analysis_id")
    if not isinstance(rep.get("model"), dict):
        raise NotFound(("analysis_id",), f"analysis {analysis_id} has no model: it was stored "
                       "before models were kept; analyse the recording again")
    return JSONResponse(rep["model"], headers={
        "content-disposition": f'attachment; filename="robot-model-{analysis_id}.json"'})


class PredictIn(BaseModel):
    """``POST /predict``: a saved model, a recording of the same robot, and whether the
    setup (instrument frame, tool point, per-session terms) is fitted to it first."""

    model_config = ConfigDict(extra="forbid")
    model: dict[str, Any]
    recording: dict[str, Any]
    refit_setup: bool = False


@router.post("/predict")
def predict_recording(body: PredictIn) -> dict[str, Any]:
    """``prediction/1`` of the recording with the model (docs/analysis.md, "Predict")."""
    from solvers.analysis.blas import single_thread
    from solvers.analysis.model import predict
    from solvers.errors import CalibrationError

    try:
        rec = parse_recording(body.recording, measurements_optional=True)
    except CalibrationError as err:
        raise CalibrationError(("recording",) + tuple(err.loc), err.reason) from None
    try:
        with single_thread():
            return predict(body.model, rec, refit_setup=body.refit_setup)
    except CalibrationError as err:
        if err.loc and err.loc[0] in ("samples", "kind", "robot"):
            raise CalibrationError(("recording",) + tuple(err.loc), err.reason) from None
        raise CalibrationError(("model",) + tuple(err.loc), err.reason) from None
