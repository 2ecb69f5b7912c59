"""The KRL variables the KVP face serves, read and written in KRL's literal syntax.

Values print as a KRC4 prints them through KUKAVARPROXY (``{FRAME: X 0.0, Y ...}``, a
``"name"``, an ``INT``); a write takes the same syntax, with or without the type prefixes,
and a partial aggregate (``{X 12.5}``) changes only the components it names, as a KRL
assignment does. Every read and write goes through :mod:`server.rws.ops`.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydantic import ValidationError

from server.formats import kuka
from server.formats.model import FormatError
from server.rws import ops
from server.api.schemas import EntryIn
from server.service.transaction import retry_reason
from solvers.errors import CalibrationError
from solvers.frames import Pose, kuka_from_matrix

log = logging.getLogger("pendant.kvp")

FRAME_KEYS = ("X", "Y", "Z", "A", "B", "C")
UNITS = {"X": "mm", "Y": "mm", "Z": "mm", "A": "deg", "B": "deg", "C": "deg"}
_INDEXED = re.compile(r"^\$?(TOOL_DATA|BASE_DATA|LOAD_DATA|TOOL_NAME|BASE_NAME)\[\s*([0-9]+)\s*(,\s*)?\]$")
_PREFIX = re.compile(r"\{\s*[A-Z_0-9]+\s*:", re.IGNORECASE)  # {FRAME: ... -> {...
SYSTEM = ("$TOOL", "$BASE", "$ACT_TOOL", "$ACT_BASE", "$AXIS_ACT", "$POS_ACT", "$OV_PRO")


class KvpError(Exception):
    """A request the face refuses: the message goes back in the answer's value."""


def real(v: float) -> str:
    return kuka.krl_real(round(float(v), 9) + 0.0)


def frame(p: Pose | None, type_name: str = "FRAME") -> str:
    v = (0.0,) * 6 if p is None else p.as_array()
    return "{" + f"{type_name}: " + ", ".join(f"{k} {real(x)}" for k, x in zip(FRAME_KEYS, v)) + "}"


def load(entry) -> str:
    ld = None if entry is None else entry.load
    if ld is None:
        return ("{LOAD: M -1.0, CM {FRAME: X 0.0, Y 0.0, Z 0.0, A 0.0, B 0.0, C 0.0}, "
                "J {INERTIA: X 0.0, Y 0.0, Z 0.0}}")
    cm = frame(Pose(*ld.com_mm, *ld.inertia_axes_deg))
    j = ", ".join(f"{k} {real(x)}" for k, x in zip("XYZ", ld.inertia_kgm2))
    return f"{{LOAD: M {real(ld.mass_kg)}, CM {cm}, J {{INERTIA: {j}}}}}"


def _aggregate(text: str, fld: str) -> dict[str, object]:
    """``{FRAME: X 1, ...}`` or ``{X 1, ...}`` (nested too) read by the KUKA import's reader."""
    try:
        return kuka.parse_aggregate(_PREFIX.sub("{", text.strip()), 1, fld)
    except FormatError as err:
        raise KvpError(f"{'.'.join(str(x) for x in err.loc[2:])}: {err.reason}") from None


def _pose_write(text: str, current: Pose | None, fld: str) -> Pose:
    agg = _aggregate(text, fld)
    unknown = [k for k in agg if k not in FRAME_KEYS]
    if unknown:
        raise KvpError(f"{fld}.{unknown[0]}: unknown component; a FRAME has X, Y, Z, A, B, C")
    base = dict(zip(FRAME_KEYS, (current or Pose(0, 0, 0, 0, 0, 0)).as_array()))
    base.update(agg)
    try:
        values = kuka.aggregate_components(base, FRAME_KEYS, UNITS, 1, fld)
    except FormatError as err:
        raise KvpError(f"{'.'.join(str(x) for x in err.loc[2:])}: {err.reason}") from None
    return Pose(*values)


def _name_write(text: str, fld: str) -> str:
    m = re.fullmatch(r'\s*"([^"]*)"\s*', text)
    if not m:
        raise KvpError(f'{fld}: expected a quoted name such as "gripper"')
    return m.group(1).strip()


@dataclass
class Face:
    """What a variable needs: the service's sessionmaker, the controller, the acting user."""

    maker: ops.Maker
    controller_id: int
    who: Callable[[], ops.Caller]  # the configured user as the database has it now


