"""ABB RAPID: ``tooldata`` and ``wobjdata`` (and ``loaddata``) in a program module.

.. code-block:: text

    tooldata := [robhold, tframe, tload]
        tframe := [[x, y, z], [q1, q2, q3, q4]]           (mm; q1 the scalar)
        tload  := [mass, [cx, cy, cz], [aom q1..q4], ix, iy, iz]   (kg, mm, kg m^2)
    wobjdata := [robhold, ufprog, ufmec, uframe, oframe]
    loaddata := [mass, [cx, cy, cz], [aom q1..q4], ix, iy, iz]

Kinds (ABB *Technical reference manual - RAPID Instructions, Functions and Data types*):

- ``tool``: tooldata, robhold TRUE, tframe = T_flange_tcp, tload = the tool's load;
- ``fixed_tool``: tooldata, robhold FALSE (stationary tool), tframe = T_world_fixedtool;
- ``workpiece``: wobjdata, robhold TRUE, ufprog TRUE, ufmec "", uframe = T_flange_workpiece
  (the robot holds the work object), oframe identity; its load as ``loaddata <name>_load``;
- ``base``: wobjdata, robhold FALSE, ufprog TRUE, ufmec "", uframe = T_world_base, oframe identity;
- ``coordinated_base``: wobjdata, robhold FALSE, ufprog FALSE, ufmec = the mechanical unit
  that moves it (``"STN1"``), uframe * oframe = T_unit_base (a coordinated work object);
- ``fixed_tool`` keeps its tload: for a stationary tool it is the load the robot carries.

A module must be whole (``MODULE`` ... ``ENDMODULE``). A declaration pendant cannot use (an
array, a value that is not literal, no value) is skipped and listed, never a reason to
refuse the rest. Given the imported text, :func:`export_abb` patches only the values that
changed into it.

ABB refuses a tool mass of 0, so a tool without a known load is written with ABB's own
minimum load ``[0.001,[0,0,0.001],[1,0,0,0],0,0,0]`` (that of ``tool0``), and that load
reads back as "no load". Each declaration is preceded by ``! pendant: <kind> <number>
"<name>"`` so numbers and names survive RAPID's identifier rules; files without these
comments are numbered in file order.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from solvers.frames import Pose, abb_from_matrix, kuka_from_matrix, matrix_from_abb

from server.service.bounds import check_name, check_value
from server.formats.model import (
    index_number,
    FormatError,
    FrameEntry,
    LoadData,
    ParsedFile,
    Skipped,
    canonical_order,
    check_unique_slots,
    family_of,
    one_line,
)
from solvers.errors import CalibrationError

__all__ = ["export_abb", "import_abb", "read_abb", "rapid_name", "MIN_TOOL_MASS_KG",
           "UNKNOWN_LOAD"]

MIN_TOOL_MASS_KG = 0.001
UNKNOWN_LOAD = "[0.001,[0,0,0.001],[1,0,0,0],0,0,0]"  # tool0's load: ABB's "nothing known"
_UNKNOWN = (0.001, (0.0, 0.0, 0.001), (1.0, 0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
IDENT_CHARS = 32
QUAT_NORM_TOL = 1e-3
_PREFIX = {"tool": "tool", "fixed_tool": "stattool", "workpiece": "heldwobj", "base": "wobj",
           "coordinated_base": "cwobj"}
_RESERVED = {
    w.upper() for w in (
        "ALIAS AND BACKWARD CASE CONNECT CONST DEFAULT DIV DO ELSE ELSEIF ENDFOR ENDFUNC ENDIF "
        "ENDMODULE ENDPROC ENDRECORD ENDTEST ENDTRAP ENDWHILE ERROR EXIT FALSE FOR FROM FUNC "
        "GOTO IF INOUT LOCAL MOD MODULE NOSTEPIN NOT NOVIEW OR PERS PROC RAISE READONLY RECORD "
        "RETRY RETURN STEP SYSMODULE TASK TEST THEN TO TRAP TRUE TRYNEXT UNDO VAR VIEWONLY WHILE "
        "WITH XOR "
        "tooldata wobjdata loaddata pose pos orient num dnum bool string robtarget jointtarget "
        "tool0 wobj0 load0"
    ).split()
}
_IDENT = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_TAG = re.compile(r'^\s*!\s*pendant:\s*(tool|fixed_tool|workpiece|base|coordinated_base)\s+'
                  r'(\d+)\s+"(.*)"\s*$', re.IGNORECASE)


# --------------------------------------------------------------------------- export


def rapid_num(value: float) -> str:
    """A num literal: integers without decimals, else the shortest exact digits.

    Examples
    --------
    >>> rapid_num(180.0), rapid_num(-0.0), rapid_num(0.7071067811865476), rapid_num(1e-05)
    ('180', '0', '0.7071067811865476', '1e-05')
    """
    v = float(value) + 0.0
    if v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    return repr(v)


def _list(values: Iterable[float]) -> str:
    return "[" + ",".join(rapid_num(v) for v in values) + "]"


def _quat(T: np.ndarray) -> np.ndarray:
    """Scalar-first quaternion with float dust (< 5e-16) cleared; import re-normalises."""
    return np.round(abb_from_matrix(T)[1], 15) + 0.0


def _pose(p: Pose) -> str:
    T = p.as_matrix()
    return f"[{_list(T[:3, 3])},{_list(_quat(T))}]"


def _load(load: LoadData | None) -> str:
    if load is None:
        return UNKNOWN_LOAD
    aom = _quat(Pose(0, 0, 0, *load.inertia_axes_deg).as_matrix())
    mass = max(load.mass_kg, MIN_TOOL_MASS_KG)
    return "[" + ",".join([rapid_num(mass), _list(load.com_mm), _list(aom),
                           *(rapid_num(x) for x in load.inertia_kgm2)]) + "]"


def _ident_for(e: FrameEntry, taken: set[str]) -> str:
    limit = IDENT_CHARS - len("_load") if e.load is not None and e.kind != "tool" else IDENT_CHARS
    name = rapid_name(e.name, e.kind, e.number, taken, limit)
    if e.load is not None and e.kind not in ("tool", "fixed_tool"):
        taken.add(f"{name}_load".upper())
    return name


def rapid_name(name: str, kind: str, number: int, taken: set[str],
               max_chars: int = IDENT_CHARS) -> str:
    """A RAPID identifier for ``name``: ASCII letters, digits and ``_``, a letter first, at most
    ``max_chars`` characters, no reserved word, unique (case-insensitive) among ``taken``.

    Examples
    --------
    >>> rapid_name("Gripper A (left)", "tool", 3, set())
    'Gripper_A_left'
    >>> rapid_name("", "workpiece", 2, set()), rapid_name("3D probe", "tool", 1, set())
    ('heldwobj2', 'tool_3D_probe')
    """
    ascii_name = unicodedata.normalize("NFKD", name).encode("ascii", "ignore").decode()
    ident = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", ascii_name)).strip("_")
    if not ident:
        ident = f"{_PREFIX[kind]}{number}"
    elif not ident[0].isalpha():
        ident = f"{_PREFIX[kind]}_{ident}"
    ident = ident[:max_chars]
    candidate, k = ident, 1
    while candidate.upper() in _RESERVED or candidate.upper() in taken:
        k += 1
        suffix = f"_{k}"
        candidate = ident[: max_chars - len(suffix)] + suffix
    taken.add(candidate.upper())
    return candidate


def _tag_name(name: str) -> str:
    return one_line(name).replace('"', "'")


def _string(text: str) -> str:
    """A RAPID string literal (quotes and backslashes cannot be written: they become ')."""
    return '"' + one_line(text).replace('"', "'").replace("\\", "/") + '"'


def _declaration(e: FrameEntry, name: str, indent: str = "  ") -> list[str]:
    """The tag comment and the PERS declaration(s) of one entry."""
    out = [f'{indent}! pendant: {e.kind} {e.number} "{_tag_name(e.name)}"']
    if e.kind in ("tool", "fixed_tool"):
        held = "TRUE" if e.kind == "tool" else "FALSE"
        out.append(f"{indent}PERS tooldata {name}:=[{held},{_pose(e.pose)},{_load(e.load)}];")
        return out
    held = "TRUE" if e.kind == "workpiece" else "FALSE"
    prog, unit = ("FALSE", e.mech_unit or "") if e.kind == "coordinated_base" else ("TRUE", "")
    out.append(f"{indent}PERS wobjdata {name}:=[{held},{prog},{_string(unit)},{_pose(e.pose)},"
               "[[0,0,0],[1,0,0,0]]];")
    if e.load is not None:
        out.append(f"{indent}PERS loaddata {name}_load:={_load(e.load)};  ! use with GripLoad")
    return out


def export_abb(entries: Iterable[FrameEntry], module_name: str = "CalibData",
               template: str | None = None) -> str:
    """A RAPID module declaring one PERS ``tooldata`` / ``wobjdata`` per entry, or the
    imported module (``template``) with only the changed values patched in.

    Orientations are quaternions scalar first (``abb_from_matrix``, q1 >= 0); numbers are
    written with the shortest exact digits, so ``import_abb`` gives back every pose to 1e-9.
    A load lighter than 1 g is written as 0.001 kg (ABB refuses a zero tool mass).

    Parameters
    ----------
    entries : iterable of FrameEntry
    module_name : str
        The RAPID module name (an identifier).
    template : str, optional
        The module imported before: its declarations of unchanged slots, comments, other
        data, routines and order stay byte for byte; a changed slot's numbers are patched
        in place (numbers whose value did not change keep their digits).

    Raises
    ------
    FormatError
        ``("module_name",)`` for a name that is no RAPID identifier;
        ``("entries", i, "number")`` when two entries share a slot.

    Examples
    --------
    >>> text = export_abb([FrameEntry(1, "pointer", "tool", Pose(0, 0, 180, 90, 0, 0))])
    >>> print(text, end="")  # doctest: +ELLIPSIS
    MODULE CalibData
    ...
      ! pendant: tool 1 "pointer"
      PERS tooldata pointer:=[TRUE,[[0,0,180],[0.707106781186548,0,0,0.707106781186548]],[0.001,[0,0,0.001],[1,0,0,0],0,0,0]];
    ENDMODULE
    """
    entries = list(entries)
    if template is not None:
        return _patch(template, entries)
    if not isinstance(module_name, str) or not _IDENT.fullmatch(module_name) \
            or len(module_name) > IDENT_CHARS or module_name.upper() in _RESERVED:
        raise FormatError(("module_name",),
                          f"must be a RAPID identifier (a letter, then letters, digits or _; "
                          f"at most {IDENT_CHARS}), got {module_name!r}")
    check_unique_slots(entries, {"robot_held": 10**9, "stationary": 10**9}, "ABB")
    taken: set[str] = {module_name.upper()}
    lines = [
        f"MODULE {module_name}",
        "  ! Tool and work object data written by pendant (docs/formats.md).",
        "  ! mm and kg; orientations [q1,q2,q3,q4] with q1 the scalar.",
        f"  ! A load of {UNKNOWN_LOAD} means the load is not known: set it before running.",
    ]
    groups = (("tool", "Tools (robot-held)"), ("fixed_tool", "Stationary tools"),
              ("workpiece", "Work objects held by the robot"), ("base", "Work objects (bases)"),
              ("coordinated_base", "Work objects moved by a mechanical unit (coordinated)"))
    for kind, title in groups:
        chosen = sorted((e for e in entries if e.kind == kind), key=lambda e: e.number)
        if not chosen:
            continue
        lines += ["", f"  ! {title}"]
        for e in chosen:
            lines += _declaration(e, _ident_for(e, taken))
    lines.append("ENDMODULE")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- import

_NUM = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"  # ASCII digits; linear
_TOKEN = re.compile(r'\s*(?:(\[)|(\])|(,)|(' + _NUM + r')(?![\w.])|("[^"]*")|([A-Za-z_]\w*)|(\S))')
_DECL = re.compile(
    r"\b(?:(?:LOCAL|TASK)\s+)*(PERS|CONST|VAR)\s+(tooldata|wobjdata|loaddata)\s+"
    r"([A-Za-z]\w*)\s*(\{[^}]*\})?\s*",
    re.IGNORECASE)
#: words that start a declaration, a routine or the module's end: never inside a value, so a
#: value that reaches one lacks its ';'
_STATEMENT_WORDS = frozenset({"PERS", "VAR", "CONST", "LOCAL", "TASK", "PROC", "FUNC", "TRAP",
                              "RECORD", "ALIAS", "ENDMODULE", "ENDPROC", "ENDFUNC", "ENDTRAP"})
_ROUTINE = re.compile(r"^[ \t]*(?:LOCAL[ \t]+)?(PROC|TRAP|FUNC[ \t]+\w+)[ \t]+([A-Za-z]\w*)",
                      re.IGNORECASE | re.MULTILINE)
_ENDROUTINE = re.compile(r"^[ \t]*(ENDPROC|ENDTRAP|ENDFUNC)\b", re.IGNORECASE | re.MULTILINE)
MODULE_LINE = re.compile(r"^[ \t]*MODULE\s+([A-Za-z]\w*)", re.IGNORECASE | re.MULTILINE)
_ENDMODULE = re.compile(r"^[ \t]*ENDMODULE\b", re.IGNORECASE | re.MULTILINE)


@dataclass
class _Tok:
    kind: str  # "[", "]", ",", "num", "str", "word", "other"
    text: str
    line: int
    start: int = 0
    end: int = 0


class _NotLiteral(FormatError):
    """A value pendant cannot evaluate (a reference, a function call): skipped, not refused."""


@dataclass
class _Decl:
    dtype: str
    name: str
    line: int
    value: object  # nested lists of float / bool / str
    tag: tuple[str, int, str, int] | None  # kind, number, name, line of the tag
    start: int = 0  # offset of the declaration (storage class) in the text
    end: int = 0  # offset after its ';'
    leaves: list[_Tok] = field(default_factory=list)  # the literal values in order


@dataclass
class _Found:
    decl: _Decl
    kind: str
    pose: Pose
    load: LoadData | None
    unit: str | None = None
    oframe: np.ndarray | None = None
    load_decl: _Decl | None = None


def _strip_comments(text: str) -> str:
    """Text with every ``!`` comment blanked (same length, so offsets keep their lines)."""
    out = []
    for raw in text.split("\n"):
        in_string = False
        cut = len(raw)
        for i, c in enumerate(raw):
            if c == '"':
                in_string = not in_string
            elif c == "!" and not in_string:
                cut = i
                break
        out.append(raw[:cut] + " " * (len(raw) - cut))
    return "\n".join(out)


def _tokens(text: str, start: int, line_of, decl_line: int, name: str) -> tuple[list[_Tok], int]:
    """Tokens of a value from ``start`` up to its closing ``;`` (returns the offset after it)."""
    kinds = ("[", "]", ",", "num", "str", "word", "other")
    toks: list[_Tok] = []
    pos = start
    while True:
        m = _TOKEN.match(text, pos)
        if not m:
            raise FormatError.at_line(decl_line, name, "no ';' ends this declaration")
        k = m.lastindex
        kind = kinds[k - 1]  # type: ignore[operator]
        pos = m.end()
        if kind == "other" and m.group(k) == ";":
            return toks, pos
        if kind == "word" and m.group(k).upper() in _STATEMENT_WORDS:
            end_line = toks[-1].line if toks else decl_line
            raise FormatError.at_line(end_line, name, f"no ';' ends this declaration (begun on "
                                      f"line {decl_line}): line {line_of(m.start(k))} starts "
                                      f"with {m.group(k)} before it")
        toks.append(_Tok(kind, m.group(k), line_of(m.start(k)), m.start(k), m.end(k)))


MAX_NESTING = 16  # brackets a value nests (a tooldata 3, an array of them 4): the reader recurses


def _parse_value(toks: list[_Tok], name: str, decl_line: int) -> object:
    def value(i: int, depth: int = 1) -> tuple[object, int]:
        if i >= len(toks):
            raise FormatError.at_line(decl_line, name, "value ends early")
        t = toks[i]
        if t.kind == "[" and depth > MAX_NESTING:
            raise FormatError.at_line(t.line, name, f"the value nests brackets more than "
                                      f"{MAX_NESTING} deep (RAPID data nests a few levels)")
        if t.kind == "[":
            items: list[object] = []
            i += 1
            if i < len(toks) and toks[i].kind == "]":
                return items, i + 1
            while True:
                item, i = value(i, depth + 1)
                items.append(item)
                if i < len(toks) and toks[i].kind == ",":
                    i += 1
                elif i < len(toks) and toks[i].kind == "]":
                    return items, i + 1
                else:
                    line = toks[i].line if i < len(toks) else decl_line
                    got = toks[i].text if i < len(toks) else "';'"
                    if i < len(toks) and toks[i].kind in ("word", "other"):
                        raise _NotLiteral.at_line(line, name, "only literal values can be "
                                                  f"read, got {got!r}")
                    raise FormatError.at_line(line, name, f"expected ',' or ']', got {got}")
        if t.kind == "num":
            return float(t.text), i + 1
        if t.kind == "str":
            return t.text[1:-1], i + 1
        if t.kind == "word" and t.text.upper() in ("TRUE", "FALSE"):
            return t.text.upper() == "TRUE", i + 1
        raise _NotLiteral.at_line(t.line, name, f"only literal values can be read, got {t.text!r}")

    if not toks:
        raise FormatError.at_line(decl_line, name, "no value after ':='")
    v, end = value(0)
    if end != len(toks):
        if toks[end].kind in ("word", "other"):
            raise _NotLiteral.at_line(toks[end].line, name, "only literal values can be read, "
                                      f"got {toks[end].text!r} after the value")
        raise FormatError.at_line(toks[end].line, name,
                                  f"unexpected {toks[end].text!r} after the value")
    return v


def _module_span(text: str, code: str) -> tuple[int, int]:
    """Offsets of ``MODULE`` and of ``ENDMODULE``; a file cut short is refused."""
    n_lines = text.count("\n") + (0 if text.endswith("\n") else 1)
    m = MODULE_LINE.search(code)
    if not m:
        raise FormatError.at_line(1, "MODULE", "no MODULE: a whole RAPID module is needed "
                                  "(MODULE name ... ENDMODULE)")
    e = _ENDMODULE.search(code, m.end())
    if not e:
        raise FormatError.at_line(n_lines, "ENDMODULE", f"the module ends at line {n_lines} "
                                  "without ENDMODULE: it was cut short")
    rest = code[e.end():].strip()
    if rest:
        line = code.count("\n", 0, e.end() + code[e.end():].index(rest[0])) + 1
        raise FormatError.at_line(line, "ENDMODULE", "text after ENDMODULE")
    return m.start(), e.start()


def _declarations(text: str) -> tuple[list[_Decl], list[Skipped], int]:
    """Declarations with their values, the skipped ones, and the offset of ENDMODULE."""
    lines = text.split("\n")
    starts = np.cumsum([0] + [len(s) + 1 for s in lines])

    def line_of(offset: int) -> int:
        return int(np.searchsorted(starts, offset, side="right"))

    tags: dict[int, tuple[str, int, str, int]] = {}
    for n, raw in enumerate(lines, start=1):
        m = _TAG.match(raw)
        if m:
            tags[n] = (m.group(1).lower(), index_number(m.group(2), n, "! pendant:"),
                       m.group(3).strip(), n)
    code = _strip_comments(text)
    begin, endmodule = _module_span(text, code)
    routines = _routines(code, begin, endmodule)
    decls: list[_Decl] = []
    skipped: list[Skipped] = []
    pos, last_line = begin, 0
    while True:
        m = _DECL.search(code, pos, endmodule)
        if not m:
            return decls, skipped, endmodule
        line = line_of(m.start())
        dtype, name, array = m.group(2).lower(), m.group(3), m.group(4)
        after = m.end()
        inside = next((r for r in routines if r[0] <= m.start() < r[2]), None)
        if inside is not None:
            start, header_end, _, kind, routine = inside
            if m.start() < header_end:
                pos = after
                skipped.append(Skipped(line, name, f"a parameter of {kind} {routine}: the "
                                       "routine's argument, not a frame of the controller"))
            else:
                end = code.find(";", after)
                pos = after if end < 0 else end + 1
                skipped.append(Skipped(line, name, f"{dtype} declared inside {kind} {routine}: "
                                       "routine data, not a frame of the controller"))
            last_line = line
            continue
        if array:
            end = code.find(";", after)
            pos = after if end < 0 else end + 1
            skipped.append(Skipped(line, name, f"an array of {dtype}: declare one per name"))
            last_line = line
            continue
        if code.startswith(":=", after):
            toks, pos = _tokens(code, after + 2, line_of, line, name)
            try:
                value = _parse_value(toks, name, line)
            except _NotLiteral as err:
                skipped.append(Skipped(err.line or line, name, err.reason))
                last_line = line
                continue
        elif code.startswith(";", after):
            pos = after + 1
            skipped.append(Skipped(line, name, f"a {dtype} declared without a value"))
            last_line = line
            continue
        else:
            raise FormatError.at_line(line, name, "expected ':=' or ';' after the name")
        tag = None
        if dtype != "loaddata":
            pending = [n for n in tags if last_line < n < line]
            tag = tags[max(pending)] if pending else None
        leaves = [t for t in toks if t.kind in ("num", "str", "word")]
        decls.append(_Decl(dtype, name, line, value, tag, m.start(), pos, leaves))
        last_line = line


def _routines(code: str, begin: int, endmodule: int) -> list[tuple[int, int, int, str, str]]:
    """(start, end of the header, end, kind, name) of each PROC, FUNC and TRAP."""
    out = []
    pos = begin
    while True:
        m = _ROUTINE.search(code, pos, endmodule)
        if not m:
            return out
        kind = m.group(1).split()[0].upper()
        header_end = m.end()
        rest = code[m.end():endmodule]
        if rest.lstrip().startswith("("):
            close = code.find(")", m.end(), endmodule)
            header_end = endmodule if close < 0 else close + 1
        e = _ENDROUTINE.search(code, header_end, endmodule)
        end = endmodule if e is None else e.end()
        out.append((m.start(), header_end, end, kind, m.group(2)))
        pos = end


def _nums(v: object, n: int, line: int, field: str, unit: str | None = None) -> list[float]:
    if not (isinstance(v, list) and len(v) == n and all(isinstance(x, float) for x in v)):
        raise FormatError.at_line(line, field, f"expected [{', '.join(['num'] * n)}]")
    if unit is not None:
        for i, x in enumerate(v):
            try:
                check_value(x, unit, (field,))
            except CalibrationError as err:
                raise FormatError.at_line(line, f"{field}[{i + 1}]", err.reason) from None
    return v  # type: ignore[return-value]


def _read_pose(v: object, line: int, field: str) -> np.ndarray:
    if not (isinstance(v, list) and len(v) == 2):
        raise FormatError.at_line(line, field, "expected [[x,y,z],[q1,q2,q3,q4]]")
    pos = _nums(v[0], 3, line, f"{field}.trans", "mm")
    q = np.array(_nums(v[1], 4, line, f"{field}.rot"))
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise FormatError.at_line(line, f"{field}.rot",
                                  f"quaternion has length {norm:.6g}; it must be 1")
    return matrix_from_abb(pos, q / norm)


def _pose_of(T: np.ndarray) -> Pose:
    """Pose with the exact translation and A, B, C rounded to 1e-9 deg (drops float dust);
    -180 is written 180 so that a second round trip gives the same numbers."""
    abc = np.round(kuka_from_matrix(T)[3:], 9) + 0.0
    abc[abc == -180.0] = 180.0
    return Pose(*(float(x) for x in T[:3, 3]), *(float(a) for a in abc))


def read_load(v: object, line: int, field: str,
               warnings: list[Skipped] | None = None) -> LoadData | None:
    shape = "[mass,[cx,cy,cz],[q1,q2,q3,q4],ix,iy,iz]"
    if not (isinstance(v, list) and len(v) == 6):
        raise FormatError.at_line(line, field, f"expected {shape}")
    mass = v[0]
    cog = _nums(v[1], 3, line, f"{field}.cog", "mm")
    aom = _nums(v[2], 4, line, f"{field}.aom")
    inertia = _nums(v[3:], 3, line, f"{field}.ix")
    if not isinstance(mass, float):
        raise FormatError.at_line(line, f"{field}.mass", "expected a number")
    if (mass, tuple(cog), tuple(aom), *inertia) == _UNKNOWN:
        return None
    if mass < 0:
        if warnings is not None:
            warnings.append(Skipped(line, f"{field}.mass", f"mass {rapid_num(mass)}: no load "
                                    "RobotWare takes; read as a load not set (as KUKA's M -1), "
                                    "the frame is imported"))
        return None
    for fld, x, unit in ((f"{field}.mass", mass, "kg"), (f"{field}.ix", inertia[0], "kgm2"),
                         (f"{field}.iy", inertia[1], "kgm2"), (f"{field}.iz", inertia[2], "kgm2")):
        try:
            check_value(x, unit, (fld,))
        except CalibrationError as err:
            raise FormatError.at_line(line, fld, err.reason) from None
    axes = _pose_of(_read_pose([[0.0, 0.0, 0.0], aom], line, f"{field}.aom"))
    return LoadData(mass, tuple(cog), tuple(inertia),  # type: ignore[arg-type]
                    (axes.a, axes.b, axes.c))


def read_declarations(text: str) -> tuple[list[_Found], list[FrameEntry], list[Skipped],
                                         list[_Decl], int]:
    if not isinstance(text, str):
        raise FormatError(("file",), f"expected text, got {type(text).__name__}")
    decls, skipped, endmodule = _declarations(text)
    loads = {d.name.upper(): d for d in decls if d.dtype == "loaddata"}
    found: list[_Found] = []
    for d in decls:
        v, line, name = d.value, d.line, d.name
        if d.dtype == "tooldata":
            if not (isinstance(v, list) and len(v) == 3 and isinstance(v[0], bool)):
                raise FormatError.at_line(line, name,
                                          "expected [robhold,[[x,y,z],[q1,q2,q3,q4]],[tload]]")
            pose = _pose_of(_read_pose(v[1], line, f"{name}.tframe"))
            load = read_load(v[2], line, f"{name}.tload", skipped)
            found.append(_Found(d, "tool" if v[0] else "fixed_tool", pose, load))
        elif d.dtype == "wobjdata":
            if not (isinstance(v, list) and len(v) == 5 and isinstance(v[0], bool)
                    and isinstance(v[1], bool) and isinstance(v[2], str)):
                raise FormatError.at_line(line, name,
                                          'expected [robhold,ufprog,"ufmec",[uframe],[oframe]]')
            unit = v[2].strip() or None
            if not v[1] and (v[0] or unit is None):
                why = ("a work object held by the robot cannot also be moved by a unit"
                       if v[0] else "ufprog FALSE but no mechanical unit in ufmec")
                skipped.append(Skipped(line, f"{name}.ufprog", why))
                continue
            if v[1]:
                unit = None
            oframe = _read_pose(v[4], line, f"{name}.oframe")
            T = _read_pose(v[3], line, f"{name}.uframe") @ oframe
            load, load_decl = None, loads.get(f"{name.upper()}_LOAD")
            if v[0] and load_decl is not None:
                load = read_load(load_decl.value, load_decl.line, load_decl.name, skipped)
            kind = "workpiece" if v[0] else ("coordinated_base" if unit else "base")
            found.append(_Found(d, kind, _pose_of(T), load, unit, oframe,
                                load_decl if v[0] else None))
    return found, _numbered(found), skipped, decls, endmodule


def read_abb(text: str) -> ParsedFile:
    """Tools, stationary tools and work objects declared in a whole RAPID module.

    Reads every ``PERS``/``CONST``/``VAR`` (optionally ``LOCAL``/``TASK``) ``tooldata`` and
    ``wobjdata`` with a literal value between ``MODULE`` and ``ENDMODULE``: numbers in any
    notation, TRUE/FALSE, free spacing and line breaks, ``!`` comments. A work object's pose
    is ``uframe * oframe``; one moved by a mechanical unit (``ufprog FALSE``, ``ufmec
    "STN1"``) is a ``coordinated_base`` of that unit. A ``loaddata`` named ``<wobj>_load``
    is the load of the robot-held work object ``<wobj>``; a stationary tool keeps its tload.
    Numbers and names come from ``! pendant:`` comments when present; otherwise the RAPID
    name is the name and numbers follow the file order per family. Arrays, values that are
    not literal and declarations without a value are skipped and listed.

    Raises
    ------
    FormatError
        ``("file", "line N", "<data name>.<field>")`` for a value of the wrong shape, a number
        beyond server/service/bounds.py, a quaternion far from unit length, two declarations tagged
        with one slot; a file without ``MODULE`` or cut before ``ENDMODULE``.
    """
    text = text.replace("\r\n", "\n").replace("\r", "\n") if isinstance(text, str) else text
    found, entries, skipped, _, _ = read_declarations(text)  # type: ignore[arg-type]
    where = {(family_of(e.kind), e.number): f.decl.line for f, e in zip(found, entries)}
    return ParsedFile(canonical_order(entries), sorted(skipped, key=lambda k: k.line), [], where)


def import_abb(text: str) -> list[FrameEntry]:
    """The entries of :func:`read_abb`, in canonical order.

    Examples
    --------
    >>> e = import_abb('MODULE M\\nPERS tooldata tPen:=[TRUE,[[0,0,1.2E2],[1,0,0,0]],'
    ...                '[0.5,[0,0,40],[1,0,0,0],0,0,0]];\\nENDMODULE')[0]
    >>> e.name, e.kind, e.pose.z, e.load.mass_kg
    ('tPen', 'tool', 120.0, 0.5)
    """
    return read_abb(text).entries


def _numbered(found: list[_Found]) -> list[FrameEntry]:
    used: dict[tuple[str, int], int] = {}
    numbers: dict[int, tuple[int, str]] = {}
    for i, f in enumerate(found):
        d, kind = f.decl, f.kind
        if d.tag is None:
            continue
        tag_kind, number, tag_name, tag_line = d.tag
        if tag_kind != kind:
            raise FormatError.at_line(tag_line, d.name,
                                      f"comment says {tag_kind} but the data is a {kind}")
        family = family_of(kind)
        if number < 1:
            raise FormatError.at_line(tag_line, d.name, "slot numbers start at 1")
        if (family, number) in used:
            raise FormatError.at_line(tag_line, d.name, f"{kind} {number} already used "
                                      f"on line {used[(family, number)]}")
        try:
            check_name(tag_name, (d.name,))
        except CalibrationError as err:
            raise FormatError.at_line(tag_line, f"{d.name}.name", err.reason) from None
        used[(family, number)] = tag_line
        numbers[i] = (number, tag_name)
    out = []
    for i, f in enumerate(found):
        if i in numbers:
            number, name = numbers[i]
        else:
            family = family_of(f.kind)
            number = 1
            while (family, number) in used:
                number += 1
            used[(family, number)] = f.decl.line
            name = f.decl.name
        try:
            out.append(FrameEntry(number, name, f.kind, f.pose, f.load,  # type: ignore[arg-type]
                                  f.unit))
        except CalibrationError as err:
            raise FormatError.at_line(f.decl.line, f"{f.decl.name}.{err.loc[-1]}",
                                      err.reason) from None
    return out


# --------------------------------------------------------------------------- patching


def _leaf_text(tok: _Tok, want: object) -> str:
    """The literal for ``want`` if it differs from the token's value, else the token."""
    if tok.kind == "num":  # an unchanged number (or one off by float dust) keeps its digits
        return tok.text if abs(float(tok.text) - want) <= NOISE else rapid_num(want)  # type: ignore
    if tok.kind == "str":
        return tok.text if tok.text[1:-1] == want else _string(str(want))
    return tok.text if (tok.text.upper() == "TRUE") == want else ("TRUE" if want else "FALSE")


def _old_leaf_values(d: _Decl) -> list[object]:
    out: list[object] = []
    for t in d.leaves:
        out.append(float(t.text) if t.kind == "num" else
                   t.text[1:-1] if t.kind == "str" else t.text.upper() == "TRUE")
    return out


NOISE = 1e-9  # mm, or a quaternion component: a difference below it is float dust


def _clean(x: float) -> float:
    """``x`` with float dust (|x| < 1e-9) written as the zero it is."""
    return 0.0 if abs(x) < NOISE else float(x) + 0.0


def _pose_leaves(T: np.ndarray, old: list[object], same_rotation: bool) -> list[object]:
    q = list(old[3:7]) if same_rotation else [_clean(x) for x in _quat(T)]
    return [_clean(x) for x in T[:3, 3]] + q


def _is_identity(leaves: list[object]) -> bool:
    return leaves == [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


def _load_leaves(load: LoadData | None, old: list[object], old_load: LoadData | None) -> list:
    if load == old_load:
        return old
    if load is None:
        return [_UNKNOWN[0], *_UNKNOWN[1], *_UNKNOWN[2], *_UNKNOWN[3:]]
    if old_load is not None and old_load.inertia_axes_deg == load.inertia_axes_deg:
        aom = list(old[4:8])
    else:
        aom = [float(x) for x in _quat(Pose(0, 0, 0, *load.inertia_axes_deg).as_matrix())]
    return [max(load.mass_kg, MIN_TOOL_MASS_KG), *load.com_mm, *aom, *load.inertia_kgm2]


def _target_leaves(f: _Found, old_entry: FrameEntry, e: FrameEntry) -> list[object] | None:
    """The new literal values of ``f``'s declaration, or None when its data type changes."""
    old = _old_leaf_values(f.decl)
    same_rot = (old_entry.pose.a, old_entry.pose.b, old_entry.pose.c) == (e.pose.a, e.pose.b,
                                                                           e.pose.c)
    if f.decl.dtype == "tooldata" and e.kind in ("tool", "fixed_tool"):
        pose = old[1:8] if old_entry.pose == e.pose else _pose_leaves(
            e.pose.as_matrix(), old[1:8], same_rot)
        return [e.kind == "tool", *pose, *_load_leaves(e.load, old[8:], old_entry.load)]
    if f.decl.dtype == "wobjdata" and e.kind not in ("tool", "fixed_tool") and (
            (e.kind == "workpiece") == (f.kind == "workpiece")):
        uframe, oframe_leaves = old[3:10], old[10:]
        if old_entry.pose != e.pose and _is_identity(old[3:10]) and not _is_identity(old[10:]):
            # a work object defined by its oframe (uframe the identity): the change goes there
            oframe_leaves = _pose_leaves(e.pose.as_matrix(), old[10:17], same_rot)
        elif old_entry.pose != e.pose and same_rot and not _is_identity(old[10:]):
            # uframe and oframe both set, the rotation kept: the uframe keeps its rotation
            # (and its quaternion's text) and its origin moves as the pose's does (no inverse)
            shift = e.pose.as_array()[:3] - old_entry.pose.as_array()[:3]
            uframe = [_clean(round(u + d, 9)) for u, d in zip(old[3:6], shift)] + list(old[6:10])
        elif old_entry.pose != e.pose:
            oframe = np.eye(4) if f.oframe is None else f.oframe
            T = e.pose.as_matrix() @ np.linalg.inv(oframe)
            uframe = _pose_leaves(T, old[3:10], same_rot and _is_identity(old[10:]))
        unit = e.mech_unit if e.kind == "coordinated_base" else ""
        return [e.kind == "workpiece", e.kind != "coordinated_base", unit, *uframe,
                *oframe_leaves]
    return None


def _line_start(text: str, offset: int) -> int:
    return text.rfind("\n", 0, offset) + 1


def _line_end(text: str, offset: int) -> int:
    end = text.find("\n", offset)
    return len(text) if end < 0 else end + 1


class _Lines:
    """The template's own line ends: offsets in its ``\\n`` text mapped back to the template,
    and the ending of each line (a mixed file keeps every line's own)."""

    def __init__(self, template: str):
        parts = re.split(r"(\r\n|\r|\n)", template)
        self.contents, self.ends = parts[0::2], parts[1::2] + [""]
        self.text = "\n".join(self.contents)
        self.norm = np.cumsum([0] + [len(c) + 1 for c in self.contents])
        self.orig = np.cumsum([0] + [len(c) + len(e) for c, e in zip(self.contents, self.ends)])
        counts = {e: self.ends.count(e) for e in ("\r\n", "\n", "\r")}
        self.common = max(counts, key=counts.get) if any(counts.values()) else "\n"  # type: ignore

    def _line(self, offset: int) -> int:
        return int(np.searchsorted(self.norm, offset, side="right")) - 1

    def offset(self, offset: int) -> int:
        i = self._line(offset)
        return int(self.orig[i]) + offset - int(self.norm[i])

    def ending(self, offset: int) -> str:
        """The ending of the line at ``offset`` (the file's most common for the last line)."""
        return self.ends[self._line(offset)] or self.common


def _patch(template: str, entries: list[FrameEntry]) -> str:
    src = _Lines(template)
    text = src.text
    found, old_entries, _, decls, endmodule = read_declarations(text)
    check_unique_slots(entries, {"robot_held": 10**9, "stationary": 10**9}, "ABB")
    new = {(family_of(e.kind), e.number): e for e in entries}
    old = {(family_of(e.kind), e.number): (f, e) for f, e in zip(found, old_entries)}
    if all(new.get(k) == e for k, (_, e) in old.items()) and set(new) == set(old):
        return template
    edits: list[tuple[int, int, str]] = []
    taken = {d.name.upper() for d in decls}
    untagged_removed = {k[0] for k, (f, _) in old.items() if k not in new and f.decl.tag is None}
    for key, (f, was) in old.items():
        e = new.get(key)
        if e == was:
            continue
        d = f.decl
        indent = text[_line_start(text, d.start):d.start]
        indent = indent if not indent.strip() else "  "
        if e is None:  # the slot was emptied: its declaration goes
            first = d.tag[3] if d.tag else d.line
            start = _line_start(text, d.start) if not d.tag else _offset_of_line(text, first)
            edits.append((start, _line_end(text, d.end - 1), ""))
            if f.load_decl is not None:
                ld = f.load_decl
                edits.append((_line_start(text, ld.start), _line_end(text, ld.end - 1), ""))
            continue
        leaves = _target_leaves(f, was, e)
        if leaves is None:
            name = d.name
            body = _declaration(e, name, "")[1:]
            edits.append((d.start, d.end, body[0]))
        else:
            for tok, want in zip(d.leaves, leaves):
                text_new = _leaf_text(tok, want)
                if text_new != tok.text:
                    edits.append((tok.start, tok.end, text_new))
        if (was.name, was.kind) != (e.name, e.kind) or d.tag is None and (
                was.name != d.name or key[0] in untagged_removed):
            tag = f'! pendant: {e.kind} {e.number} "{_tag_name(e.name)}"'
            if d.tag:
                s0 = _offset_of_line(text, d.tag[3])
                e0 = _line_end(text, s0) - 1
                lead = text[s0:e0][:len(text[s0:e0]) - len(text[s0:e0].lstrip())]
                edits.append((s0, e0, lead + tag))
            else:
                s0 = _line_start(text, d.start)
                edits.append((s0, s0, indent + tag + "\n"))
        if e.kind == "workpiece" and (was.load != e.load or leaves is None):
            ld = f.load_decl
            if ld is not None and e.load is not None:
                for tok, want in zip(ld.leaves, _load_leaves(e.load, _old_leaf_values(ld),
                                                             was.load)):
                    if _leaf_text(tok, want) != tok.text:
                        edits.append((tok.start, tok.end, _leaf_text(tok, want)))
            elif ld is not None:
                edits.append((_line_start(text, ld.start), _line_end(text, ld.end - 1), ""))
            elif e.load is not None:
                after = _line_end(text, d.end - 1)
                edits.append((after, after, f"{indent}PERS loaddata {d.name}_load:="
                                            f"{_load(e.load)};  ! use with GripLoad\n"))
    # numbers of untagged declarations follow the file order: once one of a family is gone,
    # the later untagged ones of that family get their number written in a tag
    for key, (f, was) in old.items():
        if key[0] in untagged_removed and f.decl.tag is None and new.get(key) == was:
            d = f.decl
            s0 = _line_start(text, d.start)
            lead = text[s0:d.start] if not text[s0:d.start].strip() else "  "
            edits.append((s0, s0, f'{lead}! pendant: {was.kind} {was.number} '
                                  f'"{_tag_name(was.name)}"\n'))
    added = [e for k, e in sorted(new.items()) if k not in old]
    if added:
        at = _line_start(text, endmodule)
        body = []
        for e in canonical_order(added):
            body += _declaration(e, _ident_for(e, taken))
        edits.append((at, at, "\n".join(body) + "\n"))
    out = template
    for start, end, repl in sorted(edits, key=lambda x: (x[0], x[1]), reverse=True):
        eol = src.ending(start)
        out = out[:src.offset(start)] + repl.replace("\n", eol) + out[src.offset(end):]
    return out


def _offset_of_line(text: str, line: int) -> int:
    pos = 0
    for _ in range(line - 1):
        pos = text.index("\n", pos) + 1
    return pos
