"""Plain rows for the hot paths: Core reads that skip the ORM.

A read of one slot, the controller list or a session's touch-ups goes through SQLAlchemy Core
(cached statements on the request's own connection, so in its transaction) and gives plain
objects with the models' attribute names: :class:`ControllerRow`, :class:`EntryRow`,
:class:`SessionRow` and :class:`PointRow`. The ``..._out`` builders of the routes read them as
they read the models. Through the ORM (identity map, instance state, attribute events) each
such read cost several tenths of a millisecond more per request (``benchmarks/api.py``,
README "Speed").

Only reads that change nothing use rows; a change goes through the models (so the audit hook
sees it), except the touch-up's own rows (:mod:`db.touch_up`).
"""

from __future__ import annotations

from typing import Any

from sqlalchemy import Connection, bindparam, select

from db.crud import NotFound, check_slot_address
from db.crud import _row_id as row_id
from db.models import CalibSession, Controller, FrameEntry, PoseColumns, TaughtPoint

C, S, P, E = (Controller.__table__, CalibSession.__table__, TaughtPoint.__table__,
              FrameEntry.__table__)
RESULT_COLUMNS = ("result_x_mm", "result_y_mm", "result_z_mm", "result_a_deg", "result_b_deg",
                  "result_c_deg")
POSE_COLUMNS = ("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg")

CONTROLLER = select(C).where(C.c.id == bindparam("b_id"))
CONTROLLERS = select(C).order_by(C.c.id)
CONTROLLER_LOCKED = CONTROLLER.with_for_update()  # PostgreSQL's row lock; SQLite ignores it
# sessions and their points in one statement: one row per point (one with NULLs for none)
_SESSIONS_AND_POINTS = select(*(c.label(f"s_{c.name}") for c in S.c),
                              *(c.label(f"p_{c.name}") for c in P.c)) \
    .select_from(S.outerjoin(P, P.c.session_id == S.c.id))
SESSION_POINTS = _SESSIONS_AND_POINTS.where(S.c.id == bindparam("b_id")).order_by(P.c.step)
SESSIONS_POINTS = _SESSIONS_AND_POINTS.where(S.c.id.in_(bindparam("b_ids", expanding=True))) \
    .order_by(S.c.id, P.c.step)
S_KEYS = tuple((f"s_{c.name}", c.name) for c in S.c)
P_KEYS = tuple((f"p_{c.name}", c.name) for c in P.c)
ENTRY = select(E).where(E.c.controller_id == bindparam("b_cid"),
                        E.c.entry_table == bindparam("b_table"),
                        E.c.number == bindparam("b_number"))


class Row:
    """A row's columns as attributes (the model's names)."""

    def __init__(self, mapping: Any) -> None:
        self.__dict__.update(mapping)


class ControllerRow(Row):
    """A ``controller`` row."""


class PoseRow(Row):
    pose_values = PoseColumns.pose_values  # the models' own: (x, y, z, a, b, c)


class EntryRow(PoseRow):
    """A ``frame_entry`` row (a tool or base slot)."""


class PointRow(PoseRow):
    """A ``taught_point`` row."""


class SessionRow(Row):
    """A ``calib_session`` row and its points by step (``points``)."""

    points: list[PointRow]
    result_values = CalibSession.result_values  # the model's own


class Locked:
    """What a batch of writers in one transaction (``db.batch``) has read and will write, kept
    in ``Connection.info`` under :data:`LOCKED` while the batch runs. The batch holds the
    rows' lock (PostgreSQL: its controller's row; SQLite: the database), so no other writer
    can change them meanwhile.

    - ``controllers``: each controller read once; the batch's writers read it from here (no
      round trip) and change it in place (``db.touch_up.store_state``); it is written once
      (``versions``: each one's version as read);
    - ``sessions``: each session as the batch's last writer of it left it (a later writer
      of the same session reads a copy, so each writer's answer shows its own change);
    - ``pending``: the writes of its writers, ``(statement, params)`` in order, sent
      together before the commit (``db.touch_up.write_locked``: one round trip per run of
      one statement).
    """

    def __init__(self) -> None:
        self.controllers: dict[int, ControllerRow] = {}
        self.versions: dict[int, int] = {}
        self.sessions: dict[int, SessionRow] = {}
        self.pending: list[tuple[Any, dict[str, Any]]] = []
        self.written = 0  # statements sent that were not reads (db.batch counts them)

    def keep(self, c: ControllerRow) -> ControllerRow:
        self.controllers[c.id], self.versions[c.id] = c, c.version
        return c


