"""External kinematics (KUKA EX_KIN 1..6): the slots (read, edit, history, restore), the
emulated external axes (move them) and their hidden errors (the emulator's truth).

The ``ext.*`` menus run through the session routes (server/api/routers/sessions.py) like every
other menu; a save writes the slot here with provenance and history (docs/methods/external.md).
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Response

from db import crud
from db.models import EntryHistory, ExternalKinematic
from emulator import external as ext_emu
from server.service import external as ext
from server.auth import audit
from server.api.deps import SessionDep
from server.api.preconditions import IfMatch, check, set_etag
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


def _precondition(e: ExternalKinematic, if_match: str | None) -> None:
    """A slot write needs If-Match (428 without, 412 with the current slot when stale)."""
    check(if_match, e.version, lambda: ext_slot_out(e),
          f"external kinematic {e.number} of controller {e.controller_id}", required=True)


@router.get(SLOTS, summary="All external kinematics (EX_KIN 1..6)")
def list_slots(controller_id: int, db: SessionDep) -> list[ExtSlotOut]:
    return [ext_slot_out(e) for e in ext.list_slots(db, controller_id)]


@router.get(SLOTS + "/{number}", summary="One external kinematic")
def get_slot(controller_id: int, number: int, db: SessionDep, response: Response) -> ExtSlotOut:
    """The slot; its ``ETag`` is what a later edit or restore sends as ``If-Match``."""
    e = ext.get_slot(db, controller_id, number)
    response.headers["ETag"] = f'"{e.version}"'
    return ext_slot_out(e)


@router.put(SLOTS + "/{number}", summary="Edit an external kinematic's machine data by hand")
def edit_slot(controller_id: int, number: int, body: ExtSlotIn, db: SessionDep,
              response: Response, if_match: IfMatch = None) -> ExtSlotOut:
    """``If-Match`` is required: 428 without it, 412 (with the current slot) if stale."""
    e = ext.get_slot(db, controller_id, number)
    values: dict[str, Any] = {}
    if body.name is not None:
        values["name"] = body.name
    if body.kind is not None:
        values["kind"] = body.kind
    if body.axes is not None:
        values["axes"] = ",".join(body.axes)
    if body.root is not None:
        values.update(zip(ext.POSE_KEYS, body.root.to_pose().as_array().tolist()))
    if body.flange is not None:
        values.update(zip(ext.FLANGE_KEYS, body.flange.to_pose().as_array().tolist()))
    if body.scale is not None:
        values["scale"] = body.scale
    if body.kind is not None or body.axes is not None:
        ext.check_axes(db, e, values.get("kind", e.kind),
                       values.get("axes", e.axes).split(",") if values.get("axes", e.axes) else [])
    if body.root is not None or body.flange is not None:
        values.update(method="numeric", session_id=None, error_max_mm=None, error_rms_mm=None)
    _precondition(e, if_match)
    ext.change_slot(db, e, values, reason="edit")
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
    e = ext.get_slot(db, controller_id, number)
    ext.get_history(db, e, history_id)  # 404 first: an unknown change is not a race
    _precondition(e, if_match)
    ext.restore_slot(db, e, history_id)
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
def put_external_errors(controller_id: int, body: ExternalErrorsIn,
                        db: SessionDep) -> dict[str, dict[str, float]]:
    """Replace the hidden errors (an omitted field has none): the axis tilted against its
    machine data, a root offset, a reversed sign, a scale (gear or encoder) error, the turn
    axis missing the tilt axis. Refused naming the field for an unknown one or a value no
    cell has."""
    c = crud.get_controller(db, controller_id)
    ext.values_of(c, "controller_id")
    doc = ext_emu.check_errors(body.model_dump())
    audit.record(db, "emulator.external", controller_id=c.id,
                 before={"external_errors": c.external_errors}, after={"external_errors": doc})
    c.external_errors = doc
    return doc
