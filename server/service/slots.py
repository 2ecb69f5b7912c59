"""The slot operations: a hand edit of a tool or base slot, a restore from its history, and
the same for an external kinematic (EX_KIN). Every face writes a slot through these: the REST
``PUT .../tools|bases/{n}``, the OPC UA CommitFrame, the RWS and KVP variable writes.

A slot write names the version it read (``if_match``, required: a blind overwrite of a slot
someone else just calibrated is the loss this prevents); :func:`db.crud.change_entry` records
the history row, the audit (its row hook) and the ``frame-committed`` event in the caller's
transaction.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from sqlalchemy.orm import Session

from db import crud
from db.models import ExternalKinematic, FrameEntry
from server.api.schemas import EntryIn, ExtSlotIn, LoadPatchIn
from server.service import external as ext
from server.service.controller_files import LOAD_FIELDS
from server.service.preconditions import Present, check_row
from solvers.errors import CalibrationError

POSE_FIELDS = ("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg")


def load_values(load: object | None) -> dict:
    """A load (``mass_kg``, ``com_mm``, ``inertia_kgm2``, ``inertia_axes_deg``) as a slot's
    columns; ``{}`` for none."""
    if load is None:
        return {}
    com, inertia = load.com_mm, load.inertia_kgm2  # type: ignore[attr-defined]
    axes = getattr(load, "inertia_axes_deg", (0.0, 0.0, 0.0))
    return {"mass_kg": load.mass_kg,  # type: ignore[attr-defined]
            "com_x_mm": com[0], "com_y_mm": com[1], "com_z_mm": com[2],
            "inertia_x_kgm2": inertia[0], "inertia_y_kgm2": inertia[1],
            "inertia_z_kgm2": inertia[2], "inertia_a_deg": axes[0], "inertia_b_deg": axes[1],
            "inertia_c_deg": axes[2]}


def edit_values(e: FrameEntry, body: EntryIn) -> dict:
    """The values a hand edit (``body``) writes into slot ``e``; CalibrationError naming the
    field for a kind the table does not hold or a coordinated base without its unit."""
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


def _load_values(e: FrameEntry, patch: LoadPatchIn | None) -> dict:
    """A load merged into the slot's (JSON Merge Patch): ``None`` removes it; the fields given
    replace the stored ones; a slot without a load needs ``mass_kg``."""
    if patch is None:
        return dict.fromkeys(LOAD_FIELDS)
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


def _what(e: FrameEntry) -> str:
    return f"{e.entry_table} {e.number} of controller {e.controller_id}"


def edit_slot(db: Session, controller_id: int, table: str, number: int, body: EntryIn,
              if_match: str | None, *, clear_load: bool = False,
              present: Present | None = None) -> FrameEntry:
    """A hand edit of slot ``table`` ``number`` (recorded in its history as ``edit``).

    ``if_match`` is required (PreconditionRequired without it, PreconditionFailed with
    ``present(e)`` when stale; ``*`` overwrites whatever it holds); it is checked after the
    body, so a wrong body is refused the same either way. ``clear_load`` drops the slot's load
    (a controller file's "nothing known")."""
    e = crud.get_entry(db, controller_id, table, number)
    values = edit_values(e, body)
    if clear_load:
        values.update(dict.fromkeys(LOAD_FIELDS))
    check_row(if_match, e, present, _what(e), required=True)
    crud.change_entry(db, e, values, reason="edit")
    return e


def restore_slot(db: Session, controller_id: int, table: str, number: int, history_id: int,
                 if_match: str | None, present: Present | None = None) -> FrameEntry:
    """Put slot ``table`` ``number`` back as it was before change ``history_id`` (recorded as
    a change); ``if_match`` as for :func:`edit_slot`."""
    e = crud.get_entry(db, controller_id, table, number)
    crud.get_history(db, e, history_id)  # 404 first: an unknown change is not a race
    check_row(if_match, e, present, _what(e), required=True)
    crud.restore_entry(db, e, history_id)
    return e


# ----------------------------------------------------------------- external kinematics

def _ext_what(e: ExternalKinematic) -> str:
    return f"external kinematic {e.number} of controller {e.controller_id}"


def edit_external(db: Session, controller_id: int, number: int, body: ExtSlotIn,
                  if_match: str | None, present: Present | None = None) -> ExternalKinematic:
    """A hand edit of external kinematic ``number``'s machine data; ``if_match`` as for
    :func:`edit_slot`."""
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
    check_row(if_match, e, present, _ext_what(e), required=True)
    ext.change_slot(db, e, values, reason="edit")
    return e


def restore_external(db: Session, controller_id: int, number: int, history_id: int,
                     if_match: str | None, present: Present | None = None) -> ExternalKinematic:
    """External kinematic ``number`` as it was before change ``history_id``; ``if_match`` as
    for :func:`edit_slot`."""
    e = ext.get_slot(db, controller_id, number)
    ext.get_history(db, e, history_id)  # 404 first: an unknown change is not a race
    check_row(if_match, e, present, _ext_what(e), required=True)
    ext.restore_slot(db, e, history_id)
    return e
