"""The touch-up's rows in SQLAlchemy Core: the hot path of every calibration menu.

A touch-up reads its controller and its session with the taught points, then writes one
point, bumps the session's version and advances the controller's emulated clock. Through the
ORM (identity map, unit of work, attribute events) that was 5 of the 8 ms of CPU a touch-up
cost; as cached Core statements on the request's own connection (so the same transaction,
row lock and commit as every write: ``server.deps``) it is a few tenths of a millisecond
(``benchmarks/api.py``, README "Speed").

It writes exactly what ``crud.put_point`` and ``server.routers.common.store_state`` write,
with the same optimistic versions: ``UPDATE ... SET version = v + 1 WHERE id = ? AND
version = v``, as the ORM's ``version_id_col`` does. A touch-up is not an audited change
(docs/security.md lists what is), so skipping the ORM's flush hooks loses no audit record.

It reads with :mod:`db.rows` (plain objects with the models' attribute names, so the menus'
code, ``session_out``, ``next_step``, ``flange_pose_of``, reads them as it reads the models).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any

from sqlalchemy import Connection, bindparam

from db import pipeline
from db.crud import StateConflict, require_open
from db.models import utcnow
from db.rows import (LOCKED, POSE_COLUMNS, RESULT_COLUMNS, C, P, S, ControllerRow, Locked,
                     PointRow, Row, SessionRow)

POINT_VALUES = ("source", "joints_deg", "beam_id", "edge", "t_s", "motion_sign",
                "external_axes", "x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg", "vx_mm_s",
                "vy_mm_s", "vz_mm_s", "created_at")
STATE_VALUES = ("joints_deg", "clock_s", "motion_sign", "motion_count")

INSERT_POINT = P.insert()
UPDATE_POINT = P.update().where(P.c.id == bindparam("b_id"),
                                P.c.session_id == bindparam("b_sid")).values(
    {k: bindparam(f"b_{k}") for k in POINT_VALUES})
BUMP_SESSION = S.update().where(S.c.id == bindparam("b_id"), S.c.version == bindparam("b_v")) \
    .values(version=bindparam("b_nv"), updated_at=bindparam("b_now"))
REOPEN_SESSION = BUMP_SESSION.values(state="open", report=None,
                                     **{k: None for k in RESULT_COLUMNS})
STORE_STATE = C.update().where(C.c.id == bindparam("b_id"), C.c.version == bindparam("b_v")) \
    .values(version=bindparam("b_nv"), **{k: bindparam(f"b_{k}") for k in STATE_VALUES})


def _write(conn: Connection, stmt: Any, params: dict[str, Any], what: str) -> None:
    """``stmt`` with ``params``, changing one row (409 if it changed none: another writer got
    there first; under the request's row lock that cannot happen, as with the ORM's version
    counter). In a batch (``db.rows.Locked``) it is sent with the batch's writes."""
    locked = conn.info.get(LOCKED)
    if locked is not None:
        locked.pending.append((stmt, params))
    elif conn.execute(stmt, params).rowcount != 1:
        raise StateConflict(("path",), f"{what} changed while this request ran; try again")


def _bump(conn: Connection, stmt: Any, row: Row, what: str, **values: Any) -> None:
    """``UPDATE`` ``row`` at its version, and bump it (see :func:`_write`)."""
    _write(conn, stmt, {"b_id": row.id, "b_v": row.version, "b_nv": row.version + 1, **values},
           what)
    row.version += 1


