"""Workpiece menu: robot-held workpieces, in the tool table (KUKA TOOL_DATA of type #TCP)."""

from __future__ import annotations

from fastapi import APIRouter

from db import crud
from server.api.deps import SessionDep
from server.api.routers.common import entry_out
from server.api.schemas import EntryOut

router = APIRouter(prefix="/controllers/{controller_id}/workpieces", tags=["Workpiece"])


@router.get("")
def list_workpieces(controller_id: int, db: SessionDep) -> list[EntryOut]:
    """Tool slots of type workpiece: ``pose`` = T_flange_workpiece."""
    crud.get_controller(db, controller_id)
    return [entry_out(e) for e in crud.list_entries(db, controller_id, "tool", "workpiece")]
