"""FANUC: user tools (UTOOL), user frames (UFRAME) and payload schedules, as a listing.

FANUC gives a frame as X, Y, Z (mm) and W, P, R (deg) with ``R = Rz(R) Ry(P) Rx(W)``
(fixed X, Y, Z), so W, P, R are KUKA's C, B, A. The controller keeps the frames in the
system variables ``$MNUTOOL[group, n]`` (n = 1..10) and ``$MNUFRAME[group, n]`` (n = 1..9).
Robot-held entries (tools; workpieces for Remote TCP) are user tools; bases and fixed tools
(the Remote TCP frame) are user frames. Loads become payload schedules ``PAYLOAD[n]``
(``$PLST_GRP1[n]``) numbered like the tool, in FANUC's units: centre of gravity in cm,
inertia about it in kgf cm s^2 (1 kgf cm s^2 = 0.0980665 kg m^2).
"""

from __future__ import annotations

import re
from typing import Iterable

import numpy as np

from solvers.errors import CalibrationError
from solvers.frames import Pose, fanuc_from_matrix, matrix_from_fanuc

from server.formats.fanuc_sysframe import is_sysframe, read_sysframe
from server.service.bounds import check_value
from server.formats.model import (
    LINE_END,
    index_number,
    ROBOT_HELD,
    FormatError,
    FrameEntry,
    LoadData,
    ParsedFile,
    canonical_order,
    check_unique_slots,
    family_of,
    one_line,
)

__all__ = ["export_fanuc", "read_fanuc", "KGF_CM_S2_PER_KG_M2"]

KGF_CM_S2_PER_KG_M2 = 1.0 / 0.0980665  # 1 kg m^2 in kgf cm s^2
MAX_UTOOL = 10
MAX_UFRAME = 9
_ROLE = {"tool": "tool", "workpiece": "workpiece held by the robot (Remote TCP: UTOOL)",
         "base": "user frame", "fixed_tool": "fixed tool (Remote TCP: UFRAME)",
         "coordinated_base": "coordinated user frame of unit"}


def _f(v: float, decimals: int = 6) -> str:
    return f"{round(float(v), decimals) + 0.0:.{decimals}f}"


def _comment(name: str) -> str:
    """FANUC frame comments hold 16 characters on one line; quotes are dropped."""
    return one_line(name).replace('"', "").replace("'", "")[:16]


def _payload(load: LoadData) -> tuple[float, np.ndarray, np.ndarray, float]:
    """Mass (kg), centre (cm), diagonal inertia (kgf cm s^2) in flange axes, and the largest
    product of inertia left out (kg m^2) when the principal axes are turned."""
    R = Pose(0, 0, 0, *load.inertia_axes_deg).as_matrix()[:3, :3]
    I_flange = R @ np.diag(load.inertia_kgm2) @ R.T
    off = float(np.max(np.abs(I_flange - np.diag(np.diag(I_flange)))))
    return load.mass_kg, np.array(load.com_mm) / 10.0, np.diag(I_flange) * KGF_CM_S2_PER_KG_M2, off


