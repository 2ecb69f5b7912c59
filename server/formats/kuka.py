"""KUKA KR C4 ``$config.dat``: TOOL_DATA / LOAD_DATA / BASE_DATA and their names and types.

The controller keeps its tool and base tables in ``KRC:\\R1\\System\\$config.dat``, a data
list ``DEFDAT $CONFIG`` ... ``ENDDAT``:

.. code-block:: text

    DECL FRAME TOOL_DATA[16]
    TOOL_DATA[1]={X 0.0,Y 0.0,Z 180.0,A 0.0,B 0.0,C 0.0}
    DECL CHAR TOOL_NAME[16,24]
    TOOL_NAME[1,]="pointer"
    DECL LOAD LOAD_DATA[16]
    LOAD_DATA[1]={M 2.5,CM {X 0.0,Y 0.0,Z 80.0,A 0.0,B 0.0,C 0.0},J {X 0.01,Y 0.01,Z 0.005}}
    DECL IPO_M_T TOOL_TYPE[16]
    TOOL_TYPE[1]=#BASE

and the same for BASE_DATA[32] / BASE_NAME[32,24] / BASE_TYPE[32] (bases carry no load).

**Kinds.** A slot's TYPE is the interpolation mode (``IPO_MODE``) it is used with. ``#BASE``
is the conventional mode (a standard motion's ``FDAT`` says ``IPO_FRAME #BASE``): the robot
carries the tool and the base stands still, so TOOL_TYPE ``#BASE`` is a robot-held tool and
BASE_TYPE ``#BASE`` a base. ``#TCP`` is external-TCP mode: the TCP stands still and the robot
carries the part, so TOOL_TYPE ``#TCP`` is a robot-held workpiece and BASE_TYPE ``#TCP`` a
stationary (fixed) tool. Unused slots are zero frames named ``" "`` of type ``#NONE`` with a
load of mass ``-1.0`` ("not set"). A base whose ``MACHINE_FRAME_DAT[n]`` names a machine
(``PARENT[] "DKP_400_1"``) sits on that external kinematic: a ``coordinated_base``. A
stationary tool's load has no array in KSS; pendant keeps it in a comment line
``;pendant BASE_LOAD[n]={M ...}`` after ``BASE_TYPE[n]``. Frame poses are KUKA X, Y, Z (mm)
and A, B, C (deg, ``R = Rz(A) Ry(B) Rx(C)``).

**Round trip.** :func:`export_kuka` given the imported text (``template``) patches only the
numbers, names and types that changed into it and keeps every other byte.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Iterable

from solvers.errors import CalibrationError
from solvers.frames import Pose

from server.service.bounds import NAME_CHARS, check_name, check_value
from server.formats.model import (
    index_number,
    FormatError,
    FrameEntry,
    LoadData,
    ParsedFile,
    canonical_order,
    check_unique_slots,
    family_of,
    one_line,
)

__all__ = ["export_kuka", "import_kuka", "read_kuka", "krl_real"]

KRL_NAME_CHARS = 24  # DECL CHAR TOOL_NAME[16,24]
_FRAME_KEYS = ("X", "Y", "Z", "A", "B", "C")
_TOOL_TYPE = {"tool": "#BASE", "workpiece": "#TCP"}
_BASE_TYPE = {"base": "#BASE", "fixed_tool": "#TCP", "coordinated_base": "#BASE"}
_ARRAYS = ("TOOL_DATA", "TOOL_NAME", "TOOL_TYPE", "LOAD_DATA",
           "BASE_DATA", "BASE_NAME", "BASE_TYPE", "MACHINE_FRAME_DAT")
_FAMILY_ARRAYS = {"TOOL": ("TOOL_DATA", "TOOL_NAME", "LOAD_DATA", "TOOL_TYPE"),
                  "BASE": ("BASE_DATA", "BASE_NAME", "BASE_TYPE")}
_KINDS = {"TOOL": {"#BASE": "tool", "#TCP": "workpiece", "#NONE": "tool"},
          "BASE": {"#BASE": "base", "#TCP": "fixed_tool", "#NONE": "base"}}
_FAMILY = {"TOOL": "robot_held", "BASE": "stationary"}


# --------------------------------------------------------------------------- writing values


def krl_real(value: float) -> str:
    """A REAL as KRL reads it, with the shortest digits that give back the same double.

    Examples
    --------
    >>> krl_real(180), krl_real(-0.0), krl_real(1e-05), krl_real(0.1)
    ('180.0', '0.0', '1.0E-05', '0.1')
    """
    s = repr(float(value) + 0.0)
    if "e" in s:
        mantissa, exponent = s.split("e")
        if "." not in mantissa:
            mantissa += ".0"
        s = f"{mantissa}E{exponent}"
    return s


def _frame(p: Pose | None) -> str:
    v = (0.0,) * 6 if p is None else p.as_array()
    return "{" + ",".join(f"{k} {krl_real(x)}" for k, x in zip(_FRAME_KEYS, v)) + "}"


def _load(load: LoadData | None) -> str:
    if load is None:
        return "{M -1.0,CM " + _frame(None) + ",J {X 0.0,Y 0.0,Z 0.0}}"
    cm = Pose(*load.com_mm, *load.inertia_axes_deg)
    j = ",".join(f"{k} {krl_real(x)}" for k, x in zip("XYZ", load.inertia_kgm2))
    return f"{{M {krl_real(load.mass_kg)},CM {_frame(cm)},J {{{j}}}}}"


def _name(name: str) -> str:
    """A TOOL_NAME / BASE_NAME string: no quotes or line breaks, at most 24 chars."""
    clean = one_line(name).replace('"', " ")[:KRL_NAME_CHARS]
    return f'"{clean or " "}"'


def _machine_frame(unit: str | None, index: int = 0) -> str:
    parent = one_line(unit or "").replace('"', " ") or " "
    return f'{{MACH_DEF_INDEX {index},PARENT[] "{parent}",GEOMETRY[] " "}}'


def _base_load_line(n: int, load: LoadData) -> str:
    return f";pendant BASE_LOAD[{n}]={_load(load)}"


# pendant's tool frames have their working direction along tool Z; KSS's default machine
# datum is $TOOL_DIRECTION=#X. Said in the file so the controller can be set to match.
TOOL_DIRECTION_NOTE = ("; pendant: tool working direction is TOOL Z -- set $TOOL_DIRECTION=#Z "
                       "(KSS default #X) or tool-direction jogging will differ")


def _family_block(family: str, size: int, table: dict[int, FrameEntry]) -> list[str]:
    """The DECL and assignment lines of one family (TOOL or BASE), every slot written."""
    rng = range(1, size + 1)
    types = _TOOL_TYPE if family == "TOOL" else _BASE_TYPE

    def get(n: int) -> FrameEntry | None:
        return table.get(n)

    lines = [f"INT MAX_{family}={size}", f"DECL FRAME {family}_DATA[{size}]"]
    lines += [f"{family}_DATA[{n}]={_frame(e.pose if (e := get(n)) else None)}" for n in rng]
    lines += ["", f"DECL CHAR {family}_NAME[{size},{KRL_NAME_CHARS}]"]
    lines += [f"{family}_NAME[{n},]={_name(e.name if (e := get(n)) else '')}" for n in rng]
    if family == "TOOL":
        lines += ["", f"DECL LOAD LOAD_DATA[{size}]"]
        lines += [f"LOAD_DATA[{n}]={_load(e.load if (e := get(n)) else None)}" for n in rng]
    lines += ["", f"DECL IPO_M_T {family}_TYPE[{size}]"]
    for n in rng:
        e = get(n)
        lines.append(f"{family}_TYPE[{n}]={types[e.kind] if e else '#NONE'}")
        if e is not None and family == "BASE" and e.load is not None:
            lines.append(_base_load_line(n, e.load))
    coordinated = [e for e in table.values() if e.kind == "coordinated_base"]
    if coordinated:
        lines += ["", "; bases on an external kinematic: set MACH_DEF_INDEX to the machine's "
                      "MACHINE_DEF index", f"DECL MACHINE_FRAME_T MACHINE_FRAME_DAT[{size}]"]
        lines += [f"MACHINE_FRAME_DAT[{n}]={_machine_frame(e.mech_unit if (e := get(n)) else None)}"
                  for n in rng]
    return lines


def export_kuka(entries: Iterable[FrameEntry], tool_slots: int = 16, base_slots: int = 32,
                template: str | None = None) -> str:
    """A KR C4 ``$config.dat``: the imported file with the changed values patched in, or a
    complete ``DEFDAT $CONFIG`` holding the tool and base arrays.

    Tools and workpieces go to TOOL slots (types ``#BASE`` and ``#TCP``), bases, fixed tools
    and coordinated bases to BASE slots (``#BASE``, ``#TCP``, ``#BASE`` with a
    ``MACHINE_FRAME_DAT``); the entry's number is its slot. Reals are written with the
    shortest digits that read back as the same double, so
    ``import_kuka(export_kuka(e)) == canonical_order(e)`` exactly. Names are cut to 24
    characters; double quotes and line breaks become spaces.

    Parameters
    ----------
    entries : iterable of FrameEntry
    tool_slots, base_slots : int
        Sizes of the TOOL and BASE arrays (``MAX_TOOL``, ``MAX_BASE``; KSS default 16, 32);
        with a template, the sizes it declares.
    template : str, optional
        The ``$config.dat`` imported before. Only the lines of slots whose values differ
        from it are touched, and in them only the numbers that changed; with no change
        the text comes back byte for byte.

    Returns
    -------
    str
        Lines joined by ``"\\n"`` (a template keeps its own line ends).

    Raises
    ------
    FormatError
        ``("entries", i, "number")`` when a number exceeds its array or two entries share
        a slot; ``("tool_slots",)`` / ``("base_slots",)`` for a size below 1; the template's
        own parse errors.

    Examples
    --------
    >>> text = export_kuka([FrameEntry(1, "pointer", "tool", Pose(0, 0, 180, 0, 0, 0))], 2, 1)
    >>> print(text)  # doctest: +ELLIPSIS
    &ACCESS RV
    ...
    TOOL_DATA[1]={X 0.0,Y 0.0,Z 180.0,A 0.0,B 0.0,C 0.0}
    TOOL_DATA[2]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}
    ...
    TOOL_NAME[1,]="pointer"
    TOOL_NAME[2,]=" "
    ...
    TOOL_TYPE[1]=#BASE
    TOOL_TYPE[2]=#NONE
    ...
    ENDDAT
    """
    entries = list(entries)
    if template is not None:
        return _patch(template, entries)
    for fld, n in (("tool_slots", tool_slots), ("base_slots", base_slots)):
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise FormatError((fld,), f"must be an integer >= 1, got {n!r}")
    check_unique_slots(entries, {"robot_held": tool_slots, "stationary": base_slots}, "KUKA")
    tools = {e.number: e for e in entries if e.kind in _TOOL_TYPE}
    bases = {e.number: e for e in entries if e.kind in _BASE_TYPE}
    lines = ["&ACCESS RV", "&REL 1", r"&PARAM DISKPATH = KRC:\R1\System", "DEFDAT  $CONFIG", "",
             "; TOOL AND BASE DATA (written by pendant; docs/formats.md)",
             ";----------------------------------", TOOL_DIRECTION_NOTE]
    lines += _family_block("TOOL", tool_slots, tools) + [""]
    lines += _family_block("BASE", base_slots, bases)
    lines += ["", "ENDDAT"]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- reading

_NUM = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"  # ASCII digits; linear
_DECL = re.compile(
    r"^\s*(?:DECL\s+)?(?:GLOBAL\s+)?\w+\s+(" + "|".join(_ARRAYS)
    + r")\s*\[\s*(\d+)\s*(?:,\s*(\d*)\s*)?\]\s*$", re.IGNORECASE)
_START = re.compile(r"^\s*\$?(" + "|".join(_ARRAYS) + r")\s*\[", re.IGNORECASE)
_ASSIGN = re.compile(r"^\s*\$?(\w+)\s*\[\s*([+-]?\d+)\s*(,\s*)?\]\s*=\s*(.*?)\s*$", re.IGNORECASE)
_BASE_LOAD = re.compile(r"^\s*;\s*pendant\s+BASE_LOAD\[(\d+)\]\s*=\s*(\{.*\})\s*$", re.IGNORECASE)
_TOKEN = re.compile(
    r'\s*(?:(\{)|(\})|(,)|(' + _NUM + r')(?![\w.])|(#\w+)|("[^"]*")|([A-Za-z_]\w*(?:\[\])?))')
_DEFDAT = re.compile(r"^\s*DEFDAT\b", re.IGNORECASE)
_MACHINE_DEF = re.compile(r'^\s*MACHINE_DEF\[([0-9]{1,6})\]\s*=\s*\{\s*NAME\[\]\s*"([^"]*)"',
                          re.IGNORECASE | re.MULTILINE)
_ENDDAT = re.compile(r"^\s*ENDDAT\b", re.IGNORECASE)
_LINES = re.compile(r"[^\r\n]*(?:\r\n|\r|\n)|[^\r\n]+\Z")  # each line with its end
_UNITS = {"X": "mm", "Y": "mm", "Z": "mm", "A": "deg", "B": "deg", "C": "deg"}


@dataclass
class _Value:
    value: object
    line: int  # 1-based
    span: tuple[int, int]  # of the value in the line


@dataclass
class _Parsed:
    """Everything :func:`read_kuka` found, with where it stands (for patching)."""

    lines: list[str]  # the text's lines with their line ends
    values: dict[str, dict[int, _Value]]
    sizes: dict[str, tuple[int, int]]  # array -> (declared size, line)
    base_loads: dict[int, _Value] = field(default_factory=dict)
    enddat: int = 0  # 1-based line of ENDDAT


def _strip_comment(line: str) -> str:
    """The line without its ``;`` comment (a ``;`` inside a string is kept)."""
    in_string = False
    for i, c in enumerate(line):
        if c == '"':
            in_string = not in_string
        elif c == ";" and not in_string:
            return line[:i]
    return line


def _tokens(text: str, line: int, fld: str) -> list[tuple[str, str, int, int]]:
    """(kind, text, start, end) of an aggregate's tokens."""
    out: list[tuple[str, str, int, int]] = []
    kinds = ("{", "}", ",", "num", "enum", "str", "name")
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            if text[pos:].strip() == "":
                break
            raise FormatError.at_line(line, fld, f"cannot read {text[pos:].strip()[:20]!r}")
        k = m.lastindex
        out.append((kinds[k - 1], m.group(k), m.start(k), m.end(k)))  # type: ignore[operator]
        pos = m.end()
    return out


