"""Universal Robots: a URScript snippet with TCPs, payloads and features.

UR writes a pose as ``p[x, y, z, rx, ry, rz]``: metres and a rotation vector (axis times
angle, radians). Each tool becomes ``global tool_<n> = p[...]`` (T_flange_tcp) and a
function ``use_tool_<n>()`` calling ``set_tcp`` and ``set_payload(mass, [cx, cy, cz])``
(kg, metres); a base becomes a feature ``global base_<n> = p[...]`` (T_world_base, in the
robot base frame). A fixed tool is ``global fixed_tool_<n>`` (its TCP in the robot base)
and a robot-held workpiece ``global workpiece_<n>`` (relative to the tool flange; in base
it is ``pose_trans(get_actual_tool_flange_pose(), workpiece_<n>)``).
"""

from __future__ import annotations

import math
import re
from typing import Iterable

from solvers.errors import CalibrationError
from solvers.frames import Pose, matrix_from_ur, ur_from_matrix

from server.service.bounds import check_value
from server.formats.model import (
    LINE_END,
    index_number,
    FormatError,
    FrameEntry,
    LoadData,
    ParsedFile,
    canonical_order,
    family_of,
    one_line,
)

__all__ = ["export_ur", "read_ur"]

_TITLE = {"tool": "Tools (TCP in the tool flange)",
          "workpiece": "Workpieces held by the robot (pose in the tool flange)",
          "base": "Features (bases, pose in the robot base)",
          "fixed_tool": "Fixed tools (TCP in the robot base)",
          "coordinated_base": "Features on a mechanical unit (pose in the unit's flange)"}


def _num(v: float, decimals: int) -> str:
    s = f"{round(float(v), decimals) + 0.0:.{decimals}f}".rstrip("0")
    return s + "0" if s.endswith(".") else s


def _p(entry: FrameEntry) -> str:
    v = ur_from_matrix(entry.pose.as_matrix())
    rv = v[3:]
    big = next((x for x in rv if abs(x) > 1e-9), 0.0)
    if abs(float((rv @ rv) ** 0.5) - math.pi) < 1e-9 and big < 0:
        v[3:] = -rv  # a half turn: +pi and -pi about the axis are one rotation; write one
    return "p[" + ", ".join([_num(x, 9) for x in v[:3]] + [_num(x, 12) for x in v[3:]]) + "]"


def _payload(load: LoadData) -> str:
    cog = ", ".join(_num(x / 1000.0, 9) for x in load.com_mm)
    return f"set_payload({_num(load.mass_kg, 6)}, [{cog}])"


def _comment(name: str) -> str:
    return one_line(name).replace('"', "'")


