"""FANUC ``SYSFRAME.VA``: the frame tables as a controller lists them.

A controller's backup (or ``MD:SYSFRAME.VA`` by FTP) lists the system variables of its frames::

    [*SYSTEM*]$MNUTOOL  Storage: SHADOW  Access: RW  : ARRAY[1,10] OF POSITION
        [1,1] =
      Group: 1   Config: N D B, 0, 0, 0
      X:     0.000   Y:     0.000   Z:   185.000
      W:     0.000   P:     0.000   R:     0.000
        [1,2] = Uninitialized

``$MNUTOOL[group, n]`` are the user tools, ``$MNUFRAME[group, n]`` the user frames, X, Y, Z
in mm and W, P, R in deg with ``R = Rz(R) Ry(P) Rx(W)`` (:func:`solvers.frames.matrix_from_fanuc`),
printed with 3 decimals. A frame never set up is all zeros or ``Uninitialized``. Motion group
1 is the robot; the frames of other groups (a positioner's) are left out and named. Frame
comments are not in this file (they are ``[TPFDEF]SETUP_DATA[...].$COMMENT``), nor payloads
(``$PLST_GRP``), nor which tool is a Remote TCP one: a tool reads as a tool, a frame as a base,
without a name. The listing is for reading: a controller loads ``SYSFRAME.SV``.

:func:`read_sysframe` reads it; :func:`patch_sysframe` writes changed frames back into the
same text, changing only the numbers of the frames that changed (each line keeps its spacing
as far as the number's width allows, and its line ending).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from server.formats.model import (
    index_number,
    FormatError,
    FrameEntry,
    ParsedFile,
    Skipped,
    canonical_order,
    family_of,
)
from server.service.bounds import check_value
from solvers.errors import CalibrationError
from solvers.frames import Pose, fanuc_from_matrix, matrix_from_fanuc

__all__ = ["is_sysframe", "patch_sysframe", "read_sysframe"]

GROUP = 1  # the robot's motion group
_VAR = re.compile(r"^\s*\[\*SYSTEM\*\]\$([A-Z0-9_]+)\b(.*)$")
_ARRAY = re.compile(r"ARRAY\[\s*(\d+)\s*,\s*(\d+)\s*\]\s+OF\s+POSITION", re.I)
_INDEX = re.compile(r"^\s*\[\s*(\d+)\s*,\s*(\d+)\s*\]\s*=(.*)$")
# a number, and nothing that could continue one after it (1.#INF, 185.000abc, 12,5, 1.5-3)
_NUM = r"[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?(?![\w.#,+-])"  # ASCII digits
_TRIPLE = {ax: re.compile(rf"\b({a}:\s*)({_NUM})\s+({b}:\s*)({_NUM})\s+({c}:\s*)({_NUM})")
           for ax, (a, b, c) in (("XYZ", "XYZ"), ("WPR", "WPR"))}
_TABLES = {"MNUTOOL": "tool", "MNUFRAME": "base"}
_LABEL = {"tool": "$MNUTOOL", "base": "$MNUFRAME"}


def is_sysframe(text: str) -> bool:
    """True for a controller's listing of ``$MNUTOOL`` / ``$MNUFRAME`` (not pendant's own)."""
    return any((m := _VAR.match(line)) is not None and m.group(1) in _TABLES
               for line in text.splitlines())


@dataclass
class _Slot:
    """One ``[group, n]`` entry: where its lines are and what they hold."""

    kind: str  # tool | base
    group: int
    number: int
    line: int  # 1-based line of "[g,n] ="
    xyz_line: int | None = None
    wpr_line: int | None = None
    values: list[float] | None = None  # X, Y, Z, W, P, R once both lines were read
    uninitialized: bool = False

    @property
    def field(self) -> str:
        return f"{_LABEL[self.kind]}[{self.group},{self.number}]"


def _scan(lines: list[str]) -> tuple[list[_Slot], dict[str, int]]:
    """The entries of both tables and each table's declared size (``ARRAY[g, n]``)."""
    slots: list[_Slot] = []
    seen: dict[tuple[str, int, int], int] = {}
    sizes: dict[str, int] = {}
    table: str | None = None
    slot: _Slot | None = None

    def close(at: int) -> None:
        if slot is not None and not slot.uninitialized and slot.values is None:
            raise FormatError.at_line(at, slot.field, "the frame's X, Y, Z and W, P, R lines "
                                      "are missing (the listing was cut short?)")

    for n, raw in enumerate(lines, 1):
        if (var := _VAR.match(raw)) is not None:
            close(n)
            slot = None
            table = _TABLES.get(var.group(1))
            if table is not None:
                size = _ARRAY.search(var.group(2))
                if size is None:
                    raise FormatError.at_line(n, f"${var.group(1)}", "expected 'ARRAY[g,n] OF "
                                              "POSITION' after the variable's name")
                sizes[table] = index_number(size.group(2), n, f"${var.group(1)}")
            continue
        if table is None:
            continue
        if (ix := _INDEX.match(raw)) is not None:
            close(n)
            slot = _Slot(table, index_number(ix.group(1), n, table),
                         index_number(ix.group(2), n, table), n)
            rest = ix.group(3).strip().strip("'").strip()
            slot.uninitialized = rest.lower().startswith("uninit")
            if not 1 <= slot.number <= sizes[table]:
                raise FormatError.at_line(n, slot.field, f"frames are numbered 1.."
                                          f"{sizes[table]} (the table's ARRAY[..,{sizes[table]}])")
            if rest.startswith("!"):  # pendant's own listing marks its roles so
                raise FormatError.at_line(n, slot.field, "a pendant listing's role comment in "
                                          "a controller's SYSFRAME.VA: is the file pendant's "
                                          "listing without its first line?")
            key = (slot.kind, slot.group, slot.number)
            if key in seen:
                raise FormatError.at_line(n, slot.field, f"listed twice (first at line "
                                          f"{seen[key]})")
            seen[key] = n
            slots.append(slot)
            continue
        if slot is None or slot.uninitialized:
            continue
        for axes, attr in (("XYZ", "xyz_line"), ("WPR", "wpr_line")):
            units = "mm" if axes == "XYZ" else "deg"
            m = _TRIPLE[axes].search(raw)
            if m is None:
                if raw.strip().startswith(f"{axes[0]}:"):
                    raise FormatError.at_line(n, slot.field, "expected '" + "  ".join(
                        f"{a}: <{units}>" for a in axes) + f"', got {raw.strip()!r}")
                continue
            if getattr(slot, attr) is not None:
                raise FormatError.at_line(n, slot.field, f"a second {', '.join(axes)} line")
            setattr(slot, attr, n)
            got = []
            for k, ax in enumerate(axes):
                text = m.group(2 * k + 2)
                try:
                    got.append(check_value(float(text), units, (f"{slot.field}.{ax}",)))
                except CalibrationError as err:
                    raise FormatError.at_line(n, f"{slot.field}.{ax}", err.reason) from None
            if axes == "XYZ":
                slot.values = got + (slot.values or [])[3:]
            else:
                if slot.xyz_line is None:
                    raise FormatError.at_line(n, slot.field, "W, P, R before X, Y, Z")
                slot.values = (slot.values or [])[:3] + got
    close(len(lines))
    for s in slots:
        if s.values is not None and len(s.values) != 6:
            raise FormatError.at_line(s.line, s.field, "the frame's W, P, R line is missing")
    return slots, sizes