MAX_NESTING = 16  # braces an aggregate nests (a LOAD_DATA 2): the reader recurses


def parse_aggregate(text: str, line: int, fld: str) -> dict[str, object]:
    """``{X 1.0,Y 2.0,...}`` (nested, any spacing) -> {"X": 1.0, ...} with upper-case keys;
    every number checked against server/service/bounds.py."""
    tokens = _tokens(text, line, fld)

    def agg(i: int, path: str, depth: int = 1) -> tuple[dict[str, object], int]:
        if i >= len(tokens) or tokens[i][0] != "{":
            raise FormatError.at_line(line, path, "expected '{'")
        if depth > MAX_NESTING:
            raise FormatError.at_line(line, path, f"the aggregate nests braces more than "
                                      f"{MAX_NESTING} deep (KRL data nests a few levels)")
        out: dict[str, object] = {}
        i += 1
        while True:
            if i < len(tokens) and tokens[i][0] == "}" and not out:
                return out, i + 1
            if i >= len(tokens) or tokens[i][0] != "name":
                raise FormatError.at_line(line, path, "expected a component name such as X")
            key = tokens[i][1].upper()
            if key in out:
                raise FormatError.at_line(line, f"{path}.{key}", "component given twice")
            i += 1
            if i < len(tokens) and tokens[i][0] == "{":
                out[key], i = agg(i, f"{path}.{key}", depth + 1)
            elif i < len(tokens) and tokens[i][0] in ("num", "str", "enum"):
                kind, tok = tokens[i][0], tokens[i][1]
                out[key] = float(tok) if kind == "num" else tok
                i += 1
            else:
                got = tokens[i][1] if i < len(tokens) else "end of line"
                raise FormatError.at_line(line, f"{path}.{key}", f"expected a number, got {got!r}")
            if i < len(tokens) and tokens[i][0] == ",":
                i += 1
                continue
            if i < len(tokens) and tokens[i][0] == "}":
                return out, i + 1
            raise FormatError.at_line(line, path, "expected ',' or '}' after " + key)

    value, end = agg(0, fld)
    if end != len(tokens):
        raise FormatError.at_line(line, fld, "text after the closing '}'")
    return value


