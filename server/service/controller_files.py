"""Controller files in and out of the tables: the slots as ``FrameEntry`` values and back.

:func:`apply_import` is the one write path of a file import (route and ``pendant import``):
each slot the file names is replaced whole (pose, name, kind, load, unit), the change is
recorded in history with reason ``import``, and the file is kept so that
:func:`export_file` can patch later changes into it. With ``dry_run`` nothing is written
and the reply says what would change. The formats themselves live in server/formats.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sqlalchemy.orm import Session

from db import crud
from db.models import Controller
from db.models import FrameEntry as SlotRow
from db.outbox import emit
from server import formats
from server.formats.model import ParsedFile, family_of
from solvers.errors import CalibrationError
from solvers.frames import Pose

TABLE_OF_FAMILY = {"robot_held": "tool", "stationary": "base"}
POSE_FIELDS = ("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg")
LOAD_FIELDS = ("mass_kg", "com_x_mm", "com_y_mm", "com_z_mm", "inertia_x_kgm2",
               "inertia_y_kgm2", "inertia_z_kgm2", "inertia_a_deg", "inertia_b_deg",
               "inertia_c_deg")


IMPORTED_USED = "import."  # method prefix of a slot a file declared used (even if all zero)


def is_used(e: SlotRow) -> bool:
    """A slot with a name, a frame or a load, or one a controller file declared used: KUKA's
    ``TOOL_TYPE[2]=#BASE`` with a zero frame and a blank name is a tool all the same."""
    return (bool(e.name) or any(v != 0.0 for v in e.pose_values()) or e.mass_kg is not None
            or (e.method or "").startswith(IMPORTED_USED))


def to_frame_entry(e: SlotRow) -> formats.FrameEntry:
    """A used slot as a server.formats FrameEntry (a load only where the kind takes one)."""
    load = None
    if e.mass_kg is not None and e.kind in formats.LOADED:
        com = tuple(v or 0.0 for v in (e.com_x_mm, e.com_y_mm, e.com_z_mm))
        inertia = tuple(v or 0.0 for v in (e.inertia_x_kgm2, e.inertia_y_kgm2, e.inertia_z_kgm2))
        axes = tuple(v or 0.0 for v in (e.inertia_a_deg, e.inertia_b_deg, e.inertia_c_deg))
        load = formats.LoadData(e.mass_kg, com, inertia, axes)  # type: ignore[arg-type]
    unit = e.mech_unit if e.kind == "coordinated_base" else None
    if e.kind == "coordinated_base" and not unit:
        raise CalibrationError((e.entry_table, e.number, "mech_unit"),
                               "a coordinated_base needs the mechanical unit that moves it")
    pose = Pose(*e.pose_values())
    return formats.FrameEntry(e.number, e.name, e.kind, pose, load, unit)  # type: ignore[arg-type]


def to_frame_entries(rows: list[SlotRow]) -> list[formats.FrameEntry]:
    """The used slots as server.formats FrameEntry values."""
    return [to_frame_entry(e) for e in rows if is_used(e)]


def export_file(db: Session, controller_id: int, fmt: str) -> str:
    """The tables in ``fmt``: patched into the file last imported in that format, if any."""
    return export_file_encoded(db, controller_id, fmt)[0]


def export_file_encoded(db: Session, controller_id: int, fmt: str) -> tuple[str, str]:
    """(text, encoding) of :func:`export_file`: the kept file's own encoding, else UTF-8."""
    entries = to_frame_entries(crud.list_entries(db, controller_id))
    kept = crud.get_controller_file(db, controller_id, fmt)
    if kept is not None and fmt in formats.PATCHERS:
        return formats.PATCHERS[fmt](entries, kept.text), kept.encoding
    return formats.EXPORTERS[fmt](entries), "utf-8"


def export_file_bytes(db: Session, controller_id: int, fmt: str) -> tuple[bytes, str]:
    """(bytes, encoding) of :func:`export_file`, in the imported file's encoding."""
    text, encoding = export_file_encoded(db, controller_id, fmt)
    return formats.encode_file(text, encoding), encoding


