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

import threading
import weakref
from collections import OrderedDict
from typing import Any

from sqlalchemy import Connection, and_, bindparam, select, tuple_

from db import pipeline
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
_SESSION_AND_POINT = (*(c.label(f"s_{c.name}") for c in S.c),
                      *(c.label(f"p_{c.name}") for c in P.c))
_SESSIONS_AND_POINTS = select(*_SESSION_AND_POINT) \
    .select_from(S.outerjoin(P, P.c.session_id == S.c.id))
SESSION_POINTS = _SESSIONS_AND_POINTS.where(S.c.id == bindparam("b_id")).order_by(P.c.step)
SESSIONS_POINTS = _SESSIONS_AND_POINTS.where(S.c.id.in_(bindparam("b_ids", expanding=True))) \
    .order_by(S.c.id, P.c.step)
# the same, without the points of the sessions whose (id, version) is in b_known (the
# process has them: SessionCache)
SESSIONS_POINTS_UNKNOWN = select(*_SESSION_AND_POINT) \
    .select_from(S.outerjoin(P, and_(P.c.session_id == S.c.id, tuple_(S.c.id, S.c.version)
                                     .not_in(bindparam("b_known", expanding=True))))) \
    .where(S.c.id.in_(bindparam("b_ids", expanding=True))).order_by(S.c.id, P.c.step)
C_NAMES, S_NAMES, P_NAMES = (tuple(c.name for c in t.c) for t in (C, S, P))
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
      together before the commit (``db.touch_up.write_locked``: one round trip on
      PostgreSQL).
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
    c = _controller_of(row)
    return c if locked is None else locked.keep(c)


def _controller_of(row: Any) -> ControllerRow:
    return ControllerRow(dict(zip(C_NAMES, row)))


def controllers(conn: Connection) -> list[ControllerRow]:
    return [_controller_of(r) for r in conn.execute(CONTROLLERS)]


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
    found = [] if rid is None else _sessions_of(conn.execute(SESSION_POINTS, {"b_id": rid}))
    if not found or found[0].controller_id != controller_id:
        raise NotFound(("session_id",), f"no session {session_id} on controller {controller_id}")
    (s,) = found
    if locked is not None:
        locked.sessions[s.id] = s
    return s


def _sessions_of(found: Any) -> list[SessionRow]:
    """Sessions with their points from rows of :data:`SESSION_POINTS` (ordered by session):
    the session's columns, then the point's (None for a session without points)."""
    n = len(S_NAMES)
    out: list[SessionRow] = []
    for r in found:
        r = tuple(r)
        if not out or out[-1].id != r[0]:
            out.append(SessionRow(dict(zip(S_NAMES, r[:n]))))
            out[-1].points = []
        if r[n] is not None:
            out[-1].points.append(PointRow(dict(zip(P_NAMES, r[n:]))))
    return out


class SessionCache:
    """Sessions with their points as this process's batches last committed them, each
    trusted while its row's (version, created_at) is unchanged.

    A session's version is its ETag: every change of it or of its points bumps it (the ORM's
    version counter, or :mod:`db.touch_up`) and sets ``updated_at``, so a session read again
    at the same version and ``updated_at`` has the same points. ``created_at`` and
    ``updated_at`` tell a new session from a deleted one whose id SQLite gave again (a
    restored backup's sessions are made at version 1, with their old ``created_at`` and an
    ``updated_at`` of the restore). One cache per database (:func:`session_cache`: per
    connection pool), bounded (the least recently used go first); it hands out copies of the
    points, which a batch's writers change.
    """

    def __init__(self, max_entries: int = 1024) -> None:
        self.max_entries = max_entries
        self._entries: OrderedDict[int, SessionRow] = OrderedDict()
        self._lock = threading.Lock()  # PostgreSQL's batches run in threads

    def version_of(self, session_id: int) -> int | None:
        with self._lock:
            s = self._entries.get(session_id)
        return None if s is None else s.version

    def points(self, s: SessionRow) -> list[PointRow] | None:
        """Copies of the cached points of the session whose row is ``s`` (read now), if it
        is cached with ``s``'s version, ``created_at`` and ``updated_at``."""
        with self._lock:
            cached = self._entries.get(s.id)
            if cached is None or _stamp(cached) != _stamp(s):
                return None
            self._entries.move_to_end(s.id)
        return [PointRow(p.__dict__) for p in cached.points]

    def put(self, sessions: Any) -> None:
        """Remember ``sessions`` (copies) as they now are in the database (committed)."""
        copies = [_copy(s) for s in sessions]
        with self._lock:
            for s in copies:
                self._entries[s.id] = s
                self._entries.move_to_end(s.id)
            while len(self._entries) > self.max_entries:
                self._entries.popitem(last=False)