def aggregate_components(agg: dict[str, object], keys: tuple[str, ...],
                         units: dict[str, str], line: int, fld: str) -> list[float]:
    missing = [k for k in keys if k not in agg]
    extra = [k for k in agg if k not in keys]
    if missing or extra:
        what = (f"missing {', '.join(missing)}" if missing
                else f"unknown component {', '.join(extra)}")
        raise FormatError.at_line(line, fld, f"{what}; expected {', '.join(keys)}")
    out = []
    for k in keys:
        v = agg[k]
        if not isinstance(v, float):
            raise FormatError.at_line(line, f"{fld}.{k}", "expected a number")
        out.append(_bounded(v, units[k], line, f"{fld}.{k}"))
    return out


def _bounded(v: float, unit: str, line: int, fld: str) -> float:
    try:
        return check_value(v, unit, (fld,))
    except CalibrationError as err:
        raise FormatError.at_line(line, fld, err.reason) from None


def parse_load(text: str, line: int, fld: str) -> LoadData | None:
    """``{M ..., CM {...}, J {...}}`` read (:func:`load_of`)."""
    return load_of(parse_aggregate(text, line, fld), line, fld)


def load_of(agg: dict[str, object], line: int, fld: str) -> LoadData | None:
    """The load of a ``LOAD_DATA`` aggregate (``M`` -1: none), every number checked."""
    missing = [k for k in ("M", "CM", "J") if k not in agg]
    extra = [k for k in agg if k not in ("M", "CM", "J")]
    if missing or extra:
        what = (f"missing {', '.join(missing)}" if missing
                else f"unknown component {', '.join(extra)}")
        raise FormatError.at_line(line, fld, f"{what}; expected M, CM, J")
    if not isinstance(agg["M"], float):
        raise FormatError.at_line(line, f"{fld}.M", "expected a number")
    if not isinstance(agg["CM"], dict) or not isinstance(agg["J"], dict):
        raise FormatError.at_line(line, fld, "CM and J must be {...} aggregates")
    cm = aggregate_components(agg["CM"], _FRAME_KEYS, _UNITS, line, f"{fld}.CM")
    j = aggregate_components(agg["J"], ("X", "Y", "Z"), dict.fromkeys("XYZ", "kgm2"), line,
                             f"{fld}.J")
    mass = agg["M"]
    if mass == -1.0:
        return None  # KSS: "no load data set"
    if mass < 0:
        raise FormatError.at_line(line, f"{fld}.M",
                                  f"mass must be >= 0 or -1 (not set), got {mass}")
    _bounded(mass, "kg", line, f"{fld}.M")
    return LoadData(mass, tuple(cm[:3]), tuple(j), tuple(cm[3:]))  # type: ignore[arg-type]