LOCKED = "pendant_batch_rows"  # Connection.info: the running batch's Locked rows


def controller(conn: Connection, controller_id: int, lock: bool = False) -> ControllerRow:
    """The controller (404 naming ``controller_id`` when there is none); ``lock``: with its
    row locked until commit (``SELECT ... FOR UPDATE`` on PostgreSQL, as ``crud.lock_controller``;
    a SQLite writer holds the database's lock already). In a batch (:class:`Locked`), as the
    batch's earlier writers left it."""
    rid = row_id(controller_id, conn)
    locked = conn.info.get(LOCKED)
    if locked is not None and rid in locked.controllers:
        return locked.controllers[rid]
    stmt = CONTROLLER_LOCKED if lock else CONTROLLER
    row = None if rid is None else conn.execute(stmt, {"b_id": rid}).first()
    if row is None:
        raise NotFound(("controller_id",), f"no controller {controller_id}")
    c = ControllerRow(row._mapping)
    return c if locked is None else locked.keep(c)


def controllers(conn: Connection) -> list[ControllerRow]:
    return [ControllerRow(r._mapping) for r in conn.execute(CONTROLLERS)]


def _copy(s: SessionRow) -> SessionRow:
    copy = SessionRow(s.__dict__)
    copy.points = [PointRow(p.__dict__) for p in s.points]
    return copy


def session(conn: Connection, controller_id: int, session_id: int) -> SessionRow:
    """The session with its taught points (as ``crud.get_session``); in a batch
    (:class:`Locked`), as the batch's last writer of it left it."""
    rid = row_id(session_id, conn)
    locked = conn.info.get(LOCKED)
    if locked is not None and rid in locked.sessions:
        if locked.sessions[rid].controller_id == controller_id:
            return _copy(locked.sessions[rid])
    found = [] if rid is None else conn.execute(SESSION_POINTS, {"b_id": rid}).all()
    if not found or found[0].s_controller_id != controller_id:
        raise NotFound(("session_id",), f"no session {session_id} on controller {controller_id}")
    (s,) = _sessions_of(found)
    if locked is not None:
        locked.sessions[s.id] = s
    return s


def _sessions_of(found: Any) -> list[SessionRow]:
    """Sessions with their points from rows of :data:`SESSION_POINTS` (ordered by session)."""
    out: list[SessionRow] = []
    for r in found:
        m = r._mapping
        if not out or out[-1].id != m["s_id"]:
            out.append(SessionRow({name: m[label] for label, name in S_KEYS}))
            out[-1].points = []
        if m["p_id"] is not None:
            out[-1].points.append(PointRow({name: m[label] for label, name in P_KEYS}))
    return out


def read_sessions(conn: Connection, session_ids: Any) -> None:
    """In a batch (:class:`Locked`): read the sessions its writers will read, in one query,
    into ``Locked.sessions`` (each writer then reads its own as a copy, :func:`session`).
    Ids out of range or of no session are left for the writers to refuse."""
    locked = conn.info[LOCKED]
    rids = {r for r in (row_id(i, conn) for i in session_ids if i is not None)
            if r is not None and r not in locked.sessions}
    if rids:
        for s in _sessions_of(conn.execute(SESSIONS_POINTS, {"b_ids": sorted(rids)})):
            locked.sessions[s.id] = s


def entry(conn: Connection, controller_id: int, table: str, number: int) -> EntryRow:
    """One slot (as ``crud.get_entry``, with its 404s)."""
    check_slot_address(conn, controller_id, table, number)
    row = conn.execute(ENTRY, {"b_cid": controller_id, "b_table": table,
                               "b_number": number}).first()
    if row is None:
        raise NotFound(("number",), f"no {table} {number} on controller {controller_id}")
    return EntryRow(row._mapping)