def put_point(conn: Connection, s: SessionRow, step: int, source: str,
              pose_values: Sequence[float], joints_deg: Sequence[float] | None = None,
              t_s: float | None = None, motion_sign: Sequence[float] | None = None,
              external_axes: dict[str, float] | None = None) -> PointRow:
    """Fill (or re-teach in place) one step of ``s``; a result computed before is dropped, as
    ``crud.put_point`` does. ``s`` is updated to what was written."""
    require_open(s)  # type: ignore[arg-type]
    now = utcnow()
    values: dict[str, Any] = {
        "source": source,
        "joints_deg": None if joints_deg is None else [float(q) for q in joints_deg],
        "beam_id": None, "edge": None, "t_s": None if t_s is None else float(t_s),
        "motion_sign": None if motion_sign is None else [float(v) for v in motion_sign],
        "external_axes": None if not external_axes else {k: float(v)
                                                         for k, v in external_axes.items()},
        **dict(zip(POSE_COLUMNS, (float(x) for x in pose_values))),
        "vx_mm_s": None, "vy_mm_s": None, "vz_mm_s": None, "created_at": now}
    p = next((p for p in s.points if p.step == step), None)
    if p is None:
        pid = conn.execute(INSERT_POINT, {"session_id": s.id, "step": step, **values}) \
            .inserted_primary_key[0]
        p = PointRow({"id": pid, "session_id": s.id, "step": step, **values})
        s.points = sorted([*s.points, p], key=lambda q: q.step)
    else:
        _write(conn, UPDATE_POINT, {"b_id": p.id, "b_sid": s.id,
                                    **{f"b_{k}": v for k, v in values.items()}},
               f"point {p.id}")
        p.__dict__.update(values)
    computed = s.state == "computed"
    _bump(conn, REOPEN_SESSION if computed else BUMP_SESSION, s, f"session {s.id}", b_now=now)
    s.updated_at = now
    if computed:
        s.state, s.report = "open", None
        s.__dict__.update(dict.fromkeys(RESULT_COLUMNS))
    locked = conn.info.get(LOCKED)
    if locked is not None:
        locked.sessions[s.id] = s  # what the batch's next writer of s reads (a copy)
    return p


def store_state(conn: Connection, c: ControllerRow, state: Any) -> None:
    """Save the emulated controller's state (``emulator.ControllerState``) into its row; in a
    batch that read ``c`` (``db.rows.Locked``), into ``c`` only, for :func:`write_locked` to
    write once for the whole batch."""
    values = {"joints_deg": list(state.joints_deg), "clock_s": state.clock_s,
              "motion_sign": None if state.motion_sign is None else list(state.motion_sign),
              "motion_count": state.motion_count}
    locked = conn.info.get(LOCKED)
    if locked is not None and locked.controllers.get(c.id) is c:
        c.version += 1
    else:
        _bump(conn, STORE_STATE, c, f"controller {c.id}",
              **{f"b_{k}": v for k, v in values.items()})
    c.__dict__.update(values)


def _runs(locked: Locked) -> list[tuple[Any, list[dict[str, Any]]]]:
    """A batch's writes as runs of one statement: each table's in their order, then the
    controllers as its writers left them (at the version each was read at, to the version
    they bumped it to)."""
    tables: dict[Any, list[tuple[Any, dict[str, Any]]]] = {}
    for stmt, params in locked.pending:
        tables.setdefault(stmt.table, []).append((stmt, params))
    runs = []
    for writes in tables.values():
        for _, run in itertools.groupby(writes, key=lambda w: id(w[0])):
            stmts, params = zip(*run)
            runs.append((stmts[0], list(params)))
    for cid, c in locked.controllers.items():
        if c.version != locked.versions[cid]:
            runs.append((STORE_STATE, [{"b_id": cid, "b_v": locked.versions[cid],
                                        "b_nv": c.version,
                                        **{f"b_{k}": getattr(c, k) for k in STATE_VALUES}}]))
    return runs


def write_locked(conn: Connection, locked: Locked) -> None:
    """Send a batch's writes (``db.rows.Locked``, :func:`_runs`): on PostgreSQL in one round
    trip (``db.pipeline``), else a run of one statement as one ``executemany``; each run's
    rowcount is checked (409 if a row changed under the batch: under its lock that cannot
    happen, as with the ORM's version counter)."""
    runs = _runs(locked)
    locked.pending = []
    if pipeline.supported(conn):
        counts = pipeline.write(conn, runs)
    else:
        counts = [conn.execute(stmt, params).rowcount for stmt, params in runs]
    for (stmt, params), n in zip(runs, counts):
        if n != len(params):
            raise StateConflict(("path",), f"{stmt.table.name} rows changed while this "
                                "request ran; try again")
    for cid, c in locked.controllers.items():
        locked.versions[cid] = c.version