def _parse_value(array: str, rhs: str, line: int, fld: str, width: int | None) -> object:
    if array in ("TOOL_DATA", "BASE_DATA"):
        agg = parse_aggregate(rhs, line, fld)
        return Pose(*aggregate_components(agg, _FRAME_KEYS, _UNITS, line, fld))
    if array == "LOAD_DATA":
        return parse_load(rhs, line, fld)
    if array == "MACHINE_FRAME_DAT":
        agg = parse_aggregate(rhs, line, fld)
        parent = agg.get("PARENT[]")
        if not isinstance(parent, str):
            raise FormatError.at_line(line, f"{fld}.PARENT", 'expected PARENT[] "name"')
        unit = parent[1:-1].strip()
        return None if unit.upper() in ("", "WORLD") else unit
    if array.endswith("_NAME"):
        m = re.fullmatch(r'"([^"]*)"', rhs)
        if not m:
            raise FormatError.at_line(line, fld,
                                      f'expected a quoted name such as "gripper", got {rhs[:40]!r}')
        name = m.group(1).strip()
        limit = min(width or NAME_CHARS, NAME_CHARS)
        try:
            return check_name(name, (fld,), limit)
        except CalibrationError as err:
            raise FormatError.at_line(line, fld, err.reason) from None
    kind = rhs.upper()
    if kind not in ("#TCP", "#BASE", "#NONE"):
        raise FormatError.at_line(line, fld, f"expected #TCP, #BASE or #NONE, got {rhs[:20]!r}")
    return kind


