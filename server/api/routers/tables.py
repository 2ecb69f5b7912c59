"""The slot routes every table menu shares: list, read, edit by hand, history, restore."""

from __future__ import annotations

from types import SimpleNamespace

from fastapi import APIRouter, Response

from db import crud
from db.models import EntryHistory, FrameEntry
from server.api.deps import SessionDep
from server.api.preconditions import IfMatch, check, etag, set_etag
from server.api.routers.common import entry_out, load_values
from server.api.schemas import EntryIn, EntryKind, EntryOut, HistoryOut, LoadPatchIn
from solvers.errors import CalibrationError


def history_out(h: EntryHistory) -> HistoryOut:
    return HistoryOut(id=h.id, table=h.entry_table, number=h.number, reason=h.reason,
                      session_id=h.session_id, changed_at=h.changed_at, before=h.before,
                      after=h.after, changed_by=h.changed_by)


def _precondition(e: FrameEntry, if_match: str | None) -> None:
    """A slot write needs If-Match (428 without, 412 with the current slot when stale)."""
    check(if_match, e.version, lambda: entry_out(e),
          f"{e.entry_table} {e.number} of controller {e.controller_id}", required=True)


def edit_values(e: FrameEntry, body: EntryIn) -> dict:
    """The values a hand edit (``body``) writes into slot ``e``; CalibrationError naming the
    field for a kind the table does not hold or a coordinated base without its unit. The REST
    edit and the OPC UA CommitFrame both write through this."""
    table = e.entry_table
    values: dict = {}
    if body.name is not None:
        values["name"] = body.name
    if body.kind is not None:
        if body.kind not in crud.KINDS_OF_TABLE[table]:
            kinds = " or ".join(crud.KINDS_OF_TABLE[table])
            raise CalibrationError(("kind",),
                                   f"a {table} slot holds {kinds}, not {body.kind!r}")
        values["kind"] = body.kind
    kind = values.get("kind", e.kind)
    if body.mech_unit is not None or kind != "coordinated_base":
        values["mech_unit"] = body.mech_unit if kind == "coordinated_base" else None
    if kind == "coordinated_base" and not values.get("mech_unit", e.mech_unit):
        raise CalibrationError(("mech_unit",), "a coordinated_base names the mechanical "
                               "unit that moves it")
    if body.pose is not None:
        pose = body.pose.merged(tuple(e.pose_values()))
        if pose != tuple(e.pose_values()):
            values.update(zip(POSE_FIELDS, pose))
            values.update(method="numeric", session_id=None, error_max_mm=None,
                          error_rms_mm=None)
    if "load" in body.model_fields_set:
        values.update(_load_values(e, body.load))
    return values


POSE_FIELDS = ("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg")


def _load_values(e: FrameEntry, patch: LoadPatchIn | None) -> dict:
    """A load merged into the slot's (JSON Merge Patch): ``None`` removes it; the fields given
    replace the stored ones; a slot without a load needs ``mass_kg``."""
    if patch is None:
        return dict.fromkeys(("mass_kg", "com_x_mm", "com_y_mm", "com_z_mm", "inertia_x_kgm2",
                              "inertia_y_kgm2", "inertia_z_kgm2", "inertia_a_deg",
                              "inertia_b_deg", "inertia_c_deg"))
    if e.mass_kg is None and patch.mass_kg is None:
        raise CalibrationError(("load", "mass_kg"), "the slot has no load yet: give its mass")

    def stored(*names: str) -> list[float]:
        return [getattr(e, n) or 0.0 for n in names]

    return load_values(SimpleNamespace(
        mass_kg=e.mass_kg if patch.mass_kg is None else patch.mass_kg,
        com_mm=patch.com_mm or stored("com_x_mm", "com_y_mm", "com_z_mm"),
        inertia_kgm2=patch.inertia_kgm2 or stored("inertia_x_kgm2", "inertia_y_kgm2",
                                                  "inertia_z_kgm2"),
        inertia_axes_deg=patch.inertia_axes_deg or stored("inertia_a_deg", "inertia_b_deg",
                                                          "inertia_c_deg")))


def table_router(table: str, path: str, tag: str) -> APIRouter:
    """Routes of ``/controllers/{id}/{path}``: the ``table`` ('tool' | 'base') slots."""
    router = APIRouter(prefix=f"/controllers/{{controller_id}}/{path}", tags=[tag])
    label = "tool (TOOL_DATA)" if table == "tool" else "base (BASE_DATA)"

    @router.get("", name=f"list_{path}", summary=f"All {label} slots")
    def list_slots(controller_id: int, db: SessionDep, kind: EntryKind | None = None) -> list[EntryOut]:
        crud.get_controller(db, controller_id)
        return [entry_out(e) for e in crud.list_entries(db, controller_id, table, kind)]

    @router.get("/{number}", name=f"get_{table}", summary=f"One {label} slot")
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
        e = crud.get_entry(db, controller_id, table, number)
        values = edit_values(e, body)
        _precondition(e, if_match)  # after the body's checks: a wrong body is a 422 either way
        crud.change_entry(db, e, values, reason="edit")
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
        e = crud.get_entry(db, controller_id, table, number)
        crud.get_history(db, e, history_id)  # 404 first: an unknown change is not a race
        _precondition(e, if_match)
        crud.restore_entry(db, e, history_id)
        set_etag(response, db, e)
        return entry_out(e)

    return router