def slot_values(fe: formats.FrameEntry | None, table: str) -> dict[str, Any]:
    """Every value of a slot, as ENTRY_FIELDS: the whole slot, nothing left from before."""
    if fe is None:
        values: dict[str, Any] = dict(zip(POSE_FIELDS, (0.0,) * 6))
        values.update(name="", kind=crud.DEFAULT_KIND[table], mech_unit=None)
        values.update(dict.fromkeys(LOAD_FIELDS))
        return values
    values = dict(zip(POSE_FIELDS, fe.pose.as_array().tolist()))
    values.update(name=fe.name, kind=fe.kind, mech_unit=fe.mech_unit)
    values.update(dict.fromkeys(LOAD_FIELDS))
    if fe.load is not None:
        ld = fe.load
        values.update(mass_kg=ld.mass_kg, com_x_mm=ld.com_mm[0], com_y_mm=ld.com_mm[1],
                      com_z_mm=ld.com_mm[2], inertia_x_kgm2=ld.inertia_kgm2[0],
                      inertia_y_kgm2=ld.inertia_kgm2[1], inertia_z_kgm2=ld.inertia_kgm2[2],
                      inertia_a_deg=ld.inertia_axes_deg[0], inertia_b_deg=ld.inertia_axes_deg[1],
                      inertia_c_deg=ld.inertia_axes_deg[2])
    return values


def _view(values: dict[str, Any] | None, used: bool) -> dict[str, Any] | None:
    """A slot for the preview: None when unused, else name, kind, pose, load, unit."""
    if values is None or not used:
        return None
    load = None
    if values["mass_kg"] is not None:
        load = {"mass_kg": values["mass_kg"],
                "com_mm": [values[f"com_{k}_mm"] or 0.0 for k in "xyz"],
                "inertia_kgm2": [values[f"inertia_{k}_kgm2"] or 0.0 for k in "xyz"],
                "inertia_axes_deg": [values[f"inertia_{k}_deg"] or 0.0 for k in "abc"]}
    return {"name": values["name"], "kind": values["kind"],
            "pose": dict(zip("xyzabc", (values[f] for f in POSE_FIELDS))),
            "load": load, "mech_unit": values["mech_unit"]}