def _scan(text: str) -> _Parsed:
    """Every slot value of a whole ``$config.dat`` with its line; the file must be complete."""
    if not isinstance(text, str):
        raise FormatError(("file",), f"expected text, got {type(text).__name__}")
    lines = _LINES.findall(text)  # not splitlines(): U+2028, U+0085, \f end no line
    sizes: dict[str, tuple[int, int]] = {}
    widths: dict[str, int] = {}
    values: dict[str, dict[int, _Value]] = {name: {} for name in _ARRAYS}
    base_loads: dict[int, _Value] = {}
    defdat = enddat = 0
    for number, raw_end in enumerate(lines, 1):
        raw = raw_end.rstrip("\r\n")
        bl = _BASE_LOAD.match(raw)
        if bl:
            n = index_number(bl.group(1), number, "BASE_LOAD")
            base_loads[n] = _Value(parse_load(bl.group(2), number, f"BASE_LOAD[{n}]"), number,
                                   bl.span(2))
            continue
        code = _strip_comment(raw)
        if not code.strip() or code.lstrip().startswith("&"):
            continue
        if _DEFDAT.match(code):
            if defdat:
                raise FormatError.at_line(number, "DEFDAT", f"a second DEFDAT (first on line "
                                          f"{defdat}); one $config.dat per file")
            defdat = number
            continue
        if _ENDDAT.match(code):
            if not defdat:
                raise FormatError.at_line(number, "ENDDAT", "ENDDAT before DEFDAT")
            enddat = number
            break
        if not defdat:
            raise FormatError.at_line(number, "DEFDAT", "the file must start with DEFDAT "
                                      "(a whole $config.dat, not an excerpt)")
        decl = _DECL.match(code)
        if decl:
            array = decl.group(1).upper()
            sizes[array] = (index_number(decl.group(2), number, array), number)
            if decl.group(3):
                widths[array] = index_number(decl.group(3), number, array)
            continue
        start = _START.match(code)
        if not start:
            continue  # another declaration or statement
        array = start.group(1).upper()
        m = _ASSIGN.match(code)
        if not m or m.group(1).upper() != array:
            raise FormatError.at_line(number, array, f"cannot read {code.strip()[:60]!r}")
        index, has_comma, rhs = (index_number(m.group(2), number, array), bool(m.group(3)),
                                 m.group(4))
        is_name = array.endswith("_NAME")
        fld = f"{array}[{index}{',' if is_name else ''}]"
        if is_name != has_comma:
            form = f"{array}[n,]" if is_name else f"{array}[n]"
            raise FormatError.at_line(number, fld, f"expected the form {form}=...")
        if index < 1:
            raise FormatError.at_line(number, fld, "slot numbers start at 1")
        if index in values[array]:
            first = values[array][index].line
            raise FormatError.at_line(number, fld, f"slot assigned twice (first on line {first})")
        if array in sizes and index > sizes[array][0]:
            raise FormatError.at_line(number, fld, f"beyond DECL {array}[{sizes[array][0]}] "
                                      f"on line {sizes[array][1]}")
        value = _parse_value(array, rhs, number, fld, widths.get(array))
        values[array][index] = _Value(value, number, m.span(4))
    if not defdat:
        raise FormatError.at_line(max(len(lines), 1), "DEFDAT",
                                  "no DEFDAT: not a $config.dat (a whole file is needed)")
    if not enddat:
        raise FormatError.at_line(len(lines), "ENDDAT", f"the file ends at line {len(lines)} "
                                  "without ENDDAT: it was cut short")
    _check_complete(values, sizes, enddat)
    return _Parsed(lines, values, sizes, base_loads, enddat)


