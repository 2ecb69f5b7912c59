"""The slot routes every table menu shares: list, read, edit by hand, history, restore."""

from __future__ import annotations

from fastapi import APIRouter, Response

from db import crud
from db.models import EntryHistory
from server.api.deps import SessionDep, quick_read
from server.api.preconditions import IfMatch, etag, set_etag
from server.api.routers.common import entry_out
from server.api.schemas import EntryIn, EntryKind, EntryOut, HistoryOut
from server.service import slots


def history_out(h: EntryHistory) -> HistoryOut:
    return HistoryOut(id=h.id, table=h.entry_table, number=h.number, reason=h.reason,
                      session_id=h.session_id, changed_at=h.changed_at, before=h.before,
                      after=h.after, changed_by=h.changed_by)


def table_router(table: str, path: str, tag: str) -> APIRouter:
    """Routes of ``/controllers/{id}/{path}``: the ``table`` ('tool' | 'base') slots."""
    router = APIRouter(prefix=f"/controllers/{{controller_id}}/{path}", tags=[tag])
    label = "tool (TOOL_DATA)" if table == "tool" else "base (BASE_DATA)"

    @router.get("", name=f"list_{path}", summary=f"All {label} slots")
    def list_slots(controller_id: int, db: SessionDep, kind: EntryKind | None = None) -> list[EntryOut]:
        crud.get_controller(db, controller_id)
        return [entry_out(e) for e in crud.list_entries(db, controller_id, table, kind)]

    @router.get("/{number}", name=f"get_{table}", summary=f"One {label} slot")
    @quick_read
    def get_slot(controller_id: int, number: int, db: SessionDep, response: Response) -> EntryOut:
        """The slot; its ``ETag`` is what a later edit sends as ``If-Match``."""
        e = crud.get_entry(db, controller_id, table, number)
        response.headers["ETag"] = etag(e.version)
        return entry_out(e)

    @router.put("/{number}", name=f"edit_{table}",
                summary=f"Edit a {label} slot by hand (recorded in history)")
    def edit_slot(controller_id: int, number: int, body: EntryIn, db: SessionDep,
                  response: Response, if_match: IfMatch = None) -> EntryOut:
        """``If-Match`` is required: 428 without it, 412 (with the current slot) if stale."""
        e = slots.edit_slot(db, controller_id, table, number, body, if_match,
                            present=entry_out)
        set_etag(response, db, e)
        return entry_out(e)

    @router.get("/{number}/history", name=f"history_{table}",
                summary="Every change of the slot, oldest first")
    def slot_history(controller_id: int, number: int, db: SessionDep) -> list[HistoryOut]:
        crud.get_entry(db, controller_id, table, number)
        return [history_out(h) for h in crud.history(db, controller_id, table, number)]

    @router.post("/{number}/restore/{history_id}", name=f"restore_{table}",
                 summary="Put the slot back as it was before that change (recorded as a change)")
    def restore(controller_id: int, number: int, history_id: int, db: SessionDep,
                response: Response, if_match: IfMatch = None) -> EntryOut:
        """``If-Match`` is required, as for an edit."""
        e = slots.restore_slot(db, controller_id, table, number, history_id, if_match,
                               entry_out)
        set_etag(response, db, e)
        return entry_out(e)

    return router