def _text(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return repr(v + 0.0)
    if isinstance(v, list):
        return "[" + ", ".join(_text(x) for x in v) + "]"
    return repr(v) if isinstance(v, str) else str(v)


def value_changes(before: dict[str, Any] | None, after: dict[str, Any] | None
                  ) -> list[tuple[str, str, str]]:
    """(field, before, after) of every value of a preview slot (:func:`_view`) that differs,
    with every digit: what ``pendant import --dry-run`` prints under each slot.

    >>> value_changes(None, {"name": "pen", "kind": "tool", "mech_unit": None, "load": None,
    ...                      "pose": dict(x=0.0, y=0.0, z=180.5, a=0.0, b=0.0, c=0.0)})
    [('name', '-', "'pen'"), ('kind', '-', 'tool'), ('z', '-', '180.5')]
    """
    def flat(v: dict[str, Any] | None) -> dict[str, Any]:
        if v is None:
            return {}
        out: dict[str, Any] = {"name": v["name"], "kind": v["kind"]}
        out.update({k: x for k, x in v["pose"].items()})
        load = v["load"] or {}
        out.update({"mass_kg": load.get("mass_kg"), "com_mm": load.get("com_mm"),
                    "inertia": load.get("inertia_kgm2"), "axes_deg": load.get("inertia_axes_deg"),
                    "unit": v["mech_unit"]})
        return out

    a, b = flat(before), flat(after)
    keys = list(dict.fromkeys([*a, *b]))
    out = []
    for k in keys:
        old, new = a.get(k), b.get(k)
        if before is None and new in (0.0, None, ""):
            continue  # an unused slot had nothing: show only what the file gives
        if after is None and old in (0.0, None, ""):
            continue
        if old != new:
            show = (lambda v: "-" if v is None else v) if k == "kind" else _text
            out.append((k, show(old), show(new)))
    return out


@dataclass
class SlotChange:
    table: str
    number: int
    line: int | None
    before: dict[str, Any] | None
    after: dict[str, Any] | None
    kind_change: str | None  # "tool -> workpiece"
    changed: bool


@dataclass
class ImportResult:
    format: str
    dry_run: bool
    slots: list[SlotChange] = field(default_factory=list)
    skipped: list[formats.Skipped] = field(default_factory=list)

    @property
    def entries(self) -> int:
        return sum(1 for s in self.slots if s.after is not None)


def parse_file(fmt: str, text: str) -> ParsedFile:
    """The controller file ``text`` in ``fmt`` read (FormatError names the line and field).

    A file that lists its slots as unused (a new robot's ``$config.dat``) imports: it
    empties them. A file with no slot at all is refused."""
    parsed = formats.READERS[fmt](text)
    if not parsed.entries and not parsed.unused:
        raise CalibrationError(("text",), "no tool, base, workpiece or fixed-tool slot found "
                               f"in this {fmt} text")
    return parsed


def apply_import(db: Session, controller: Controller, fmt: str, text: str,
                 parsed: ParsedFile, dry_run: bool = False, encoding: str = "utf-8",
                 slots: list[tuple[str, int]] | None = None) -> ImportResult:
    """Replace every slot ``parsed`` names by the file's values (or say what would change).

    Each named slot is written whole: pose, name, kind, load (none when the file has none,
    e.g. KUKA ``M -1``) and mechanical unit. Slots the file lists as unused are emptied.
    ``slots`` (``(table, number)`` pairs) applies only those: every other slot keeps what it
    holds (a calibrated TOOL 1 survives importing the controller's file), and a later export
    patches it into the file. Nothing is written before every slot has been checked against
    the tables; ``dry_run`` writes nothing at all. ``text`` is kept for :func:`export_file`,
    with ``encoding``, the one it was decoded from.

    Raises
    ------
    CalibrationError
        ``("text", "line N", "<slot>")`` for a slot number the tables do not have;
        ``("slots", i)`` for a chosen slot the file does not name.
    """
    planned: list[tuple[SlotRow, dict[str, Any], SlotChange]] = []
    named = [(family_of(fe.kind), fe.number, fe) for fe in parsed.entries]
    named += [(family, n, None) for family, n in parsed.unused]
    if slots is not None:
        in_file = {(TABLE_OF_FAMILY[f], n) for f, n, _ in named}
        for i, ref in enumerate(slots):
            if tuple(ref) not in in_file:
                raise CalibrationError(("slots", i), f"the file does not name {ref[0]} {ref[1]}")
        chosen = {tuple(ref) for ref in slots}
        named = [x for x in named if (TABLE_OF_FAMILY[x[0]], x[1]) in chosen]
    for family, number, fe in sorted(named, key=lambda x: (x[0] != "robot_held", x[1])):
        table = TABLE_OF_FAMILY[family]
        line = parsed.slot_lines.get((family, number))
        limit = crud.slot_limit(controller, table)
        if not 1 <= number <= limit:
            if fe is None:
                continue  # an unused slot beyond the tables: nothing to empty
            where = f"line {line}" if line else "file"
            raise CalibrationError(("text", where, f"{fe.kind} {number}"),
                                   f"{table} slots are numbered 1..{limit}; this controller "
                                   f"has no {table} {number}" + (
                                       "" if crud.is_abb(controller) else
                                       " (a KUKA-kind controller keeps 16 tools and 32 bases)"))
        row = crud.find_entry(db, controller.id, table, number)
        if row is None:  # beyond an ABB-kind controller's table so far
            if fe is None:
                continue  # an unused slot of a table that never grew to it
            row = (crud.empty_entry(table, number) if dry_run
                   else crud.ensure_entry(db, controller, table, number))
        before = {f: getattr(row, f) for f in slot_values(None, table)}
        after = slot_values(fe, table)
        changed = (any(before[k] != v for k, v in after.items())
                   or is_used(row) != (fe is not None))
        if fe is None and not is_used(row):
            continue
        kind_change = None
        if is_used(row) and fe is not None and row.kind != fe.kind:
            kind_change = f"{row.kind} -> {fe.kind}"
        planned.append((row, after, SlotChange(table, number, line, _view(before, is_used(row)),
                                               _view(after, fe is not None),
                                               kind_change, changed)))
    result = ImportResult(fmt, dry_run, [c for _, _, c in planned], list(parsed.skipped))
    if dry_run:
        return result
    for row, after, change in planned:
        if change.changed:
            after.update(method=f"{IMPORTED_USED}{fmt}" if change.after is not None else None,
                         session_id=None, error_max_mm=None, error_rms_mm=None)
            crud.change_entry(db, row, after, reason="import")
    crud.store_controller_file(db, controller.id, fmt, text, encoding)
    emit(db, "import-applied", controller, {
        "format": fmt, "entries": result.entries, "skipped": len(result.skipped),
        "changed": [{"table": c.table, "number": c.number, "kind_change": c.kind_change}
                    for c in result.slots if c.changed]})
    return result