def _check_complete(values: dict[str, dict[int, _Value]], sizes: dict[str, tuple[int, int]],
                    enddat: int) -> None:
    """Every array of a family present once any is, and every declared slot assigned."""
    for family, arrays in _FAMILY_ARRAYS.items():
        present = [a for a in arrays if values[a] or a in sizes]
        if not present:
            continue
        for a in arrays:
            if a not in present:
                raise FormatError.at_line(enddat, a, f"the file has {present[0]} but no {a}; "
                                          "every slot needs its frame, name and type")
        for a in arrays:
            size = sizes[a][0] if a in sizes else max(values[a])
            missing = [n for n in range(1, size + 1) if n not in values[a]]
            if missing:
                where = f"DECL on line {sizes[a][1]}" if a in sizes else "the highest slot"
                raise FormatError.at_line(enddat, f"{a}[{missing[0]}]",
                                          f"not assigned ({where} has {size} slots); "
                                          "a whole $config.dat lists every slot")


def _entries(p: _Parsed) -> tuple[list[FrameEntry], list[tuple[str, int]], dict]:
    """(entries, unused slots, line of each slot) of a scanned file."""
    out: list[FrameEntry] = []
    unused: list[tuple[str, int]] = []
    where: dict[tuple[str, int], int] = {}
    v = p.values
    for family in ("TOOL", "BASE"):
        data, names, types = v[f"{family}_DATA"], v[f"{family}_NAME"], v[f"{family}_TYPE"]
        for index in sorted(set(data) | set(names) | set(types)):
            e = _slot(p, family, index)
            where[(_FAMILY[family], index)] = (data.get(index) or names.get(index)
                                               or types[index]).line
            if e is None:
                unused.append((_FAMILY[family], index))
            else:
                out.append(e)
    return canonical_order(out), unused, where


def _slot(p: _Parsed, family: str, index: int) -> FrameEntry | None:
    """The entry of one slot as the file gives it, or None for an unused slot."""
    v = p.values
    data, names, types = v[f"{family}_DATA"], v[f"{family}_NAME"], v[f"{family}_TYPE"]
    pose: Pose = data[index].value if index in data else Pose()  # type: ignore[assignment]
    kind_type = types[index].value if index in types else "#NONE"
    name = names[index].value if index in names else ""
    if kind_type == "#NONE" and not pose.as_array().any() and not name:
        return None  # a #NONE slot keeps a name it has (BASE_NAME[10,]="KukaReburn")
    kind = _KINDS[family][kind_type]  # type: ignore[index]
    unit = None
    if family == "BASE" and index in v["MACHINE_FRAME_DAT"]:
        unit = v["MACHINE_FRAME_DAT"][index].value
        if unit is not None and kind == "base":
            kind = "coordinated_base"
        elif unit is not None:
            line = v["MACHINE_FRAME_DAT"][index].line
            raise FormatError.at_line(line, f"MACHINE_FRAME_DAT[{index}]",
                                      f"BASE_TYPE[{index}] is {kind_type}: only a base "
                                      "(#BASE) can sit on an external kinematic")
    if family == "TOOL":
        load = v["LOAD_DATA"][index].value if index in v["LOAD_DATA"] else None
    else:
        load = p.base_loads[index].value if index in p.base_loads else None
        if load is not None and kind != "fixed_tool":
            raise FormatError.at_line(p.base_loads[index].line, f"BASE_LOAD[{index}]",
                                      "only a stationary tool (BASE_TYPE #TCP) has a load")
    line = (data.get(index) or names.get(index) or types[index]).line
    try:
        return FrameEntry(index, name, kind, pose, load, unit)  # type: ignore[arg-type]
    except CalibrationError as err:
        raise FormatError.at_line(line, f"{family}[{index}]", err.reason) from None