def read(face: Face, name: str, after_write: bool = False) -> str:
    """The value of ``name`` as a KRC4 prints it; KvpError for one pendant does not serve.
    ``after_write``: the answer to a write that committed, which needs no read permission
    (REST's PUT answers with what it wrote too; a refusal after the commit would tell the
    client its write failed)."""
    var = name.strip().upper()
    m = _INDEXED.match(var)
    who = face.who()
    cid = face.controller_id
    if m:
        array, n = m.group(1), int(m.group(2))
        table = "tool" if array in ("TOOL_DATA", "LOAD_DATA", "TOOL_NAME") else "base"
        s = _slot(face, who, table, n, var, for_write=after_write)
        if array.endswith("_DATA") and array != "LOAD_DATA":
            return frame(s.entry.pose if s.entry else None)
        if array == "LOAD_DATA":
            return load(s.entry)
        # CHAR[24] on a KRC4 (the KUKA export cuts so too): 64 four-byte characters made an
        # answer past the 256 bytes a client reads at once
        return '"' + (s.entry.name[:kuka.KRL_NAME_CHARS] if s.entry else "") + '"'
    if var not in SYSTEM:
        raise KvpError(f"{name}: not a variable pendant serves ({', '.join(SYSTEM)}, "
                       "TOOL_DATA[n], BASE_DATA[n], LOAD_DATA[n], TOOL_NAME[n,], BASE_NAME[n,])")
    if var == "$OV_PRO":
        ops.robot(face.maker, who, cid)  # the read permission
        return "100"
    state = (ops.robot_state(face.maker, cid) if after_write
             else ops.robot(face.maker, who, cid))
    if var == "$ACT_TOOL":
        return str(state.active_tool_no)
    if var == "$ACT_BASE":
        return str(state.active_base_no)
    if var == "$AXIS_ACT":
        q = list(state.joints_deg) + [0.0] * (6 - len(state.joints_deg))
        ext = state.external_axes or {}
        parts = [f"A{i + 1} {real(v)}" for i, v in enumerate(q[:6])]
        parts += [f"E{i} {real(ext.get(f'E{i}', 0.0))}" for i in range(1, 7)]
        return "{E6AXIS: " + ", ".join(parts) + "}"
    if var == "$POS_ACT":
        p = kuka_from_matrix(state.T_base_tcp_active)
        q = np.asarray(state.joints_deg, float)
        turn = sum(1 << i for i, v in enumerate(q[:6]) if v < 0)
        ext = state.external_axes or {}
        parts = [f"{k} {real(v)}" for k, v in zip(FRAME_KEYS, p)]
        parts += ["S 2", f"T {turn}"]
        parts += [f"E{i} {real(ext.get(f'E{i}', 0.0))}" for i in range(1, 7)]
        return "{E6POS: " + ", ".join(parts) + "}"
    table, n = ("tool", state.active_tool_no) if var == "$TOOL" else ("base", state.active_base_no)
    if n == 0:
        return frame(None)
    s = _slot(face, who, table, n, var)
    return frame(s.entry.pose if s.entry else None)


def _check_index(table: str, n: int, var: str) -> None:
    from db import crud

    if not 1 <= n <= crud.SLOTS[table]:
        raise KvpError(f"{var}: index {n} out of range 1..{crud.SLOTS[table]}")


def _slot(face: Face, who: ops.Caller, table: str, n: int, var: str,
          for_write: bool = False) -> ops.Slot:
    _check_index(table, n, var)
    return ops.slot(face.maker, who, face.controller_id, table, n, for_write=for_write)


MERGE_TRIES = 3  # a partial frame merged again when another writer changed the slot meanwhile


def _write_merged(face: Face, who: ops.Caller, table: str, n: int, var: str,
                  merge: Callable[[object], tuple[EntryIn, bool]]) -> None:
    """Slot ``n`` := ``merge(its entry as read)`` (the edit and whether it clears the load): a
    partial aggregate (``{X 12.5}``) keeps the components it does not name, as a KRL
    assignment keeps them.

    The merge is made with the slot as read, and the write carries the version it read (the
    If-Match REST's PUT takes): a change another face or person committed between the two is
    not overwritten with the old components; the merge is made again on the new slot, up to
    :data:`MERGE_TRIES` times, then refused."""
    for _ in range(MERGE_TRIES):
        s = _slot(face, who, table, n, var, for_write=True)
        body, clear = merge(s.entry)
        try:
            ops.commit_slot(face.maker, who, face.controller_id, table, n, body,
                            clear_load=clear, expected_version=s.version)
            return
        except ops.Stale:
            continue
    raise KvpError(f"{var}: changed by another writer {MERGE_TRIES} times while this write "
                   "merged with it; nothing written, send it again")


def _frame_merge(value: str, var: str) -> Callable[[object], tuple[EntryIn, bool]]:
    """``TOOL_DATA[n]`` / ``BASE_DATA[n]`` := ``value`` on the frame as it is."""
    def merge(entry) -> tuple[EntryIn, bool]:  # noqa: ANN001
        p = _pose_write(value, entry.pose if entry else None, var)
        return EntryIn(pose={k.lower(): v for k, v in zip(FRAME_KEYS, p.as_array())}), False
    return merge