def export_fanuc(entries: Iterable[FrameEntry], group: int = 1) -> str:
    """FANUC UTOOL / UFRAME / PAYLOAD listing and the ``$MNUTOOL`` / ``$MNUFRAME`` values.

    The first part is a table to type in (MENU > SETUP > Frames > Direct Entry, and
    MENU > SYSTEM > Motion for payloads); the second lists the same values laid out like
    the system variables in SYSFRAME.VA. Values have 6 decimals (mm, deg).

    Parameters
    ----------
    entries : iterable of FrameEntry
    group : int
        Motion group (1 for a single robot).

    Raises
    ------
    FormatError
        ``("entries", i, "number")`` for a tool number above 10, a frame number above 9,
        or two entries in one slot.

    Examples
    --------
    >>> print(export_fanuc([FrameEntry(1, "pointer", "tool", Pose(0, 0, 180, 30, 20, 10))]))
    ... # doctest: +ELLIPSIS
    ! pendant: FANUC user tool / user frame data, motion group 1 (docs/formats.md)
    ...
    UTOOL    1  pointer               0.000000      0.000000    180.000000     10.000000     20.000000     30.000000
    ...
    """
    entries = list(entries)
    check_unique_slots(entries, {"robot_held": MAX_UTOOL, "stationary": MAX_UFRAME}, "FANUC")
    tools = sorted((e for e in entries if e.kind in ROBOT_HELD), key=lambda e: e.number)
    frames = sorted((e for e in entries if e.kind not in ROBOT_HELD), key=lambda e: e.number)
    head = f"{'':7}{'No':>3}  {'Comment':<16}" + "".join(f"{k:>14}" for k in "XYZWPR")
    lines = [
        f"! pendant: FANUC user tool / user frame data, motion group {group} (docs/formats.md)",
        "! X, Y, Z in mm; W, P, R in deg: R = Rz(R) Ry(P) Rx(W) (fixed X, Y, Z), i.e. W = KUKA C, "
        "P = B, R = A",
        "! UTOOL: tools, and workpieces held by the robot (Remote TCP); UFRAME: bases, and fixed "
        "tools (Remote TCP)",
        "",
        "!" + head[1:],
    ]

    def row(label: str, e: FrameEntry) -> str:
        xyzwpr = fanuc_from_matrix(e.pose.as_matrix())
        cells = "".join(f"{_f(v):>14}" for v in xyzwpr)
        return f"{label:<7}{e.number:>3}  {_comment(e.name):<16}{cells}"

    lines += [row("UTOOL", e) for e in tools] + [row("UFRAME", e) for e in frames]
    loaded = [e for e in tools if e.load is not None]
    if loaded:
        lines += ["", "! PAYLOAD[n] goes with UTOOL n. Mass kg; centre of gravity X, Y, Z in cm "
                  "(flange axes);",
                  "! inertia IX, IY, IZ about the centre of gravity in kgf cm s^2",
                  "!" + f"{'':6}{'No':>3}{'Mass':>12}"
                  + "".join(f"{k:>12}" for k in ("X", "Y", "Z", "IX", "IY", "IZ"))]
        for e in loaded:
            mass, cm, inertia, off = _payload(e.load)  # type: ignore[arg-type]
            cells = [f"{_f(mass, 4):>12}", *(f"{_f(v, 4):>12}" for v in cm),
                     *(f"{_f(v, 6):>12}" for v in inertia)]
            lines.append(f"PAYLOAD{e.number:>3}" + "".join(cells))
            if off > 1e-12:
                lines.append(f"! PAYLOAD {e.number}: principal axes turned; products of inertia "
                             f"up to {off:.6g} kg m^2 are not representable and left out")
    for var, chosen, size in (("$MNUTOOL", tools, MAX_UTOOL), ("$MNUFRAME", frames, MAX_UFRAME)):
        if not chosen:
            continue
        lines += ["", f"[*SYSTEM*]{var}  Storage: SHADOW  Access: RW  : "
                      f"ARRAY[{group},{size}] OF POSITION"]
        for e in chosen:
            x, y, z, w, p, r = (_f(v) for v in fanuc_from_matrix(e.pose.as_matrix()))
            role = _ROLE[e.kind] + (f" {_comment(e.mech_unit or '')}" if e.mech_unit else "")
            lines += [f" [{group},{e.number}] =  ! {role} \"{_comment(e.name)}\"",
                      f"  Group: {group}   Config: N U T, 0, 0, 0",
                      f"  X: {x:>14}   Y: {y:>14}   Z: {z:>14}",
                      f"  W: {w:>14}   P: {p:>14}   R: {r:>14}"]
    lines += ["", END_LINE]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- reading

END_LINE = "! end of pendant frames"
HEADER = "! pendant: FANUC"


def is_controller_listing(text: str) -> bool:
    """True for a controller's ``SYSFRAME.VA`` rather than pendant's own listing (which has
    its header and end line, wherever a hand may have moved them)."""
    return HEADER not in text and END_LINE not in text and is_sysframe(text)


_ROLE_KIND = (("coordinated user frame of unit ", "coordinated_base"), ("workpiece", "workpiece"),
              ("fixed tool", "fixed_tool"), ("user frame", "base"), ("tool", "tool"))
_SECTION = re.compile(r"^\[\*SYSTEM\*\]\$(MNUTOOL|MNUFRAME)\b")
_ROLE_LINE = re.compile(r'^ \[(\d+),(\d+)\] =  ! (.*?) "(.*)"\s*$')


