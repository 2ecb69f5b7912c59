"""Fixed tool menu: external TCPs, stored in the base table (KUKA BASE_DATA of type #TCP)."""

from __future__ import annotations

from fastapi import APIRouter

from db import crud
from server.api.deps import SessionDep
from server.api.routers.common import entry_out
from server.api.schemas import EntryOut

router = APIRouter(prefix="/controllers/{controller_id}/fixed-tools", tags=["Fixed tool"])


@router.get("")
def list_fixed_tools(controller_id: int, db: SessionDep) -> list[EntryOut]:
    """Base slots of type fixed_tool: ``pose`` = T_world_fixedtool (z = the fixed tool's axis)."""
    crud.get_controller(db, controller_id)
    return [entry_out(e) for e in crud.list_entries(db, controller_id, "base", "fixed_tool")]
