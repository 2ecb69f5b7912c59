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
- ``base``: wobjdata, robhold FALSE, ufprog TRUE, ufmec "", uframe = T_world_base, oframe identity.

ABB refuses a tool mass of 0, so a tool without a known load is written with ABB's own
minimum load ``[0.001,[0,0,0.001],[1,0,0,0],0,0,0]`` (that of ``tool0``), and that load
reads back as "no load". Each declaration is preceded by ``! pendant: <kind> <number>
"<name>"`` so numbers and names survive RAPID's identifier rules; files without these
comments are numbered in file order.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from solvers.frames import Pose, abb_from_matrix, kuka_from_matrix, matrix_from_abb

from server.formats.model import (
    ROBOT_HELD,
    FormatError,
    FrameEntry,
    LoadData,
    canonical_order,
    check_unique_slots,
)

__all__ = ["export_abb", "import_abb", "rapid_name", "MIN_TOOL_MASS_KG", "UNKNOWN_LOAD"]

MIN_TOOL_MASS_KG = 0.001
UNKNOWN_LOAD = "[0.001,[0,0,0.001],[1,0,0,0],0,0,0]"  # tool0's load: ABB's "nothing known"
_UNKNOWN = (0.001, (0.0, 0.0, 0.001), (1.0, 0.0, 0.0, 0.0), 0.0, 0.0, 0.0)
IDENT_CHARS = 32
QUAT_NORM_TOL = 1e-3
_PREFIX = {"tool": "tool", "fixed_tool": "stattool", "workpiece": "heldwobj", "base": "wobj"}
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
_TAG = re.compile(r'^\s*!\s*pendant:\s*(tool|fixed_tool|workpiece|base)\s+(\d+)\s+"(.*)"\s*$',
                  re.IGNORECASE)


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
    return "".join("'" if c == '"' else (" " if ord(c) < 32 else c) for c in name)


