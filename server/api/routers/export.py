"""Export: the tables as a controller file (KUKA, ABB, FANUC, UR) or a JSON backup, and import.

The file formats live in server/formats; here only the slots are turned into
``FrameEntry`` values and back. A JSON backup holds the whole controller incl. history.
"""

from __future__ import annotations

from fastapi import APIRouter, Request, Response

from db import crud
from server.auth.guard import require
from server.service.controller_files import (
    ImportResult,
    apply_import,
    export_file_bytes,
    parse_file,
)
from server.service.backup import restore_later
from server.service.export import export_text
from server.service.robot import controller
from server.api.deps import SessionDep
from server.api.preconditions import IfMatch
from server.api.routers.controllers import controller_out
from server.api.routers.jobs import JobOut, accepted
from server.api.schemas import ExportFormat, ImportIn, ImportOut, SkippedOut, SlotChangeOut
from solvers.errors import CalibrationError

router = APIRouter(prefix="/controllers/{controller_id}", tags=["Export"])

MEDIA = {"kuka": ("text/plain", "$config.dat"), "abb": ("text/plain", "CalibData.mod"),
         "fanuc": ("text/plain", "frames.ls"), "ur": ("text/plain", "frames.script"),
         "json": ("application/json", "backup.json"),
         "kuka_machine": ("text/plain", "external-kinematics.dat"),
         "abb_moc": ("text/plain", "MOC-external.cfg")}


def import_out(result: ImportResult) -> ImportOut:
    return ImportOut(
        format=result.format, entries=result.entries, dry_run=result.dry_run,
        slots=[SlotChangeOut(**vars(s)) for s in result.slots],
        skipped=[SkippedOut(line=k.line, field=k.field, reason=k.reason)
                 for k in result.skipped])


@router.get("/export", response_class=Response,
            responses={200: {"content": {"text/plain": {}, "application/json": {}}}})
def export(controller_id: int, db: SessionDep, request: Request,
           format: ExportFormat = "kuka") -> Response:
    """Download the tables as a controller file (``format=kuka|abb|fanuc|ur``), the external
    kinematics (``kuka_machine``: ``$machine.dat`` ``$ETn_...`` and ``$config.dat``
    ``MACHINE_DEF`` and the bases on them; ``abb_moc``: ``MOC.cfg`` base frames) or the whole
    controller as a JSON backup (``format=json``, incl. history and sessions; needs
    ``backup:write``)."""
    if format == "json":
        require(request, "backup:write")
    media, filename = MEDIA[format]
    name = crud.get_controller(db, controller_id).name
    if format in ("kuka", "abb", "fanuc", "ur"):  # in the imported file's own encoding
        raw, encoding = export_file_bytes(db, controller_id, format)
        charset = "windows-1252" if encoding == "cp1252" else "utf-8"
        return Response(raw, media_type=f"{media}; charset={charset}", headers={
            "Content-Disposition": f'attachment; filename="{name}-{filename}"'})
    text = export_text(db, controller_id, format)
    return Response(text, media_type=media,
                    headers={"Content-Disposition": f'attachment; filename="{name}-{filename}"'})


@router.post("/import", responses={202: {"model": JobOut,
                                         "description": "JSON backup: the restore job"}})
def import_tables(controller_id: int, body: ImportIn, db: SessionDep, request: Request,
                  response: Response, if_match: IfMatch = None) -> ImportOut | JobOut:
    """Read a controller file (KUKA ``$config.dat``, ABB RAPID module, pendant's FANUC or UR
    export) or a JSON backup into the tables.

    A controller file replaces each slot it names whole (each change recorded in history),
    or only the ``slots`` chosen (the others keep what they hold), and is kept, with its
    ``encoding``, so that a later export in that format patches only changed values into it;
    the answer is 200. ``dry_run`` returns, per slot, before -> after, kind changes and
    skipped declarations, and writes nothing. A JSON backup replaces the tables, history and
    sessions (needs ``backup:restore``; the audit keeps every earlier change): it is checked
    at once (422 naming the field), then restored by a job (202,
    ``Location: /jobs/{id}``; the job's result is ``{"format", "entries", "history"}``).
    ``If-Match`` (the controller's ETag) is honoured: 412 when the controller changed since."""
    c = controller(db, controller_id, if_match, controller_out)
    if body.format == "json" and body.slots is not None:
        raise CalibrationError(("slots",), "a JSON backup restores the whole controller; "
                               "slots choose among a controller file's slots")
    if body.format == "json":
        require(request, "backup:restore")
        entries, job = restore_later(db, c, body.text, body.dry_run)
        if job is None:
            return ImportOut(format="json", entries=entries, dry_run=True)
        response.status_code = 202  # the restore itself is a job (server.jobs.kinds)
        return accepted(response, job)
    slots = None if body.slots is None else [(s.table, s.number) for s in body.slots]
    result = apply_import(db, c, body.format, body.text, parse_file(body.format, body.text),
                          body.dry_run, body.encoding, slots)
    return import_out(result)