def export_ur(entries: Iterable[FrameEntry]) -> str:
    """URScript: ``global`` poses for every entry and a ``use_tool_<n>()`` per tool.

    Poses go through ``ur_from_matrix`` (metres, rotation vector of length <= pi); numbers
    carry 9 decimals in metres (1 nm) and 12 in radians. Inertia is not part of
    ``set_payload`` and is given in a comment.

    Raises
    ------
    FormatError
        ``("entries", i, "number")`` when two entries of one kind share a number.

    Examples
    --------
    >>> from solvers.frames import Pose
    >>> from server.formats.model import LoadData
    >>> text = export_ur([FrameEntry(1, "pointer", "tool", Pose(0, 0, 180, 0, 0, 0),
    ...                              LoadData(2.5, (0, 0, 80)))])
    >>> print(text, end="")  # doctest: +ELLIPSIS
    # pendant: Universal Robots TCP and feature data (docs/formats.md)
    ...
    # tool 1 "pointer"
    global tool_1 = p[0.0, 0.0, 0.18, 0.0, 0.0, 0.0]
    def use_tool_1():
      set_tcp(tool_1)
      set_payload(2.5, [0.0, 0.0, 0.08])
    end
    <BLANKLINE>
    # end of pendant frames
    """
    entries = list(entries)
    seen: dict[tuple[str, int], int] = {}
    for i, e in enumerate(entries):  # named per kind: tool_1 and workpiece_1 may coexist
        if (e.kind, e.number) in seen:
            raise FormatError(("entries", i, "number"),
                              f"{e.kind} {e.number} is also entries[{seen[(e.kind, e.number)]}]")
        seen[(e.kind, e.number)] = i
    lines = ["# pendant: Universal Robots TCP and feature data (docs/formats.md)",
             "# p[x, y, z, rx, ry, rz]: metres, rotation vector in radians"]
    for kind in ("tool", "workpiece", "base", "fixed_tool", "coordinated_base"):
        chosen = sorted((e for e in entries if e.kind == kind), key=lambda e: e.number)
        if not chosen:
            continue
        lines += ["", f"# {_TITLE[kind]}"]
        for e in chosen:
            var = f"{kind}_{e.number}"
            on = f' on "{_comment(e.mech_unit)}"' if e.mech_unit else ""
            lines += [f'# {kind} {e.number} "{_comment(e.name)}"{on}', f"global {var} = {_p(e)}"]
            if kind == "tool":
                lines += [f"def use_{var}():", f"  set_tcp({var})"]
                if e.load is None:
                    lines.append("  # load not known: set the payload before running")
                else:
                    lines.append(f"  {_payload(e.load)}")
                lines.append("end")
            elif kind == "workpiece" and e.load is not None:
                lines.append(f"# payload while holding it: {_payload(e.load)}")
            elif kind == "fixed_tool" and e.load is not None:
                lines.append(f"# payload while working at it: {_payload(e.load)}")
            if e.load is not None and any(e.load.inertia_kgm2):
                ix, iy, iz = (repr(float(x)) for x in e.load.inertia_kgm2)
                axes = ", ".join(repr(float(a)) for a in e.load.inertia_axes_deg)
                lines.append(f"# principal inertia {ix}, {iy}, {iz} kg m^2 "
                             f"(axes at KUKA A, B, C = {axes} deg)")
    lines += ["", END_LINE]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- reading

END_LINE = "# end of pendant frames"
_NUM = r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"  # ASCII digits
_TAG = re.compile(r'^# (tool|workpiece|base|fixed_tool|coordinated_base) (\d+) "(.*?)"'
                  r'(?: on "([^"]*)")?\s*$')
_GLOBAL = re.compile(r"^\s*global\s+(\w+)\s*=\s*p\[([^\]]*)\]\s*(?:#.*)?$")  # any spacing, a comment
_GLOBAL_NAME = re.compile(r"^\s*global\s+(\w+)\s*=")
_PAYLOAD = re.compile(r"set_payload\(\s*(" + _NUM + r")\s*,\s*\[([^\]]*)\]\s*\)")  # any spacing
_INERTIA = re.compile(r"^# principal inertia (.*) kg m\^2 \(axes at KUKA A, B, C = (.*) deg\)$")


def _numbers(text: str, n: int, units: tuple[str, ...], line: int, fld: str) -> list[float]:
    cells = [c.strip() for c in text.split(",")]
    if len(cells) != n or not all(re.fullmatch(_NUM, c) for c in cells):
        raise FormatError.at_line(line, fld, f"expected {n} numbers, got {text[:60]!r}")
    out = []
    for i, (c, unit) in enumerate(zip(cells, units)):
        try:
            out.append(check_value(float(c), unit, (fld,)))
        except CalibrationError as err:
            raise FormatError.at_line(line, f"{fld}[{i}]", err.reason) from None
    return out


