"""What each kind of job does: the analysis of a stored recording, the restore of a JSON backup.

A kind is a function ``run(sessionmaker, params, progress) -> apply``: it reads what it needs
in short sessions, computes outside any transaction (reporting ``progress(fraction,
message)``), and returns ``apply(db) -> result``, which writes the outcome. The worker calls
``apply`` in the transaction that marks the job done, so a job is done exactly when its
result is stored (:mod:`server.jobs.worker`). A kind raises what a route would
(:class:`~solvers.errors.CalibrationError`, :class:`~db.crud.NotFound`, ...); the worker
stores it as the job's error, shaped as the route would have answered.

To add a kind: write its ``run`` here, add it to ``KINDS`` and give it a route that checks
the request and calls :func:`db.jobs.enqueue` (see ``server/api/routers/analysis.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sqlalchemy.orm import Session, sessionmaker

from db import crud

Progress = Callable[[float, str], None]
Apply = Callable[[Session], dict[str, Any]]


def run_analysis(sm: sessionmaker[Session], params: dict[str, Any], progress: Progress) -> Apply:
    """``params``: recording_id, folds, seed, split. Result: ``{"analysis_id": N}``."""
    from server.formats.recording import parse_recording
    from solvers.analysis import analyze

    rid = int(params["recording_id"])
    with sm() as db:
        doc = crud.load_document(db, "recordings", rid, "recording_id")
    progress(0.05, "reading the recording")
    rec = parse_recording(doc)
    del doc
    progress(0.1, f"analysing {rec.n_samples} samples")
    report = analyze(rec, folds=int(params.get("folds", 5)), seed=int(params.get("seed", 0)),
                     split=params.get("split"))
    report["recording_id"] = rid

    def apply(db: Session) -> dict[str, Any]:
        from db.outbox import emit

        analysis_id = crud.store_document(db, "analyses", report)
        emit(db, "analysis-finished", None, {
            "analysis_id": analysis_id, "recording_id": rid, "verdict": report.get("verdict"),
            "findings": [f.get("effect") for f in report.get("findings", [])]})
        return {"analysis_id": analysis_id}

    return apply


def run_restore(sm: sessionmaker[Session], params: dict[str, Any], progress: Progress) -> Apply:
    """``params``: controller_id, doc (a checked ``pendant-backup/1``, server.service.backup).

    Result: ``{"format": "json", "entries": N, "history": H}`` as the import answered."""
    from solvers.errors import CalibrationError

    cid, doc = int(params["controller_id"]), params["doc"]
    progress(0.1, "restoring the backup")

    def apply(db: Session) -> dict[str, Any]:
        from server.auth import audit

        audit.install()
        with audit.acting_as(params.get("actor"), "backup.restore"):  # who asked for it
            crud.lock_controller(db, cid)  # the row lock a REST write takes (PostgreSQL)
            c = crud.get_controller(db, cid)
            n_before = len(crud.history(db, c.id))
            try:
                n, h = crud.restore_backup(db, c, doc)
            except (KeyError, TypeError, ValueError) as err:
                raise CalibrationError(("text",),
                                       f"malformed backup: {type(err).__name__} {err}") from None
            audit.record(db, "backup.restore", controller_id=c.id,
                         before={"history_rows": n_before}, after={"history_rows": h, "entries": n})
            db.flush()  # the audit hooks run now, under the actor
        return {"format": "json", "entries": n, "history": h}

    return apply


KINDS: dict[str, Callable[[sessionmaker[Session], dict[str, Any], Progress], Apply]] = {
    "analysis": run_analysis,
    "restore": run_restore,
}