def _number(text: str, unit: str, line: int, fld: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise FormatError.at_line(line, fld, f"expected a number, got {text!r}") from None
    try:
        return check_value(v, unit, (fld,))
    except CalibrationError as err:
        raise FormatError.at_line(line, fld, err.reason) from None


def read_fanuc(text: str) -> ParsedFile:
    """The frames of pendant's own FANUC listing (:func:`export_fanuc`), whole; or of a
    controller's ``SYSFRAME.VA`` (:func:`server.formats.fanuc_sysframe.read_sysframe`).

    Values come from the UTOOL / UFRAME / PAYLOAD table (6 decimals; payload centre in cm
    and inertia in kgf cm s^2, converted back), kinds and units from the ``$MNUTOOL`` /
    ``$MNUFRAME`` part. The listing must start with pendant's header and end with
    ``! end of pendant frames``.

    Raises
    ------
    FormatError
        ``("file", "line N", "UTOOL 3.X")`` for a value that is not a number or beyond
        server/service/bounds.py; a listing without its header or cut before its end line.
    """
    if not isinstance(text, str):
        raise FormatError(("file",), f"expected text, got {type(text).__name__}")
    lines = LINE_END.split(text)
    if is_controller_listing(text):
        return read_sysframe(text)
    at = next((i for i, s in enumerate(lines, 1) if s.startswith(HEADER)), None)
    if at is not None and at > 1:
        raise FormatError.at_line(1, "header", f"a pendant FANUC listing begins with its header "
                                  f"line ('{HEADER} ...'); here it is line {at}")
    if at is None:
        raise FormatError.at_line(1, "header", "neither a pendant FANUC listing (its first "
                                  "line is '! pendant: FANUC user tool / user frame data ...') "
                                  "nor a controller's SYSFRAME.VA (no [*SYSTEM*]$MNUTOOL or "
                                  "$MNUFRAME in it)")
    end = next((i for i, s in enumerate(lines, 1) if s.rstrip() == END_LINE), None)
    if end is None:
        n = len(lines) - (1 if lines[-1] == "" else 0)
        raise FormatError.at_line(n, "end", f"the listing ends at line {n} without "
                                  f"'{END_LINE}': it was cut short")
    rows: dict[tuple[str, int], tuple[str, Pose, int]] = {}
    payloads: dict[int, tuple[LoadData, int]] = {}
    roles: dict[tuple[str, int], str] = {}
    section = None
    for n, raw in enumerate(lines[:end], 1):
        label, digits = raw[:7].strip(), raw[7:10].strip()
        if label in ("UTOOL", "UFRAME") and digits.isdigit():
            number = index_number(digits, n, label)
            fld = f"{label} {number}"
            cells = raw[28:].split()
            if len(cells) != 6:
                raise FormatError.at_line(n, fld, "expected X, Y, Z, W, P, R")
            v = [_number(c, "mm" if i < 3 else "deg", n, f"{fld}.{'XYZWPR'[i]}")
                 for i, c in enumerate(cells)]
            rows[(label, number)] = (raw[12:28].rstrip(), Pose.from_matrix(matrix_from_fanuc(v)), n)
        elif raw.startswith(("UTOOL", "UFRAME")):
            # a row whose columns moved ("UTOOL 12" typed by hand): it was taken as a comment
            # and its frame silently left out
            raise FormatError.at_line(n, raw[:6].strip(), "expected the frame's number in "
                                      f"columns 8-10, as the listing writes it; got {raw[:12]!r}")
        elif raw.startswith("PAYLOAD"):
            if not digits.isdigit():  # "PAYLOAD [ 1" or a cut line: a ValueError
                raise FormatError.at_line(n, "PAYLOAD", "expected the payload's number in "
                                          f"columns 8-10, got {raw[7:10]!r}")
            number, fld = index_number(digits, n, "PAYLOAD"), f"PAYLOAD {digits}"
            cells = raw[10:].split()
            if len(cells) != 7:
                raise FormatError.at_line(n, fld, "expected Mass, X, Y, Z, IX, IY, IZ")
            units = ("kg", "mm", "mm", "mm", "kgm2", "kgm2", "kgm2")
            v = [_number(c, u, n, f"{fld}.{k}") for c, u, k in
                 zip(cells, units, ("Mass", "X", "Y", "Z", "IX", "IY", "IZ"))]
            com = tuple(10.0 * x for x in v[1:4])
            inertia = tuple(x / KGF_CM_S2_PER_KG_M2 for x in v[4:])
            payloads[number] = (LoadData(v[0], com, inertia), n)  # type: ignore[arg-type]
        elif (sec := _SECTION.match(raw)) is not None:
            section = "UTOOL" if sec.group(1) == "MNUTOOL" else "UFRAME"
        elif section and _ROLE_LINE.match(raw):
            m = _ROLE_LINE.match(raw)
            roles[(section, index_number(m.group(2), n, section))] = m.group(3)  # type: ignore[union-attr]
    entries, where = [], {}
    for (label, number), (name, pose, line) in rows.items():
        role = roles.get((label, number), "tool" if label == "UTOOL" else "user frame")
        kind, unit = next(((k, role[len(p):].strip() if k == "coordinated_base" else None)
                           for p, k in _ROLE_KIND if role.startswith(p)), (None, None))
        if kind is None or (kind in ROBOT_HELD) != (label == "UTOOL"):
            raise FormatError.at_line(line, f"{label} {number}", f"unknown role {role!r}")
        load = payloads[number][0] if label == "UTOOL" and number in payloads else None
        try:
            entry = FrameEntry(number, name, kind, pose, load, unit)  # type: ignore[arg-type]
            entries.append(entry)
        except CalibrationError as err:
            raise FormatError.at_line(line, f"{label} {number}", err.reason) from None
        where[(family_of(kind), number)] = line
    return ParsedFile(canonical_order(entries), [], [], where)