def _load_merge(value: str, var: str) -> Callable[[object], tuple[EntryIn, bool]]:
    """``LOAD_DATA[n]`` := ``value`` on the load as it is: ``{M 4.5}`` keeps CM and J;
    ``M -1`` clears the load."""
    given = _aggregate(value, var)

    def merge(entry) -> tuple[EntryIn, bool]:  # noqa: ANN001
        ld = entry.load if entry else None
        if ld is None and given and "M" not in given:
            raise KvpError(f"{var}.M: the tool has no load (M -1); a write of CM or J gives M")
        now: dict[str, object] = {"M": -1.0, "CM": dict.fromkeys(FRAME_KEYS, 0.0),
                                  "J": dict.fromkeys("XYZ", 0.0)}
        if ld is not None:
            now = {"M": ld.mass_kg,
                   "CM": dict(zip(FRAME_KEYS, (*ld.com_mm, *ld.inertia_axes_deg))),
                   "J": dict(zip("XYZ", ld.inertia_kgm2))}
        for k, v in given.items():
            old = now.get(k)
            now[k] = {**old, **v} if isinstance(v, dict) and isinstance(old, dict) else v
        try:
            new = kuka.load_of(now, 1, var)
        except FormatError as err:
            raise KvpError(f"{'.'.join(str(x) for x in err.loc[2:])}: {err.reason}") from None
        if new is None:
            return EntryIn(), True
        return EntryIn(load={"mass_kg": new.mass_kg, "com_mm": list(new.com_mm),
                             "inertia_kgm2": list(new.inertia_kgm2),
                             "inertia_axes_deg": list(new.inertia_axes_deg)}), False
    return merge


def _read_back(face: Face, name: str, sent: str) -> str:
    """The value of ``name`` read back after its write committed; the value as sent when the
    database cannot answer that read now (``transaction.unavailable``): the write is done, and
    a refusal saying "nothing was written" would be false."""
    try:
        return read(face, name, after_write=True)
    except Exception as err:
        why = retry_reason(err)
        log.warning("kvp: %s written; reading it back failed: %s", name, why)
        return sent


def write(face: Face, name: str, value: str) -> str:
    """Write ``value`` to ``name`` through the service's operations; the value read back."""
    var = name.strip().upper()
    who = face.who()
    cid = face.controller_id
    m = _INDEXED.match(var)
    if m:
        array, n = m.group(1), int(m.group(2))
        table = "tool" if array in ("TOOL_DATA", "LOAD_DATA", "TOOL_NAME") else "base"
        if array in ("TOOL_DATA", "BASE_DATA", "LOAD_DATA"):
            _check_index(table, n, var)
            merge = (_load_merge if array == "LOAD_DATA" else _frame_merge)(value, var)
            _write_merged(face, who, table, n, var, merge)
            return _read_back(face, name, value)
        _check_index(table, n, var)
        ops.commit_slot(face.maker, who, cid, table, n, EntryIn(name=_name_write(value, var)))
        return _read_back(face, name, value)
    if var in ("$ACT_TOOL", "$ACT_BASE"):
        if not re.fullmatch(r"\s*[0-9]+\s*", value):
            raise KvpError(f"{var}: expected an INT slot number, got {value[:40]!r}")
        n = int(value)
        if var == "$ACT_TOOL":
            ops.set_active(face.maker, who, cid, tool_no=n)
        else:
            ops.set_active(face.maker, who, cid, base_no=n)
        return _read_back(face, name, value)
    if var in SYSTEM:
        raise KvpError(f"{var}: write-protected (pendant moves the arm and selects frames "
                       "through $ACT_TOOL, $ACT_BASE and its REST API)")
    raise KvpError(f"{name}: not a variable pendant serves")


def answer(face: Face, name: str, value: str | None) -> tuple[str, bool]:
    """(value, ok) of a read (``value`` None) or write; every refusal as its message."""
    try:
        return (read(face, name) if value is None else write(face, name, value)), True
    except KvpError as err:
        return str(err), False
    except ops.Refused as err:
        return str(err), False
    except CalibrationError as err:
        return f"{'.'.join(str(x) for x in err.loc)}: {err.reason}", False
    except LookupError as err:  # crud.NotFound: the controller is gone
        return str(err), False
    except ValidationError as err:  # the API's own bounds (a name too long, ...)
        e = err.errors()[0]
        return f"{name}.{'.'.join(str(x) for x in e['loc'])}: {e['msg']}", False