def export_abb(entries: Iterable[FrameEntry], module_name: str = "CalibData") -> str:
    """A RAPID module declaring one PERS ``tooldata`` / ``wobjdata`` per entry.

    Orientations are quaternions scalar first (``abb_from_matrix``, q1 >= 0); numbers are
    written with the shortest exact digits, so ``import_abb`` gives back every pose to 1e-9.
    A load lighter than 1 g is written as 0.001 kg (ABB refuses a zero tool mass).

    Parameters
    ----------
    entries : iterable of FrameEntry
    module_name : str
        The RAPID module name (an identifier).

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
              ("workpiece", "Work objects held by the robot"), ("base", "Work objects (bases)"))
    for kind, title in groups:
        chosen = sorted((e for e in entries if e.kind == kind), key=lambda e: e.number)
        if not chosen:
            continue
        lines += ["", f"  ! {title}"]
        for e in chosen:
            limit = IDENT_CHARS - len("_load") if kind == "workpiece" else IDENT_CHARS
            name = rapid_name(e.name, kind, e.number, taken, limit)
            lines.append(f'  ! pendant: {kind} {e.number} "{_tag_name(e.name)}"')
            if kind == "tool":
                lines.append(f"  PERS tooldata {name}:=[TRUE,{_pose(e.pose)},{_load(e.load)}];")
            elif kind == "fixed_tool":
                lines.append(f"  PERS tooldata {name}:=[FALSE,{_pose(e.pose)},{UNKNOWN_LOAD}];")
            else:
                held = "TRUE" if kind == "workpiece" else "FALSE"
                lines.append(f'  PERS wobjdata {name}:=[{held},TRUE,"",{_pose(e.pose)},'
                             "[[0,0,0],[1,0,0,0]]];")
                if e.load is not None:
                    taken.add(f"{name}_load".upper())
                    lines.append(f"  PERS loaddata {name}_load:={_load(e.load)};"
                                 "  ! use with GripLoad")
    lines.append("ENDMODULE")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- import

_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_TOKEN = re.compile(r'\s*(?:(\[)|(\])|(,)|(' + _NUM + r')(?![\w.])|("[^"]*")|([A-Za-z_]\w*)|(\S))')
_DECL = re.compile(
    r"\b(?:(?:LOCAL|TASK)\s+)*(PERS|CONST|VAR)\s+(tooldata|wobjdata|loaddata)\s+"
    r"([A-Za-z]\w*)\s*(\{[^}]*\})?\s*",
    re.IGNORECASE)


@dataclass
class _Tok:
    kind: str  # "[", "]", ",", "num", "str", "word", "other"
    text: str
    line: int


@dataclass
class _Decl:
    dtype: str
    name: str
    line: int
    value: object  # nested lists of float / bool / str
    tag: tuple[str, int, str, int] | None  # kind, number, name, line of the tag


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
        kind = kinds[m.lastindex - 1]
        pos = m.end()
        if kind == "other" and m.group(m.lastindex) == ";":
            return toks, pos
        toks.append(_Tok(kind, m.group(m.lastindex), line_of(m.start(m.lastindex))))


def _parse_value(toks: list[_Tok], name: str, decl_line: int) -> object:
    def value(i: int) -> tuple[object, int]:
        if i >= len(toks):
            raise FormatError.at_line(decl_line, name, "value ends early")
        t = toks[i]
        if t.kind == "[":
            items: list[object] = []
            i += 1
            if i < len(toks) and toks[i].kind == "]":
                return items, i + 1
            while True:
                item, i = value(i)
                items.append(item)
                if i < len(toks) and toks[i].kind == ",":
                    i += 1
                elif i < len(toks) and toks[i].kind == "]":
                    return items, i + 1
                else:
                    line = toks[i].line if i < len(toks) else decl_line
                    got = toks[i].text if i < len(toks) else "';'"
                    raise FormatError.at_line(line, name, f"expected ',' or ']', got {got}")
        if t.kind == "num":
            return float(t.text), i + 1
        if t.kind == "str":
            return t.text[1:-1], i + 1
        if t.kind == "word" and t.text.upper() in ("TRUE", "FALSE"):
            return t.text.upper() == "TRUE", i + 1
        raise FormatError.at_line(t.line, name, f"only literal values can be read, got {t.text!r}")

    if not toks:
        raise FormatError.at_line(decl_line, name, "no value after ':='")
    v, end = value(0)
    if end != len(toks):
        raise FormatError.at_line(toks[end].line, name,
                                  f"unexpected {toks[end].text!r} after the value")
    return v


def _declarations(text: str) -> list[_Decl]:
    lines = text.split("\n")
    starts = np.cumsum([0] + [len(s) + 1 for s in lines])

    def line_of(offset: int) -> int:
        return int(np.searchsorted(starts, offset, side="right"))

    tags: dict[int, tuple[str, int, str, int]] = {}
    for n, raw in enumerate(lines, start=1):
        m = _TAG.match(raw)
        if m:
            tags[n] = (m.group(1).lower(), int(m.group(2)), m.group(3).strip(), n)
    code = _strip_comments(text)
    decls: list[_Decl] = []
    pos, last_line = 0, 0
    while True:
        m = _DECL.search(code, pos)
        if not m:
            return decls
        line = line_of(m.start())
        dtype, name, array = m.group(2).lower(), m.group(3), m.group(4)
        if array:
            raise FormatError.at_line(line, name,
                                      f"arrays of {dtype} are not supported; declare one per name")
        after = m.end()
        if code.startswith(":=", after):
            toks, pos = _tokens(code, after + 2, line_of, line, name)
            value = _parse_value(toks, name, line)
        elif code.startswith(";", after):
            pos = after + 1
            last_line = line
            continue  # declared without a value: nothing to import
        else:
            raise FormatError.at_line(line, name, "expected ':=' or ';' after the name")
        tag = None
        if dtype != "loaddata":
            pending = [n for n in tags if last_line < n < line]
            tag = tags[max(pending)] if pending else None
        decls.append(_Decl(dtype, name, line, value, tag))
        last_line = line


def _nums(v: object, n: int, line: int, field: str) -> list[float]:
    if not (isinstance(v, list) and len(v) == n and all(isinstance(x, float) for x in v)):
        raise FormatError.at_line(line, field, f"expected [{', '.join(['num'] * n)}]")
    return v  # type: ignore[return-value]


def _read_pose(v: object, line: int, field: str) -> np.ndarray:
    if not (isinstance(v, list) and len(v) == 2):
        raise FormatError.at_line(line, field, "expected [[x,y,z],[q1,q2,q3,q4]]")
    pos = _nums(v[0], 3, line, f"{field}.trans")
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


def _read_load(v: object, line: int, field: str) -> LoadData | None:
    shape = "[mass,[cx,cy,cz],[q1,q2,q3,q4],ix,iy,iz]"
    if not (isinstance(v, list) and len(v) == 6):
        raise FormatError.at_line(line, field, f"expected {shape}")
    mass = v[0]
    cog, aom = _nums(v[1], 3, line, f"{field}.cog"), _nums(v[2], 4, line, f"{field}.aom")
    inertia = _nums(v[3:], 3, line, f"{field}.ix")
    if not isinstance(mass, float):
        raise FormatError.at_line(line, f"{field}.mass", "expected a number")
    if (mass, tuple(cog), tuple(aom), *inertia) == _UNKNOWN:
        return None
    if mass < 0:
        raise FormatError.at_line(line, f"{field}.mass", f"must be >= 0, got {mass}")
    if any(x < 0 for x in inertia):
        raise FormatError.at_line(line, f"{field}.ix", "moments of inertia must be >= 0")
    axes = _pose_of(_read_pose([[0.0, 0.0, 0.0], aom], line, f"{field}.aom"))
    return LoadData(mass, tuple(cog), tuple(inertia),  # type: ignore[arg-type]
                    (axes.a, axes.b, axes.c))


def import_abb(text: str) -> list[FrameEntry]:
    """Tools, stationary tools and work objects declared in a RAPID module.

    Reads every ``PERS``/``CONST``/``VAR`` (optionally ``LOCAL``/``TASK``) ``tooldata`` and
    ``wobjdata`` with a literal value: numbers in any notation, TRUE/FALSE, free spacing and
    line breaks, ``!`` comments. A work object's pose is ``uframe * oframe``. A ``loaddata``
    named ``<wobj>_load`` is the load of the robot-held work object ``<wobj>``. A stationary
    tool's tload (the gripper load, in ABB's model) is not kept: pendant stores loads on
    robot-held entries only. Numbers and names come from ``! pendant:`` comments when
    present; otherwise the RAPID name is the name and numbers follow the file order.

    Raises
    ------
    FormatError
        ``("file", "line N", "<data name>.<field>")`` for a value of the wrong shape, a
        non-literal value, a quaternion far from unit length, a work object moved by a
        mechanical unit (ufprog FALSE), or two declarations tagged with one slot.

    Examples
    --------
    >>> e = import_abb('PERS tooldata tPen:=[TRUE,[[0,0,1.2E2],[1,0,0,0]],'
    ...                '[0.5,[0,0,40],[1,0,0,0],0,0,0]];')[0]
    >>> e.name, e.kind, e.pose.z, e.load.mass_kg
    ('tPen', 'tool', 120.0, 0.5)
    """
    if not isinstance(text, str):
        raise FormatError(("file",), f"expected text, got {type(text).__name__}")
    text = text.replace("\r\n", "\n").replace("\r", "\n")
    decls = _declarations(text)
    loads = {d.name.upper(): d for d in decls if d.dtype == "loaddata"}
    found: list[tuple[_Decl, str, Pose, LoadData | None]] = []
    for d in decls:
        v, line, name = d.value, d.line, d.name
        if d.dtype == "tooldata":
            if not (isinstance(v, list) and len(v) == 3 and isinstance(v[0], bool)):
                raise FormatError.at_line(line, name,
                                          "expected [robhold,[[x,y,z],[q1,q2,q3,q4]],[tload]]")
            pose = _pose_of(_read_pose(v[1], line, f"{name}.tframe"))
            load = _read_load(v[2], line, f"{name}.tload")
            if v[0]:
                found.append((d, "tool", pose, load))
            else:
                found.append((d, "fixed_tool", pose, None))
        elif d.dtype == "wobjdata":
            if not (isinstance(v, list) and len(v) == 5 and isinstance(v[0], bool)
                    and isinstance(v[1], bool) and isinstance(v[2], str)):
                raise FormatError.at_line(line, name,
                                          'expected [robhold,ufprog,"ufmec",[uframe],[oframe]]')
            if not v[0] and not v[1]:
                raise FormatError.at_line(line, f"{name}.ufprog",
                                          f'a work object moved by the mechanical unit "{v[2]}" '
                                          "has no fixed pose; only ufprog TRUE is read")
            T = _read_pose(v[3], line, f"{name}.uframe") @ _read_pose(v[4], line, f"{name}.oframe")
            load = None
            if v[0] and f"{name.upper()}_LOAD" in loads:
                ld = loads[f"{name.upper()}_LOAD"]
                load = _read_load(ld.value, ld.line, ld.name)
            found.append((d, "workpiece" if v[0] else "base", _pose_of(T), load))
    return canonical_order(_numbered(found))


def _numbered(found: list[tuple[_Decl, str, Pose, LoadData | None]]) -> list[FrameEntry]:
    used: dict[tuple[bool, int], int] = {}
    numbers: dict[int, tuple[int, str]] = {}
    for i, (d, kind, _, _) in enumerate(found):
        if d.tag is None:
            continue
        tag_kind, number, tag_name, tag_line = d.tag
        if tag_kind != kind:
            raise FormatError.at_line(tag_line, d.name,
                                      f"comment says {tag_kind} but the data is a {kind}")
        family = kind in ROBOT_HELD
        if number < 1:
            raise FormatError.at_line(tag_line, d.name, "slot numbers start at 1")
        if (family, number) in used:
            raise FormatError.at_line(tag_line, d.name, f"{kind} {number} already used "
                                      f"on line {used[(family, number)]}")
        used[(family, number)] = tag_line
        numbers[i] = (number, tag_name)
    out = []
    for i, (d, kind, pose, load) in enumerate(found):
        if i in numbers:
            number, name = numbers[i]
        else:
            family = kind in ROBOT_HELD
            number = 1
            while (family, number) in used:
                number += 1
            used[(family, number)] = d.line
            name = d.name
        out.append(FrameEntry(number, name, kind, pose, load))  # type: ignore[arg-type]
    return out