def read_kuka(text: str) -> ParsedFile:
    """Tool, workpiece, base, fixed-tool and coordinated-base slots of a whole ``$config.dat``.

    Reads the TOOL_DATA, TOOL_NAME, TOOL_TYPE, LOAD_DATA, BASE_DATA, BASE_NAME, BASE_TYPE
    (and MACHINE_FRAME_DAT) arrays between ``DEFDAT`` and ``ENDDAT``; everything else
    (``&ACCESS``/``&REL`` headers, ``;FOLD`` lines, ``;`` comments, other declarations) is
    kept out. Keywords are case-insensitive and spacing is free. A slot whose type is
    ``#NONE``, whose frame is all zeros and whose name is blank is unused (listed in
    ``unused``); a ``#NONE`` slot with a frame or a name is read as a tool / base, and a
    ``#BASE`` or ``#TCP`` slot is used whatever its frame and name. A load of mass -1 is
    "not set". A file whose every slot is unused (a new robot's) reads, with no entry.

    Raises
    ------
    FormatError
        ``("file", "line N", "TOOL_DATA[3].X")``: a line that cannot be read, a number
        beyond server/service/bounds.py, a name longer than its ``DECL``, an unknown TYPE, a slot
        beyond its declared size or assigned twice; a file without ``DEFDAT`` or cut
        before ``ENDDAT``; a family missing an array or a declared slot.
    """
    p = _scan(text)
    entries, unused, where = _entries(p)
    return ParsedFile(entries, [], unused, where)


def import_kuka(text: str) -> list[FrameEntry]:
    """The used slots of a whole ``$config.dat`` (:func:`read_kuka`), in canonical order.

    Examples
    --------
    >>> import_kuka('DEFDAT $CONFIG\\nTOOL_DATA[1]={X 0,Y 0,Z 180,A 0,B 0,C 0}\\n'
    ...             'TOOL_NAME[1,]="pen"\\nTOOL_TYPE[1]=#BASE\\n'
    ...             'LOAD_DATA[1]={M -1,CM {X 0,Y 0,Z 0,A 0,B 0,C 0},J {X 0,Y 0,Z 0}}\\n'
    ...             'ENDDAT')[0].pose.z
    180.0
    """
    return read_kuka(text).entries


# --------------------------------------------------------------------------- patching


def _patch_numbers(rhs: str, target: dict[tuple[str, ...], object], line: int, fld: str) -> str:
    """``rhs`` with each value at key path ``target`` replaced when it differs (a number by
    value, an ``#ENUM`` ignoring case, a ``"string"`` by its trimmed text); every other
    character (spacing, digits of unchanged numbers) kept."""
    out, pos, path = [], 0, []  # type: ignore[var-annotated]
    key = None
    for kind, tok, start, end in _tokens(rhs, line, fld):
        if kind == "name":
            key = tok.upper()
        elif kind == "{" and key is not None:
            path.append(key)
            key = None
        elif kind == "}" and path:
            path.pop()
        elif kind in ("num", "enum", "str") and key is not None:
            new = _changed_token(kind, tok, target.get((*path, key)))
            if new is not None:
                out.append(rhs[pos:start] + new)
                pos = end
            key = None
    out.append(rhs[pos:])
    return "".join(out)


def _changed_token(kind: str, tok: str, want: object) -> str | None:
    """The text for ``want`` where the token ``tok`` stands, or None when it already holds it."""
    if want is None:
        return None
    if kind == "num":
        return None if float(tok) == want else krl_real(want)  # type: ignore[arg-type]
    if kind == "enum":
        return None if tok.upper() == str(want).upper() else str(want)
    return None if tok[1:-1].strip() == str(want) else f'"{want or " "}"'


def _frame_target(p: Pose | None, prefix: tuple[str, ...] = ()) -> dict:
    v = (0.0,) * 6 if p is None else p.as_array()
    return {(*prefix, k): float(x) for k, x in zip(_FRAME_KEYS, v)}


def _load_target(load: LoadData | None) -> dict:
    if load is None:
        return {("M",): -1.0, **_frame_target(None, ("CM",)),
                **{("J", k): 0.0 for k in "XYZ"}}
    cm = Pose(*load.com_mm, *load.inertia_axes_deg)
    return {("M",): load.mass_kg, **_frame_target(cm, ("CM",)),
            **{("J", k): x for k, x in zip("XYZ", load.inertia_kgm2)}}