def _stamp(s: SessionRow) -> tuple:
    return s.version, s.created_at, s.updated_at


_CACHES: weakref.WeakKeyDictionary[Any, SessionCache] = weakref.WeakKeyDictionary()
_CACHES_LOCK = threading.Lock()


def session_cache(conn: Connection) -> SessionCache:
    """The :class:`SessionCache` of ``conn``'s database (one per connection pool: an app's
    engines, its SQLite writers' included, share one)."""
    pool = conn.engine.pool
    with _CACHES_LOCK:
        cache = _CACHES.get(pool)
        if cache is None:
            cache = _CACHES[pool] = SessionCache()
        return cache


def read_locked(conn: Connection, controller_id: int | None, session_ids: Any) -> None:
    """In a batch (:class:`Locked`): lock and read controller ``controller_id`` (if given:
    PostgreSQL; a SQLite writer holds the database's lock already), then read the sessions
    the batch's writers will read (``session_ids``), in one query, into the batch (each writer
    then reads its own as a copy, :func:`session`). On PostgreSQL the two selects go in one
    round trip (:mod:`db.pipeline`; psycopg's ``BEGIN`` goes before, on its own).

    The points of a session the process's :class:`SessionCache` holds at its current version
    are not read again (a writer of another process may have changed it: then they are). An
    unknown controller, ids out of range or of no session are left for the writers to refuse.
    """
    locked = conn.info[LOCKED]
    cid = None if controller_id is None else row_id(controller_id, conn)
    rids = sorted({r for r in (row_id(i, conn) for i in session_ids if i is not None)
                   if r is not None and r not in locked.sessions})
    statements: list[tuple[Any, dict[str, Any]]] = []
    if cid is not None:
        statements.append((CONTROLLER_LOCKED, {"b_id": cid}))
    cache = session_cache(conn)
    known = {(r, v) for r in rids if (v := cache.version_of(r)) is not None}
    if rids:
        statements.append((SESSIONS_POINTS_UNKNOWN, {"b_ids": rids, "b_known": sorted(known)})
                          if known else (SESSIONS_POINTS, {"b_ids": rids}))
    if not statements:
        return
    found = pipeline.read(conn, statements) if pipeline.supported(conn) else \
        [conn.execute(stmt, params).all() for stmt, params in statements]
    if cid is not None:
        controller_rows = found.pop(0)
        if controller_rows:
            locked.keep(_controller_of(controller_rows[0]))
    for s in _sessions_of(found[0] if rids else ()):
        if (s.id, s.version) in known:  # read without its points
            points = cache.points(s)
            if points is None:  # another session at the cached one's id and version
                s = session(conn, s.controller_id, s.id)  # not in the batch yet: read
            else:
                s.points = points
        locked.sessions[s.id] = s


def entry(conn: Connection, controller_id: int, table: str, number: int) -> EntryRow:
    """One slot (as ``crud.get_entry``, with its 404s)."""
    check_slot_address(conn, controller_id, table, number)
    row = conn.execute(ENTRY, {"b_cid": controller_id, "b_table": table,
                               "b_number": number}).first()
    if row is None:
        raise NotFound(("number",), f"no {table} {number} on controller {controller_id}")
    return EntryRow(row._mapping)