def read_ur(text: str) -> ParsedFile:
    """The frames of pendant's own URScript (:func:`export_ur`), whole.

    Each ``# <kind> <n> "<name>"`` comment opens an entry; ``global <kind>_<n> = p[...]`` is
    its pose (metres, rotation vector), ``set_payload(m, [cx, cy, cz])`` and the
    ``# principal inertia`` comment its load. The script must start with pendant's header
    and end with ``# end of pendant frames``.

    Raises
    ------
    FormatError
        ``("file", "line N", "tool_3")`` for a pose or payload that cannot be read or is
        beyond server/service/bounds.py; a script without its header or cut before its end line.
    """
    if not isinstance(text, str):
        raise FormatError(("file",), f"expected text, got {type(text).__name__}")
    lines = LINE_END.split(text)
    if not lines[0].startswith("# pendant: Universal Robots"):
        raise FormatError.at_line(1, "header", "not a pendant URScript (its first line is "
                                  "'# pendant: Universal Robots TCP and feature data ...')")
    end = next((i for i, s in enumerate(lines, 1) if s.rstrip() == END_LINE), None)
    if end is None:
        n = len(lines) - (1 if lines[-1] == "" else 0)
        raise FormatError.at_line(n, "end", f"the script ends at line {n} without "
                                  f"'{END_LINE}': it was cut short")
    found: list[dict] = []
    for n, raw in enumerate(lines[:end], 1):
        tag = _TAG.match(raw)
        if tag:
            found.append({"kind": tag.group(1), "number": index_number(tag.group(2), n, "#"),
                          "name": tag.group(3), "unit": tag.group(4), "line": n,
                          "pose": None, "mass": None, "com": None, "inertia": None,
                          "axes": None})
            continue
        if not found:
            continue
        cur = found[-1]
        var = f"{cur['kind']}_{cur['number']}"
        g = _GLOBAL.match(raw)
        named = _GLOBAL_NAME.match(raw)
        if named and named.group(1) == var and not g:
            raise FormatError.at_line(n, var, f"expected 'global {var} = p[x, y, z, rx, ry, rz]', "
                                      f"got {raw.strip()[:60]!r}")
        if g and g.group(1) == var:
            v = _numbers(g.group(2), 6, ("mm",) * 3 + ("deg",) * 3, n, var)
            cur["pose"] = Pose.from_matrix(matrix_from_ur(v))
        elif "set_payload(" in raw.split("#", 1)[0] and _PAYLOAD.search(raw) is None:
            raise FormatError.at_line(n, f"{var}.payload", "expected set_payload(mass, [cx, cy, "
                                      f"cz]), got {raw.strip()[:60]!r}")
        elif (m := _PAYLOAD.search(raw)) is not None:
            cur["mass"] = _numbers(m.group(1), 1, ("kg",), n, f"{var}.payload")[0]
            com = _numbers(m.group(2), 3, ("mm",) * 3, n, f"{var}.payload")
            cur["com"] = tuple(1000.0 * x for x in com)
        elif (m := _INERTIA.match(raw)) is not None:
            cur["inertia"] = tuple(_numbers(m.group(1), 3, ("kgm2",) * 3, n, f"{var}.inertia"))
            cur["axes"] = tuple(_numbers(m.group(2), 3, ("deg",) * 3, n, f"{var}.inertia"))
    entries, where = [], {}
    for f in found:
        var = f"{f['kind']}_{f['number']}"
        if f["pose"] is None:
            raise FormatError.at_line(f["line"], var, f"no 'global {var} = p[...]' after it")
        load = None
        if f["mass"] is not None:
            load = LoadData(f["mass"], f["com"], f["inertia"] or (0.0, 0.0, 0.0),
                            f["axes"] or (0.0, 0.0, 0.0))
        try:
            entries.append(FrameEntry(f["number"], f["name"], f["kind"], f["pose"], load,
                                      f["unit"]))
        except CalibrationError as err:
            raise FormatError.at_line(f["line"], var, err.reason) from None
        where[(family_of(f["kind"]), f["number"])] = f["line"]
    return ParsedFile(canonical_order(entries), [], [], where)
