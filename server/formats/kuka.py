"""KUKA KR C4 ``$config.dat``: TOOL_DATA / LOAD_DATA / BASE_DATA and their names and types.

The controller keeps its tool and base tables in ``KRC:\\R1\\System\\$config.dat``:

.. code-block:: text

    DECL FRAME TOOL_DATA[16]
    TOOL_DATA[1]={X 0.0,Y 0.0,Z 180.0,A 0.0,B 0.0,C 0.0}
    DECL CHAR TOOL_NAME[16,24]
    TOOL_NAME[1,]="pointer"
    DECL LOAD LOAD_DATA[16]
    LOAD_DATA[1]={M 2.5,CM {X 0.0,Y 0.0,Z 80.0,A 0.0,B 0.0,C 0.0},J {X 0.01,Y 0.01,Z 0.005}}
    DECL IPO_M_T TOOL_TYPE[16]
    TOOL_TYPE[1]=#TCP

and the same for BASE_DATA[32] / BASE_NAME[32,24] / BASE_TYPE[32] (bases carry no load).
The TYPE tells what a slot holds: a TOOL slot of type ``#TCP`` is a robot-held tool and of
type ``#BASE`` a robot-held workpiece; a BASE slot of type ``#BASE`` is a base and of type
``#TCP`` a fixed (external) tool. Unused slots are zero frames named ``" "`` of type
``#NONE`` with a load of mass ``-1.0`` ("not set"). Frame poses are KUKA X, Y, Z (mm) and
A, B, C (deg, ``R = Rz(A) Ry(B) Rx(C)``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Iterable

from solvers.frames import Pose

from server.formats.model import (
    FormatError,
    FrameEntry,
    LoadData,
    canonical_order,
    check_unique_slots,
)

__all__ = ["export_kuka", "import_kuka", "krl_real"]

NAME_CHARS = 24  # DECL CHAR TOOL_NAME[16,24]
_FRAME_KEYS = ("X", "Y", "Z", "A", "B", "C")
_TOOL_TYPE = {"tool": "#TCP", "workpiece": "#BASE"}
_BASE_TYPE = {"base": "#BASE", "fixed_tool": "#TCP"}
_ARRAYS = ("TOOL_DATA", "TOOL_NAME", "TOOL_TYPE", "LOAD_DATA",
           "BASE_DATA", "BASE_NAME", "BASE_TYPE")


# --------------------------------------------------------------------------- export


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
    """A TOOL_NAME / BASE_NAME string: no quotes or control characters, at most 24 chars."""
    clean = "".join(" " if (c == '"' or ord(c) < 32) else c for c in name)[:NAME_CHARS]
    return f'"{clean or " "}"'


# pendant's tool frames have their working direction along tool Z; KSS's default machine
# datum is $TOOL_DIRECTION=#X. Said in the file so the controller can be set to match.
TOOL_DIRECTION_NOTE = ("; pendant: tool working direction is TOOL Z -- set $TOOL_DIRECTION=#Z "
                       "(KSS default #X) or tool-direction jogging will differ")


def export_kuka(entries: Iterable[FrameEntry], tool_slots: int = 16, base_slots: int = 32) -> str:
    """The tool and base section of a KR C4 ``$config.dat``, every slot written.

    Tools and workpieces go to TOOL slots (types ``#TCP`` and ``#BASE``), bases and fixed
    tools to BASE slots (types ``#BASE`` and ``#TCP``); the entry's number is its slot.
    Reals are written with the shortest digits that read back as the same double, so
    ``import_kuka(export_kuka(e)) == canonical_order(e)`` exactly. Names longer than 24
    characters are cut to 24 and double quotes become spaces.

    Parameters
    ----------
    entries : iterable of FrameEntry
    tool_slots, base_slots : int
        Sizes of the TOOL and BASE arrays (``MAX_TOOL``, ``MAX_BASE``; KSS default 16, 32).

    Returns
    -------
    str
        Lines joined by ``"\\n"`` (the controller itself writes CR LF; either reads back).

    Raises
    ------
    FormatError
        ``("entries", i, "number")`` when a number exceeds its array or two entries share
        a slot; ``("tool_slots",)`` / ``("base_slots",)`` for a size below 1.

    Examples
    --------
    >>> text = export_kuka([FrameEntry(1, "pointer", "tool", Pose(0, 0, 180, 0, 0, 0))], 2, 1)
    >>> print(text)  # doctest: +ELLIPSIS
    ; TOOL AND BASE DATA
    ...
    TOOL_DATA[1]={X 0.0,Y 0.0,Z 180.0,A 0.0,B 0.0,C 0.0}
    TOOL_DATA[2]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}
    ...
    TOOL_NAME[1,]="pointer"
    TOOL_NAME[2,]=" "
    ...
    TOOL_TYPE[1]=#TCP
    TOOL_TYPE[2]=#NONE
    ...
    """
    entries = list(entries)
    for field, n in (("tool_slots", tool_slots), ("base_slots", base_slots)):
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise FormatError((field,), f"must be an integer >= 1, got {n!r}")
    check_unique_slots(entries, {"robot_held": tool_slots, "stationary": base_slots}, "KUKA")
    tools = {e.number: e for e in entries if e.kind in _TOOL_TYPE}
    bases = {e.number: e for e in entries if e.kind in _BASE_TYPE}
    t_range, b_range = range(1, tool_slots + 1), range(1, base_slots + 1)

    def pose(table: dict[int, FrameEntry], n: int) -> Pose | None:
        return table[n].pose if n in table else None

    lines = ["; TOOL AND BASE DATA", ";----------------------------------",
             TOOL_DIRECTION_NOTE, f"INT MAX_TOOL={tool_slots}"]
    lines.append(f"DECL FRAME TOOL_DATA[{tool_slots}]")
    lines += [f"TOOL_DATA[{n}]={_frame(pose(tools, n))}" for n in t_range]
    lines += ["", f"DECL CHAR TOOL_NAME[{tool_slots},{NAME_CHARS}]"]
    lines += [f"TOOL_NAME[{n},]={_name(tools[n].name if n in tools else '')}" for n in t_range]
    lines += ["", f"DECL LOAD LOAD_DATA[{tool_slots}]"]
    lines += [f"LOAD_DATA[{n}]={_load(tools[n].load if n in tools else None)}" for n in t_range]
    lines += ["", f"DECL IPO_M_T TOOL_TYPE[{tool_slots}]"]
    lines += [f"TOOL_TYPE[{n}]={_TOOL_TYPE[tools[n].kind] if n in tools else '#NONE'}"
              for n in t_range]
    lines += ["", f"INT MAX_BASE={base_slots}", f"DECL FRAME BASE_DATA[{base_slots}]"]
    lines += [f"BASE_DATA[{n}]={_frame(pose(bases, n))}" for n in b_range]
    lines += ["", f"DECL CHAR BASE_NAME[{base_slots},{NAME_CHARS}]"]
    lines += [f"BASE_NAME[{n},]={_name(bases[n].name if n in bases else '')}" for n in b_range]
    lines += ["", f"DECL IPO_M_T BASE_TYPE[{base_slots}]"]
    lines += [f"BASE_TYPE[{n}]={_BASE_TYPE[bases[n].kind] if n in bases else '#NONE'}"
              for n in b_range]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- import

_NUM = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_DECL = re.compile(
    r"^(?:DECL\s+)?(?:GLOBAL\s+)?(?:FRAME|CHAR|LOAD|IPO_M_T)\s+(" + "|".join(_ARRAYS)
    + r")\s*\[\s*(\d+)\s*(?:,\s*\d*\s*)?\]\s*$", re.IGNORECASE)
_START = re.compile(r"^\$?(" + "|".join(_ARRAYS) + r")\s*\[", re.IGNORECASE)
_ASSIGN = re.compile(r"^\$?(\w+)\s*\[\s*([+-]?\d+)\s*(,\s*)?\]\s*=\s*(.*?)\s*$", re.IGNORECASE)
_TOKEN = re.compile(
    r'\s*(?:(\{)|(\})|(,)|(' + _NUM + r')(?![\w.])|(#\w+)|("[^"]*")|([A-Za-z_]\w*))')


@dataclass
class _Value:
    value: object
    line: int


def _strip_comment(line: str) -> str:
    """The line without its ``;`` comment (a ``;`` inside a string is kept)."""
    in_string = False
    for i, c in enumerate(line):
        if c == '"':
            in_string = not in_string
        elif c == ";" and not in_string:
            return line[:i]
    return line


def _parse_aggregate(text: str, line: int, field: str) -> dict[str, object]:
    """``{X 1.0,Y 2.0,...}`` (nested, any spacing) -> {"X": 1.0, ...} with upper-case keys."""
    tokens: list[tuple[str, str]] = []
    pos = 0
    kinds = ("{", "}", ",", "num", "enum", "str", "name")
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            if text[pos:].strip() == "":
                break
            raise FormatError.at_line(line, field, f"cannot read {text[pos:].strip()[:20]!r}")
        kind = kinds[m.lastindex - 1]
        tokens.append((kind, m.group(m.lastindex)))
        pos = m.end()

    def agg(i: int, path: str) -> tuple[dict[str, object], int]:
        if i >= len(tokens) or tokens[i][0] != "{":
            raise FormatError.at_line(line, path, "expected '{'")
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
                out[key], i = agg(i, f"{path}.{key}")
            elif i < len(tokens) and tokens[i][0] == "num":
                out[key] = float(tokens[i][1])
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

    value, end = agg(0, field)
    if end != len(tokens):
        raise FormatError.at_line(line, field, "text after the closing '}'")
    return value


def _components(agg: dict[str, object], keys: tuple[str, ...], line: int,
                field: str) -> list[float]:
    missing = [k for k in keys if k not in agg]
    extra = [k for k in agg if k not in keys]
    if missing or extra:
        what = (f"missing {', '.join(missing)}" if missing
                else f"unknown component {', '.join(extra)}")
        raise FormatError.at_line(line, field, f"{what}; expected {', '.join(keys)}")
    for k in keys:
        if not isinstance(agg[k], float):
            raise FormatError.at_line(line, f"{field}.{k}", "expected a number")
    return [agg[k] for k in keys]  # type: ignore[misc]


def _parse_load(text: str, line: int, field: str) -> LoadData | None:
    agg = _parse_aggregate(text, line, field)
    missing = [k for k in ("M", "CM", "J") if k not in agg]
    extra = [k for k in agg if k not in ("M", "CM", "J")]
    if missing or extra:
        what = (f"missing {', '.join(missing)}" if missing
                else f"unknown component {', '.join(extra)}")
        raise FormatError.at_line(line, field, f"{what}; expected M, CM, J")
    if not isinstance(agg["M"], float):
        raise FormatError.at_line(line, f"{field}.M", "expected a number")
    if not isinstance(agg["CM"], dict) or not isinstance(agg["J"], dict):
        raise FormatError.at_line(line, field, "CM and J must be {...} aggregates")
    cm = _components(agg["CM"], _FRAME_KEYS, line, f"{field}.CM")
    j = _components(agg["J"], ("X", "Y", "Z"), line, f"{field}.J")
    mass = agg["M"]
    if mass == -1.0:
        return None  # KSS: "no load data set"
    if mass < 0:
        raise FormatError.at_line(line, f"{field}.M",
                                  f"mass must be >= 0 or -1 (not set), got {mass}")
    if any(x < 0 for x in j):
        raise FormatError.at_line(line, f"{field}.J", "moments of inertia must be >= 0")
    return LoadData(mass, tuple(cm[:3]), tuple(j), tuple(cm[3:]))  # type: ignore[arg-type]


def import_kuka(text: str) -> list[FrameEntry]:
    """Tool, workpiece, base and fixed-tool slots of a KUKA ``$config.dat`` (or an excerpt).

    Reads the TOOL_DATA, TOOL_NAME, TOOL_TYPE, LOAD_DATA, BASE_DATA, BASE_NAME and
    BASE_TYPE arrays wherever they stand; everything else (``&ACCESS``/``&REL`` headers,
    ``DEFDAT``/``ENDDAT``, ``;FOLD`` lines, ``;`` comments, other declarations) is skipped.
    Keywords are case-insensitive and spacing is free. A slot whose type is ``#NONE`` (or
    missing) and whose frame is all zeros is unused and left out; a ``#NONE`` slot with a
    frame is read as a tool (TOOL slot) or a base (BASE slot). A load of mass -1 means "not
    set" (``load=None``).

    Returns
    -------
    list of FrameEntry
        In :func:`~server.formats.model.canonical_order`.

    Raises
    ------
    FormatError
        ``("file", "line N", "TOOL_DATA[3]")`` (or ``"LOAD_DATA[2].CM.Z"`` ...) for a line
        that cannot be read, an unknown TYPE, a slot beyond its declared size, or a slot
        assigned twice.

    Examples
    --------
    >>> import_kuka('TOOL_DATA[1]={X 0,Y 0,Z 180,A 0,B 0,C 0}\\nTOOL_TYPE[1]=#TCP')[0].pose.z
    180.0
    """
    if not isinstance(text, str):
        raise FormatError(("file",), f"expected text, got {type(text).__name__}")
    sizes: dict[str, tuple[int, int]] = {}
    values: dict[str, dict[int, _Value]] = {name: {} for name in _ARRAYS}
    for number, raw in enumerate(text.replace("\r\n", "\n").replace("\r", "\n").split("\n"), 1):
        line = _strip_comment(raw).strip()
        if not line or line.startswith("&"):
            continue
        decl = _DECL.match(line)
        if decl:
            sizes[decl.group(1).upper()] = (int(decl.group(2)), number)
            continue
        if not _START.match(line):
            continue  # another declaration or statement
        m = _ASSIGN.match(line)
        array = _START.match(line).group(1).upper()  # type: ignore[union-attr]
        if not m or m.group(1).upper() != array:
            raise FormatError.at_line(number, array, f"cannot read {line[:60]!r}")
        index, has_comma, rhs = int(m.group(2)), bool(m.group(3)), m.group(4)
        field = f"{array}[{index}{',' if array.endswith('_NAME') else ''}]"
        if array.endswith("_NAME") != has_comma:
            form = f"{array}[n,]" if array.endswith("_NAME") else f"{array}[n]"
            raise FormatError.at_line(number, field, f"expected the form {form}=...")
        if index < 1:
            raise FormatError.at_line(number, field, "slot numbers start at 1")
        if index in values[array]:
            first = values[array][index].line
            raise FormatError.at_line(number, field, f"slot assigned twice (first on line {first})")
        values[array][index] = _Value(_parse_value(array, rhs, number, field), number)

    for array, table in values.items():
        if array in sizes:
            size, decl_line = sizes[array]
            for index, v in table.items():
                if index > size:
                    raise FormatError.at_line(v.line, f"{array}[{index}]",
                                              f"beyond DECL {array}[{size}] on line {decl_line}")

    out: list[FrameEntry] = []
    for family, kinds in (("TOOL", {"#TCP": "tool", "#BASE": "workpiece", "#NONE": "tool"}),
                          ("BASE", {"#BASE": "base", "#TCP": "fixed_tool", "#NONE": "base"})):
        data, names = values[f"{family}_DATA"], values[f"{family}_NAME"]
        types = values[f"{family}_TYPE"]
        loads = values["LOAD_DATA"] if family == "TOOL" else {}
        for index in sorted(set(data) | set(names) | set(types)):
            pose: Pose = data[index].value if index in data else Pose()  # type: ignore[assignment]
            kind_type = types[index].value if index in types else "#NONE"
            if kind_type == "#NONE" and not pose.as_array().any():
                continue
            name = names[index].value if index in names else ""
            load = loads[index].value if index in loads else None
            out.append(FrameEntry(index, name, kinds[kind_type],  # type: ignore[arg-type]
                                  pose, load))
    return canonical_order(out)


def _parse_value(array: str, rhs: str, line: int, field: str) -> object:
    if array.endswith("_DATA") and array != "LOAD_DATA":
        agg = _parse_aggregate(rhs, line, field)
        return Pose(*_components(agg, _FRAME_KEYS, line, field))
    if array == "LOAD_DATA":
        return _parse_load(rhs, line, field)
    if array.endswith("_NAME"):
        m = re.fullmatch(r'"([^"]*)"', rhs)
        if not m:
            raise FormatError.at_line(line, field,
                                      f'expected a quoted name such as "gripper", got {rhs[:40]!r}')
        return m.group(1).strip()
    kind = rhs.upper()
    if kind not in ("#TCP", "#BASE", "#NONE"):
        raise FormatError.at_line(line, field, f"expected #TCP, #BASE or #NONE, got {rhs[:20]!r}")
    return kind