def _lines(text: str) -> tuple[list[str], list[str]]:
    parts = re.split(r"(\r\n|\r|\n)", text)
    return parts[0::2], parts[1::2] + [""]


def read_sysframe(text: str) -> ParsedFile:
    """The robot's frames of a controller's ``SYSFRAME.VA`` listing: ``$MNUTOOL[1, n]`` as
    tool n, ``$MNUFRAME[1, n]`` as base n; an all-zero or ``Uninitialized`` frame as an
    unused slot. The frames of other motion groups are skipped and named.

    Raises
    ------
    FormatError
        ``("file", "line N", "$MNUTOOL[1,3].X")`` for a value that is not a number or beyond
        server/service/bounds.py, a frame without its X, Y, Z / W, P, R lines, an index
        beyond the table's declared size.
    """
    return _parsed(_scan(_lines(text)[0])[0])


def _parsed(slots: list[_Slot]) -> ParsedFile:
    """What :func:`read_sysframe` answers, from the scanned entries."""
    entries: list[FrameEntry] = []
    skipped: list[Skipped] = []
    unused: list[tuple[str, int]] = []
    where: dict[tuple[str, int], int] = {}
    for s in slots:
        if s.group != GROUP:
            if not s.uninitialized and s.values is not None and any(s.values):
                skipped.append(Skipped(s.line, s.field, f"a frame of motion group {s.group} "
                                       f"(a positioner's; the robot is group {GROUP})"))
            continue
        family = family_of(s.kind)
        where[(family, s.number)] = s.line
        if s.uninitialized or s.values is None or not any(s.values):
            unused.append((family, s.number))
            continue
        try:
            entries.append(FrameEntry(s.number, "", s.kind,  # type: ignore[arg-type]
                                      Pose.from_matrix(matrix_from_fanuc(s.values))))
        except CalibrationError as err:
            raise FormatError.at_line(s.line, s.field, err.reason) from None
    return ParsedFile(canonical_order(entries), skipped, unused, where)


def _fmt(v: float) -> str:
    text = f"{v:.3f}"
    return "0.000" if text == "-0.000" else text


