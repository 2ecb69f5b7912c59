"""What every controller file format carries: numbered frames of four kinds, with loads.

A :class:`FrameEntry` is one slot as the pendant shows it: its number, its name, its kind
and its pose in the KUKA notation (x, y, z in mm, a, b, c in degrees). The kinds are

- ``tool``: a robot-held tool, pose = T_flange_tcp;
- ``workpiece``: a robot-held workpiece, pose = T_flange_workpiece;
- ``base``: a base (user frame, work object), pose = T_world_base;
- ``fixed_tool``: a stationary (external) tool, pose = T_world_fixedtool;
- ``coordinated_base``: a base moved by a mechanical unit (a positioner): ABB's coordinated
  work object (``ufprog FALSE``, ``ufmec "STN1"``), KUKA's base on an external kinematic
  (``MACHINE_FRAME_DAT[n]`` names its machine); pose = T_unit_base, ``mech_unit`` the unit.

A :class:`LoadData` is what the robot carries when it works with the slot: a tool's or a
held workpiece's load, and for a stationary tool the gripper and part the robot brings to
it (ABB's tload of a stationary tool). Bases carry none. Parsers raise :class:`FormatError`,
which names the line and the field like ``("file", "line 12", "TOOL_DATA[3]")``; a
declaration a reader cannot use but that need not stop the file is a :class:`Skipped`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Iterable, Literal, get_args

from server.service.bounds import MECH_UNIT_CHARS, NAME_CHARS, check_name, check_value, unprintable
from solvers.errors import CalibrationError
from solvers.frames import Pose

FrameKind = Literal["tool", "fixed_tool", "base", "workpiece", "coordinated_base"]
FRAME_KINDS: tuple[str, ...] = get_args(FrameKind)
ROBOT_HELD: frozenset[str] = frozenset({"tool", "workpiece"})
STATIONARY: frozenset[str] = frozenset({"base", "fixed_tool", "coordinated_base"})
LOADED: frozenset[str] = frozenset({"tool", "workpiece", "fixed_tool"})
# the line ends every reader and patcher counts: CR LF, a lone CR or LF (not U+2028, U+0085
# or a form feed, which str.splitlines() would take)
LINE_END = re.compile(r"\r\n|\r|\n")


class FormatError(CalibrationError):
    """A controller file (or an entry to write into one) that cannot be read or written.

    ``loc`` is ``("file", "line N", field)`` for a parse error, or ``("entries", i, field)``
    for an entry that a format cannot hold; ``reason`` says what is wrong.

    Examples
    --------
    >>> e = FormatError.at_line(12, "TOOL_DATA[3]", "expected a number for Y, got 'abc'")
    >>> e.loc
    ('file', 'line 12', 'TOOL_DATA[3]')
    >>> e.line, e.field
    (12, 'TOOL_DATA[3]')
    """

    def __init__(self, loc: tuple[str | int, ...], reason: str):
        super().__init__(loc, reason)
        self.line: int | None = None
        self.field: str | None = str(loc[-1]) if loc else None

    @classmethod
    def at_line(cls, line: int, field: str, reason: str, source: str = "file") -> "FormatError":
        """Parse error on 1-based ``line`` in the field ``field`` (of ``source``)."""
        err = cls((source, f"line {line}", field), reason)
        err.line = line
        return err


MAX_INDEX_DIGITS = 6  # an index or a table size in a controller file: none has a million slots


def index_number(digits: str, line: int, field: str, source: str = "file") -> int:
    """``digits`` (the digits a pattern caught, ``\\d`` or ``[0-9]``) as an index or a table's size.

    More than :data:`MAX_INDEX_DIGITS` digits is a :class:`FormatError` naming the line and
    the field: Python's ``int()`` refuses a string of over 4300 digits with a ``ValueError``,
    which answered a controller file's import with a 500 (``TOOL_DATA[111...]``).

    >>> index_number("12", 3, "TOOL_DATA")
    12
    >>> index_number("1" * 7, 3, "TOOL_DATA")
    Traceback (most recent call last):
    ...
    server.formats.model.FormatError: file.line 3.TOOL_DATA: an index of 7 digits: at most 6 (no controller has a table that long)
    """
    if not digits.lstrip("+-").isascii():  # int() reads other scripts' digits: "٣" is 3
        raise FormatError.at_line(line, field, f"an index written with digits other than 0-9: "
                                  f"{digits[:12]!r}", source)
    if len(digits) > MAX_INDEX_DIGITS:
        raise FormatError.at_line(line, field, f"an index of {len(digits)} digits: at most "
                                  f"{MAX_INDEX_DIGITS} (no controller has a table that long)",
                                  source)
    return int(digits)


@dataclass(frozen=True)
class LoadData:
    """A payload as KUKA ``LOAD_DATA`` holds it.

    ``com_mm`` is the centre of mass in the flange frame (mm), ``inertia_kgm2`` the
    principal moments of inertia about it (kg m^2), and ``inertia_axes_deg`` the KUKA
    A, B, C angles of the principal axes relative to the flange (``CM`` A, B, C; ABB's
    ``aom``), zero when the axes are parallel to the flange.
    """

    mass_kg: float
    com_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia_kgm2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia_axes_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mass_kg) and self.mass_kg >= 0):
            raise CalibrationError(("load", "mass_kg"),
                                   f"must be finite and >= 0, got {self.mass_kg}")
        for name in ("com_mm", "inertia_kgm2", "inertia_axes_deg"):
            v = tuple(float(x) for x in getattr(self, name))
            if len(v) != 3 or not all(math.isfinite(x) for x in v):
                raise CalibrationError(("load", name), f"must be 3 finite numbers, got {v}")
            object.__setattr__(self, name, v)
        if any(x < 0 for x in self.inertia_kgm2):
            raise CalibrationError(("load", "inertia_kgm2"), "moments of inertia must be >= 0")
        object.__setattr__(self, "mass_kg", float(self.mass_kg))
        check_value(self.mass_kg, "kg", ("load", "mass_kg"))
        for fld, unit in (("com_mm", "mm"), ("inertia_kgm2", "kgm2"), ("inertia_axes_deg", "deg")):
            for i, x in enumerate(getattr(self, fld)):
                check_value(x, unit, ("load", fld, i))


@dataclass(frozen=True)
class FrameEntry:
    """One numbered tool, workpiece, base or fixed-tool slot.

    Examples
    --------
    >>> FrameEntry(1, "pointer", "tool", Pose(0, 0, 180, 0, 0, 0)).kind
    'tool'
    """

    number: int
    name: str
    kind: FrameKind
    pose: Pose
    load: LoadData | None = None
    mech_unit: str | None = None  # coordinated_base only: the unit that moves it

    def __post_init__(self) -> None:
        if self.kind not in FRAME_KINDS:
            raise CalibrationError(("kind",),
                                   f"must be one of {', '.join(FRAME_KINDS)}, got {self.kind!r}")
        if isinstance(self.number, bool) or not isinstance(self.number, int) or self.number < 1:
            raise CalibrationError(("number",), f"must be an integer >= 1, got {self.number!r}")
        values = self.pose.as_array()
        if not all(math.isfinite(x) for x in values):
            raise CalibrationError(("pose",), "x, y, z, a, b, c must be finite")
        for k, x in zip("xyzabc", values):
            check_value(float(x), "mm" if k in "xyz" else "deg", ("pose", k))
        if len(self.name) > NAME_CHARS:  # control characters are the writers' job (one_line)
            raise CalibrationError(("name",), f"has {len(self.name)} characters; "
                                   f"at most {NAME_CHARS}")
        if self.load is not None and self.kind not in LOADED:
            raise CalibrationError(("load",), f"a {self.kind} is not carried by the robot; "
                                              "only tool, workpiece and fixed_tool take a load")
        if (self.kind == "coordinated_base") != (self.mech_unit is not None):
            raise CalibrationError(("mech_unit",), "a coordinated_base names its mechanical "
                                   "unit, and only a coordinated_base has one")
        if self.mech_unit is not None:
            check_name(self.mech_unit, ("mech_unit",), MECH_UNIT_CHARS)
            if not self.mech_unit.strip():
                raise CalibrationError(("mech_unit",), "must not be blank")


@dataclass(frozen=True)
class Skipped:
    """A declaration a reader left out, with its 1-based line and the reason."""

    line: int
    field: str
    reason: str


@dataclass(frozen=True)
class ParsedFile:
    """What a reader found in a whole controller file.

    ``entries`` in :func:`canonical_order`; ``skipped`` the declarations left out (never a
    reason to refuse the rest); ``unused`` the slots the file lists as empty, as
    ``(family, number)`` with family ``"robot_held"`` or ``"stationary"`` (KUKA lists every
    slot; an import empties them too); ``slot_lines`` the line where each slot
    ``(family, number)`` is given, for errors a later check finds.
    """

    entries: list[FrameEntry]
    skipped: list[Skipped] = field(default_factory=list)
    unused: list[tuple[str, int]] = field(default_factory=list)
    slot_lines: dict[tuple[str, int], int] = field(default_factory=dict)


def family_of(kind: str) -> str:
    """``"robot_held"`` (KUKA TOOL slots, FANUC UTOOL) or ``"stationary"`` (BASE, UFRAME)."""
    return "robot_held" if kind in ROBOT_HELD else "stationary"


def one_line(text: str) -> str:
    r"""``text`` with every character that would break a line (control characters, U+0085,
    U+2028, U+2029) turned into a space: what any exporter may write inside a line.

    >>> one_line("pointer\nUTOOL 9\u2028x\x85y")
    'pointer UTOOL 9 x y'
    """
    return "".join(" " if unprintable(c) else c for c in text)


def canonical_order(entries: Iterable[FrameEntry]) -> list[FrameEntry]:
    """Entries in the order importers return them: robot-held slots (tool, workpiece) by
    number, then stationary ones (base, fixed_tool) by number."""
    return sorted(entries, key=lambda e: (e.kind not in ROBOT_HELD, e.number, e.kind))


def check_unique_slots(entries: Iterable[FrameEntry], limits: dict[str, int], fmt: str) -> None:
    """Refuse two entries in one slot, or a number beyond the format's slots.

    ``limits`` maps each slot family (``"robot_held"``, ``"stationary"``) to its size.
    """
    seen: dict[tuple[str, int], int] = {}
    for i, e in enumerate(entries):
        family = family_of(e.kind)
        if e.number > limits[family]:
            raise FormatError(("entries", i, "number"),
                              f"{fmt} has {limits[family]} {family.replace('_', '-')} slots; "
                              f"{e.kind} {e.number} does not fit")
        if (family, e.number) in seen:
            j = seen[(family, e.number)]
            raise FormatError(("entries", i, "number"),
                              f"{e.kind} {e.number} shares its {fmt} slot with entries[{j}]; "
                              "tools and workpieces share one numbering, "
                              "bases and fixed tools another")
        seen[(family, e.number)] = i