def _patch(template: str, entries: list[FrameEntry]) -> str:
    p = _scan(template)
    sizes = {fam: p.sizes.get(f"{fam}_DATA", (max(p.values[f"{fam}_DATA"] or [0]), 0))[0]
             for fam in ("TOOL", "BASE")}
    check_unique_slots(entries, {"robot_held": sizes["TOOL"] or 10**9,
                                 "stationary": sizes["BASE"] or 10**9}, "the imported $config.dat")
    lines = list(p.lines)
    eol = "\r\n" if lines and lines[0].endswith("\r\n") else "\n"
    inserts: dict[int, list[str]] = {}  # after 1-based line -> new lines
    new = {(family_of(e.kind), e.number): e for e in entries}
    machines = {name.strip(): int(i) for i, name in _MACHINE_DEF.findall(template)}
    if not p.values["MACHINE_FRAME_DAT"] and "MACHINE_FRAME_DAT" not in p.sizes and any(
            e.kind == "coordinated_base" for e in entries) and sizes["BASE"]:
        size = sizes["BASE"]  # the template has no MACHINE_FRAME_DAT: add the array
        units = {e.number: e.mech_unit for e in entries if e.kind == "coordinated_base"}
        block = [f"DECL MACHINE_FRAME_T MACHINE_FRAME_DAT[{size}]"]
        for n in range(1, size + 1):
            unit = units.get(n)
            block.append(f"MACHINE_FRAME_DAT[{n}]="
                         f"{_machine_frame(unit, machines.get(unit or '', 0))}")
        inserts.setdefault(p.enddat - 1, []).extend(block)

    def put(arr: str, n: int, text: str) -> None:
        val = p.values[arr][n]
        raw = lines[val.line - 1]
        a, b = val.span
        lines[val.line - 1] = raw[:a] + text + raw[b:]

    for family in ("TOOL", "BASE"):
        fam = _FAMILY[family]
        if not sizes[family]:  # the template has no such arrays: add them before ENDDAT
            table = {e.number: e for (f, _), e in new.items() if f == fam}
            if table:
                block = _family_block(family, max(table), table)
                inserts.setdefault(p.enddat - 1, []).extend(["", *block, ""])
            continue
        types = _TOOL_TYPE if family == "TOOL" else _BASE_TYPE
        for n in range(1, sizes[family] + 1):
            old, e = _slot(p, family, n), new.get((fam, n))
            if old == e:
                continue
            val = p.values[f"{family}_DATA"][n]
            rhs = p.lines[val.line - 1][slice(*val.span)]
            put(f"{family}_DATA", n, _patch_numbers(rhs, _frame_target(e.pose if e else None),
                                                    val.line, f"{family}_DATA[{n}]"))
            if (old.name if old else "") != (e.name if e else ""):
                put(f"{family}_NAME", n, _name(e.name if e else ""))
            if (old.kind if old else None) != (e.kind if e else None):
                old_type = p.values[f"{family}_TYPE"][n].value
                want = types[e.kind] if e else "#NONE"
                if old_type != want:
                    put(f"{family}_TYPE", n, want)
            if family == "TOOL" and (old.load if old else None) != (e.load if e else None):
                val = p.values["LOAD_DATA"][n]
                rhs = p.lines[val.line - 1][slice(*val.span)]
                put("LOAD_DATA", n, _patch_numbers(rhs, _load_target(e.load if e else None),
                                                   val.line, f"LOAD_DATA[{n}]"))
            if family == "BASE":
                _patch_base_extras(p, lines, inserts, n, old, e, machines)
    out: list[str] = []
    for i, raw in enumerate(lines, 1):
        out.append(raw)
        own = raw[len(raw.rstrip("\r\n")):] or eol  # the line's own ending, as its neighbours
        if i in inserts and not raw.endswith(("\n", "\r")):
            out[-1] = raw + own
        for extra in inserts.get(i, []):
            out.append(extra + own)
    if 0 in inserts:
        out = [x + eol for x in inserts[0]] + out
    return "".join(out)


def _patch_base_extras(p: _Parsed, lines: list[str], inserts: dict[int, list[str]], n: int,
                       old: FrameEntry | None, e: FrameEntry | None,
                       machines: dict[str, int]) -> None:
    """A BASE slot's stationary-tool load comment and its MACHINE_FRAME_DAT (PARENT and the
    MACH_DEF_INDEX of the machine of that name in the template's MACHINE_DEF, else 0)."""
    old_load, new_load = (old.load if old else None), (e.load if e else None)
    type_line = p.values["BASE_TYPE"][n].line
    if old_load != new_load:
        if n in p.base_loads:
            if new_load is None:
                lines[p.base_loads[n].line - 1] = ""
            else:
                put_raw = lines[p.base_loads[n].line - 1]
                a, b = p.base_loads[n].span
                lines[p.base_loads[n].line - 1] = put_raw[:a] + _load(new_load) + put_raw[b:]
        elif new_load is not None:
            inserts.setdefault(type_line, []).append(_base_load_line(n, new_load))
    old_unit, new_unit = (old.mech_unit if old else None), (e.mech_unit if e else None)
    if old_unit != new_unit:
        if n in p.values["MACHINE_FRAME_DAT"]:
            val = p.values["MACHINE_FRAME_DAT"][n]
            raw = lines[val.line - 1]
            a, b = val.span
            parent = one_line(new_unit or "").replace('"', " ") or " "
            index = machines.get(new_unit or "", 0)
            rhs = re.sub(r'(PARENT\[\]\s*)"[^"]*"', lambda m: f'{m.group(1)}"{parent}"',
                         raw[a:b], count=1, flags=re.IGNORECASE)
            rhs = re.sub(r"(MACH_DEF_INDEX\s+)\d+", lambda m: f"{m.group(1)}{index}", rhs,
                         count=1, flags=re.IGNORECASE)
            lines[val.line - 1] = raw[:a] + rhs + raw[b:]
