"""External kinematics (KUKA EX_KIN 1..6): the slots (read, edit, history, restore), the
emulated external axes (move them) and their hidden errors (the emulator's truth).

The ``ext.*`` menus run through the session routes (server/api/routers/sessions.py) like every
other menu; a save writes the slot here with provenance and history (docs/methods/external.md).
"""

from __future__ import annotations

from fastapi import APIRouter, Response

from db import crud
from db.models import EntryHistory, ExternalKinematic
from emulator import external as ext_emu
from server.service import controllers
from server.service import external as ext
from server.service import slots
from server.api.deps import SessionDep, quick_read
from server.api.preconditions import IfMatch, set_etag
from server.api.routers.controllers import controller_out
from server.api.schemas import (ExternalErrorsIn, ExtHistoryOut, ExtSlotIn, ExtSlotOut,
                            ProvenanceOut, PoseOut)

router = APIRouter(prefix="/controllers/{controller_id}", tags=["External kinematics"])
SLOTS = "/external-kinematics"


def ext_slot_out(e: ExternalKinematic) -> ExtSlotOut:
    return ExtSlotOut(number=e.number, name=e.name, kind=e.kind,  # type: ignore[arg-type]
                      axes=ext.axes_of(e), root=PoseOut.of(e.pose_values()),
                      flange=PoseOut.of(e.flange_values()), scale=e.scale,
                      provenance=ProvenanceOut(method=e.method, session_id=e.session_id,
                                               error_max_mm=e.error_max_mm,
                                               error_rms_mm=e.error_rms_mm,
                                               updated_at=e.updated_at, updated_by=e.updated_by))


def _history_out(h: EntryHistory) -> ExtHistoryOut:
    return ExtHistoryOut(id=h.id, table="extkin", number=h.number, reason=h.reason,
                         session_id=h.session_id, changed_at=h.changed_at, before=h.before,
                         after=h.after, changed_by=h.changed_by)


@router.get(SLOTS, summary="All external kinematics (EX_KIN 1..6)")
def list_slots(controller_id: int, db: SessionDep) -> list[ExtSlotOut]:
    return [ext_slot_out(e) for e in ext.list_slots(db, controller_id)]


@router.get(SLOTS + "/{number}", summary="One external kinematic")
@quick_read
def get_slot(controller_id: int, number: int, db: SessionDep, response: Response) -> ExtSlotOut:
    """The slot; its ``ETag`` is what a later edit or restore sends as ``If-Match``."""
    e = ext.get_slot(db, controller_id, number)
    response.headers["ETag"] = f'"{e.version}"'
    return ext_slot_out(e)


@router.put(SLOTS + "/{number}", summary="Edit an external kinematic's machine data by hand")
def edit_slot(controller_id: int, number: int, body: ExtSlotIn, db: SessionDep,
              response: Response, if_match: IfMatch = None) -> ExtSlotOut:
    """``If-Match`` is required: 428 without it, 412 (with the current slot) if stale."""
    e = slots.edit_external(db, controller_id, number, body, if_match, ext_slot_out)
    set_etag(response, db, e)
    return ext_slot_out(e)


@router.get(SLOTS + "/{number}/history", summary="Every change of the slot, oldest first")
def slot_history(controller_id: int, number: int, db: SessionDep) -> list[ExtHistoryOut]:
    ext.get_slot(db, controller_id, number)
    return [_history_out(h) for h in crud.history(db, controller_id, ext.TABLE, number)]


@router.post(SLOTS + "/{number}/restore/{history_id}",
             summary="Put the slot back as it was before that change (recorded as a change)")
def restore(controller_id: int, number: int, history_id: int, db: SessionDep,
            response: Response, if_match: IfMatch = None) -> ExtSlotOut:
    """``If-Match`` is required, as for an edit."""
    e = slots.restore_external(db, controller_id, number, history_id, if_match, ext_slot_out)
    set_etag(response, db, e)
    return ext_slot_out(e)


@router.get("/cell/external", summary="The external machines' hidden errors (the truth)")
def get_external_errors(controller_id: int, db: SessionDep) -> dict[str, dict[str, float]]:
    """What the emulated turntable, positioner and rail really do differently from their
    machine data; the seeded defaults until ``PUT`` sets them."""
    c = crud.get_controller(db, controller_id)
    ext.values_of(c, "controller_id")
    return ext_emu.check_errors(c.external_errors) if c.external_errors else \
        ext_emu.default_errors(int(c.cell_seed))


@router.put("/cell/external", summary="Set the external machines' hidden errors")
def put_external_errors(controller_id: int, body: ExternalErrorsIn, db: SessionDep,
                        response: Response, if_match: IfMatch = None
                        ) -> dict[str, dict[str, float]]:
    """Replace the hidden errors (an omitted field has none): the axis tilted against its
    machine data, a root offset, a reversed sign, a scale (gear or encoder) error, the turn
    axis missing the tilt axis. Refused naming the field for an unknown one or a value no
    cell has. ``If-Match`` is the controller's ETag (412 when stale)."""
    c, errors = controllers.set_external_errors(db, controller_id, body.model_dump(), if_match,
                                                controller_out)
    set_etag(response, db, c)
    return errors
