"""One set of bounds for every value of a table slot, on every path into the tables.

The API bodies (server/api/schemas.py), the JSON backup restore (server/service/backup.py) and the
controller-file importers (server/formats) all take their limits from here, so a value one
path accepts is never refused by another (a name that a backup could not restore, a
``9E+99`` that the API refuses). Beyond these magnitudes a number is a typo or the wrong
unit, and the kinematics would overflow to inf/NaN.

:func:`check_value` and :func:`check_name` raise :class:`~solvers.errors.CalibrationError`
naming the field and the bound.
"""

from __future__ import annotations

import math
import unicodedata
from typing import Annotated

from pydantic import AfterValidator, Field

from solvers.errors import CalibrationError

MAX_MM = 1e6  # 1 km: a position, a centre of mass
MAX_DEG = 1e4  # an angle
MAX_KG = 1e4  # a mass
MAX_KGM2 = 1e6  # a moment of inertia
MAX_CLOCK_S = 1e9  # the emulated clock as set (PUT .../cell/clock): 31.7 years powered
# a time the clock reached, as stored and restored (a touch-up's t_s in a backup): motions
# advance the clock by seconds, so from MAX_CLOCK_S they never come near this bound
MAX_T_S = 1e12
NAME_CHARS = 64  # a slot's name (DB column String(64))
MECH_UNIT_CHARS = 32  # a mechanical unit's name (ABB ufmec, KUKA MACHINE_DEF NAME)

Mm = Annotated[float, Field(ge=-MAX_MM, le=MAX_MM)]
Deg = Annotated[float, Field(ge=-MAX_DEG, le=MAX_DEG)]
Kg = Annotated[float, Field(ge=0.0, le=MAX_KG)]
Kgm2 = Annotated[float, Field(ge=0.0, le=MAX_KGM2)]
ClockS = Annotated[float, Field(ge=0.0, le=MAX_CLOCK_S)]

#: unit of a value -> (low, high)
LIMITS: dict[str, tuple[float, float]] = {
    "mm": (-MAX_MM, MAX_MM), "deg": (-MAX_DEG, MAX_DEG), "kg": (0.0, MAX_KG),
    "kgm2": (0.0, MAX_KGM2),
}


def check_value(value: float, unit: str, loc: tuple[str | int, ...]) -> float:
    """``value`` if it is finite and within the bounds of ``unit`` (mm, deg, kg, kgm2).

    Examples
    --------
    >>> check_value(180.0, "mm", ("x",))
    180.0
    >>> check_value(2e7, "mm", ("TOOL_DATA[1].X",))
    Traceback (most recent call last):
    ...
    solvers.errors.CalibrationError: TOOL_DATA[1].X: must be within -1e+06..1e+06 mm, got 2e+07
    """
    low, high = LIMITS[unit]
    if not (math.isfinite(value) and low <= value <= high):
        raise CalibrationError(loc, f"must be within {low:g}..{high:g} {unit}, got {value:g}")
    return value


def unprintable(c: str) -> bool:
    """A character no controller file can hold in a name: control characters (C0, C1 such
    as U+0085) and line or paragraph separators (U+2028, U+2029)."""
    return unicodedata.category(c) in ("Cc", "Zl", "Zp")


def no_nul(text: str) -> str:
    """``text`` unless it holds a NUL (U+0000), which a PostgreSQL text field cannot store (a
    500 there) and no name, label, URL or controller file has (a pydantic validator)."""
    if "\x00" in text:
        raise ValueError("contains the character U+0000 (NUL)")
    return text


Text = Annotated[str, AfterValidator(no_nul)]  # a text field a client sends (no NUL)


def check_name(name: str, loc: tuple[str | int, ...], max_chars: int = NAME_CHARS) -> str:
    """``name`` if it has at most ``max_chars`` characters and none that breaks a line."""
    if len(name) > max_chars:
        raise CalibrationError(loc, f"has {len(name)} characters; at most {max_chars}")
    bad = next((c for c in name if unprintable(c)), None)
    if bad is not None:
        raise CalibrationError(loc, f"contains the control character U+{ord(bad):04X}")
    return name


# the bidi embeddings, overrides and isolates (U+202A..U+202E, U+2066..U+2069): a name with one
# shows reordered ("pointer<RLO>txt.ini" as "pointerini.txt") on the pendant, in files, the audit
BIDI_CONTROLS = frozenset({"LRE", "RLE", "LRO", "RLO", "PDF", "LRI", "RLI", "FSI", "PDI"})


def check_given_name(name: str, loc: tuple[str | int, ...]) -> str:
    """:func:`check_name` of a name a client gives (a slot edit, a save), which also may not
    hold a bidi control (a controller file's names are read as they are)."""
    check_name(name, loc)
    bidi = next((c for c in name if unicodedata.bidirectional(c) in BIDI_CONTROLS), None)
    if bidi is not None:
        raise CalibrationError(loc, f"contains the bidi control U+{ord(bidi):04X} (it shows the "
                               "name reordered)")
    return name