def _rewrite(line: str, axes: str, values: list[float]) -> str:
    """``line`` with its three numbers of ``axes`` replaced by ``values`` (3 decimals), each
    right-aligned in the width the old number and the spaces before it had."""
    m = _TRIPLE[axes].search(line)
    assert m is not None
    out, last = [], 0
    for k in range(3):
        label_at, number_end = m.start(2 * k + 1), m.end(2 * k + 2)
        label = m.group(2 * k + 1).rstrip()  # "X:"
        width = number_end - label_at - len(label)  # the spaces and digits after it
        new = _fmt(values[k])
        out.append(line[last:label_at] + label + new.rjust(max(width, len(new) + 1)))
        last = number_end
    return "".join(out) + line[last:]


def patch_sysframe(entries: Iterable[FrameEntry], text: str) -> str:
    """``text`` (a ``SYSFRAME.VA`` listing) with the robot's frames set to ``entries``: the
    X, Y, Z / W, P, R lines of each frame whose values changed are rewritten in place (3
    decimals, as the controller prints them); a frame no entry holds any more becomes zeros; an
    ``Uninitialized`` one that now holds a frame gets the controller's four lines. Everything
    else (other variables, other groups, spacing, line endings) is kept byte for byte. With no
    change, the text itself.

    A frame counts as changed when its X, Y, Z as printed or its rotation changed: W, P, R
    that name the same rotation in other numbers (near P = ±90, or W = 360) stay as they are.

    Raises FormatError naming the slot when an entry has no place in the file (a tool beyond
    its ``ARRAY[.., n]``, a base on a positioner); names, loads and Remote TCP kinds are not in
    this file."""
    entries = canonical_order(list(entries))
    lines, ends = _lines(text)
    slots, sizes = _scan(lines)
    if entries == _parsed(slots).entries:
        return text
    mine = {(s.kind, s.number): s for s in slots if s.group == GROUP}
    want: dict[tuple[str, int], FrameEntry] = {}
    for e in entries:
        kind = "tool" if family_of(e.kind) == "robot_held" else "base"
        if e.kind == "coordinated_base":
            raise FormatError((f"base {e.number}",), f"a base on the external axis unit "
                              f"{e.mech_unit or '(none)'}: SYSFRAME.VA holds the robot's user "
                              f"frames ($MNUFRAME[{GROUP},n]) only")
        if (kind, e.number) not in mine:
            size = sizes.get(kind)
            raise FormatError((f"{kind} {e.number}",), (
                f"the kept SYSFRAME.VA has no {_LABEL[kind]}[{GROUP},{e.number}]" +
                (f" (its table holds {kind}s 1..{size})" if size else
                 f" (it lists no {_LABEL[kind]})")
                + f": move the frame to a {kind} the controller has, or clear {kind} "
                  f"{e.number}"))
        want[(kind, e.number)] = e
    common = max(("\n", "\r\n", "\r"), key=ends.count)
    after_index = next((lines[s.line - 1].split("=", 1)[1] for s in slots
                        if not s.uninitialized), " ")  # what this file prints after "[g,n] ="
    inserts: dict[int, list[str]] = {}  # 0-based line index -> lines after it
    for key, s in mine.items():
        e = want.get(key)
        was = s.values if (s.values is not None and not s.uninitialized) else [0.0] * 6
        if e is None:
            now = [0.0] * 6
        else:
            now = [float(v) for v in fanuc_from_matrix(e.pose.as_matrix())]
            if any(was) and np.allclose(matrix_from_fanuc(was)[:3, :3],
                                        e.pose.as_matrix()[:3, :3], rtol=0, atol=1e-9):
                now[3:] = was[3:]  # the same rotation: its numbers as the file has them
        if [_fmt(v) for v in now] == [_fmt(v) for v in was]:
            continue
        if s.uninitialized:
            i = s.line - 1
            lines[i] = lines[i][:lines[i].index("=") + 1] + after_index
            x, y, z, w, p, r = (f"{_fmt(v):>9}" for v in now)
            added = [f"  Group: {GROUP}   Config: N D B, 0, 0, 0",
                     f"  X: {x}   Y: {y}   Z: {z}", f"  W: {w}   P: {p}   R: {r}"]
            if not ends[i]:  # the file's last line, without a line end: so are the added
                ends[i] = common
                inserts[i] = [line + common for line in added[:-1]] + [added[-1]]
            else:
                inserts[i] = [line + ends[i] for line in added]
            continue
        assert s.xyz_line is not None and s.wpr_line is not None
        for at, axes, part in ((s.xyz_line, "XYZ", slice(0, 3)), (s.wpr_line, "WPR", slice(3, 6))):
            if [_fmt(v) for v in now[part]] != [_fmt(v) for v in was[part]]:
                lines[at - 1] = _rewrite(lines[at - 1], axes, now[part])
    out = []
    for i, (line, end) in enumerate(zip(lines, ends)):
        out.append(line + end)
        out += inserts.get(i, [])
    return "".join(out)
