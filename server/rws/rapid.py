"""The RAPID symbols RWS serves: the controller's tool and work-object slots as PERS data.

The symbols are the declarations of the controller's RAPID module as ``pendant export
--format abb`` writes it (the module imported last, patched, or pendant's ``CalibData``):
each ``tooldata`` and ``wobjdata`` is a slot, a ``loaddata <wobj>_load`` the load of a
robot-held work object. A slot not in the module answers under its default name
(``tool<n>`` for a tool slot, ``wobj<n>`` for a base slot), so a client can fill an empty
slot. Values are read and written as RAPID literals through :mod:`server.formats.abb`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from server.formats import abb
from server.formats.model import FormatError, FrameEntry
from solvers.errors import CalibrationError
from solvers.frames import Pose

TASK = "T_ROB1"
DEFAULT_MODULE = "CalibData"
DTYPE_OF_KIND = {"tool": "tooldata", "fixed_tool": "tooldata", "workpiece": "wobjdata",
                 "base": "wobjdata", "coordinated_base": "wobjdata"}
TABLE_OF_FAMILY = {"robot_held": "tool", "stationary": "base"}
MAX_LITERAL = 2000  # characters of a value a client may send


@dataclass(frozen=True)
class Symbol:
    """One PERS symbol: its name, RAPID type, module, literal and the slot it stands for."""

    name: str
    dtype: str  # tooldata | wobjdata | loaddata
    module: str
    value: str
    table: str | None  # tool | base; None for a loaddata that is no slot's load
    number: int | None
    kind: str | None  # the slot's kind (a loaddata: its work object's)

    @property
    def url(self) -> str:
        return f"RAPID/{TASK}/{self.module}/{self.name}"


def _literal(text: str, start: int, end: int) -> str:
    decl = text[start:end]
    value = decl.split(":=", 1)[1].rsplit(";", 1)[0]
    return re.sub(r"\s+", "", value)  # RWS prints a value on one line, without spaces


def symbols(module_text: str, table_numbers: dict[str, list[int]],
            used: set[tuple[str, int]]) -> list[Symbol]:
    """Every symbol of ``module_text`` (the ABB export) and the default-named unused slots.

    ``table_numbers``: the slot numbers of each table; ``used``: (table, number) in use."""
    found, entries, _skipped, decls, _ = abb.read_declarations(module_text)
    m = abb.MODULE_LINE.search(module_text)
    module = m.group(1) if m else DEFAULT_MODULE
    out: list[Symbol] = []
    slot_of_decl: dict[int, tuple[str, int, str]] = {}
    for f, e in zip(found, entries):
        table = "tool" if e.kind in ("tool", "workpiece") else "base"
        slot_of_decl[id(f.decl)] = (table, e.number, e.kind)
        if f.load_decl is not None:
            slot_of_decl[id(f.load_decl)] = (table, e.number, e.kind)
    taken = set()
    for d in decls:
        table, number, kind = slot_of_decl.get(id(d), (None, None, None))
        out.append(Symbol(d.name, d.dtype, module, _literal(module_text, d.start, d.end),
                          table, number, kind))
        taken.add(d.name.upper())
    defaults = (("tool", "tool", "tool"), ("base", "wobj", "base"))
    for table, prefix, kind in defaults:
        for n in table_numbers.get(table, []):
            name = f"{prefix}{n}"
            if (table, n) in used or name.upper() in taken:
                continue
            pose = Pose(0, 0, 0, 0, 0, 0)
            text = abb.export_abb([FrameEntry(n, name, kind, pose)], "M")  # type: ignore[arg-type]
            (d,) = [x for x in abb.read_declarations(text)[3]]
            out.append(Symbol(name, DTYPE_OF_KIND[kind], module,
                              _literal(text, d.start, d.end), table, n, kind))
    return out


def find(syms: list[Symbol], path: str) -> Symbol:
    """The symbol at ``T_ROB1/<module>/<name>`` or ``T_ROB1/<name>`` (RAPID names are not
    case-sensitive). Raises LookupError naming what is not there."""
    parts = [p for p in path.strip("/").split("/") if p]
    if not parts or parts[0].upper() != TASK or len(parts) not in (2, 3):
        raise LookupError(f"no symbol RAPID/{path}: pendant serves RAPID/{TASK}/<module>/<name> "
                          f"and RAPID/{TASK}/<name>")
    name = parts[-1].upper()
    module = parts[1].upper() if len(parts) == 3 else None
    for s in syms:
        if s.name.upper() == name and (module is None or s.module.upper() == module):
            return s
    raise LookupError(f"no symbol RAPID/{'/'.join(parts)} (see POST /rw/rapid/symbols"
                      "?action=search-symbols)")


def parse_value(sym: Symbol, value: str) -> FrameEntry | object:
    """The literal ``value`` for ``sym`` read by the ABB import's own reader: a FrameEntry of
    the slot's new pose, kind, load and unit (tooldata, wobjdata), or the LoadData / None of
    a loaddata. FormatError names the field and the reason."""
    if not isinstance(value, str) or not value.strip():
        raise FormatError(("value",), "is empty; give a RAPID literal such as [TRUE,[[0,0,100],"
                          "[1,0,0,0]],[1,[0,0,50],[1,0,0,0],0,0,0]]")
    if len(value) > MAX_LITERAL:
        raise FormatError(("value",), f"has {len(value)} characters; at most {MAX_LITERAL}")
    if any(c in value for c in ";!\n\r"):
        raise FormatError(("value",), "a literal has no ';', '!' or line break")
    text = f"MODULE M\n  PERS {sym.dtype} {sym.name}:={value};\nENDMODULE\n"
    try:
        _found, entries, skipped, decls, _ = abb.read_declarations(text)
    except FormatError as err:
        raise FormatError(("value", *err.loc[2:]), err.reason) from None
    if skipped:
        raise FormatError(("value", skipped[0].field), skipped[0].reason)
    if sym.dtype == "loaddata":
        if len(decls) != 1:
            raise FormatError(("value",), "expected one loaddata literal")
        try:
            return abb.read_load(decls[0].value, 2, sym.name)
        except FormatError as err:
            raise FormatError(("value", *err.loc[2:]), err.reason) from None
    if len(entries) != 1:
        raise FormatError(("value",), f"expected one {sym.dtype} literal")
    return entries[0]


def kind_allowed(sym: Symbol, kind: str) -> None:
    """A slot keeps its table: a tooldata in a tool slot stays robot-held, and so on."""
    allowed = {"tool": ("tool", "workpiece"), "base": ("base", "fixed_tool", "coordinated_base")}
    if sym.table is not None and kind not in allowed[sym.table]:
        held = "TRUE" if kind in ("tool", "workpiece") else "FALSE"
        raise CalibrationError(("value", "robhold"), f"{sym.name} is a {sym.table} slot; "
                               f"robhold {held} would make it a {kind}, which that table "
                               "does not hold")
