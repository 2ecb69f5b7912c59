"""What the OPC UA face shows of a controller, read from the database as plain values.

The OPC UA server holds no state of its own: every ``poll`` reads the controllers, their
slots and open sessions into these frozen dataclasses, and the address space is updated
where a value differs from the last read. Several API workers or hosts write the same
database, so a change made anywhere reaches the OPC UA clients through the database.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from db import crud
from db.auth_models import AuditRecord
from db.models import CalibSession, Controller, Event, FrameEntry, TaughtPoint
from server.service.robot import robot_of


@dataclass(frozen=True)
class SlotState:
    """One TOOL_DATA / BASE_DATA slot: pose as KUKA x, y, z (mm), a, b, c (deg)."""

    table: str
    number: int
    name: str
    kind: str
    pose: tuple[float, ...]
    mass_kg: float | None
    com_mm: tuple[float, float, float]
    inertia_kgm2: tuple[float, float, float]
    version: int
    method: str | None
    error_rms_mm: float | None
    error_max_mm: float | None
    updated_at: str


@dataclass(frozen=True)
class SessionState:
    """An open or computed calibration session, as MES sees its progress."""

    id: int
    method: str
    target: str
    state: str
    points: int


@dataclass(frozen=True)
class ControllerState:
    id: int
    name: str
    created_at: str  # the row's creation time, UTC, as YYYYMMDDTHHMMSSffffffZ
    robot_name: str
    robot_key: str  # solvers.robots.ROBOTS key, "custom" for a custom DH table
    joints_deg: tuple[float, ...]
    joint_limits_deg: tuple[tuple[float, float], ...]
    active_tool_no: int
    active_base_no: int
    current_user: str  # the role (user level) of whoever last changed this controller, or ""
    slots: tuple[SlotState, ...]
    sessions: tuple[SessionState, ...]

    @property
    def node_key(self) -> str:
        """The root of this controller's NodeIds (docs/opcua.md): its name and when it was made,
        so a restart gives the same ids and a controller made again (same name, or an id
        SQLite hands out again) never gets a deleted one's. ``@`` keeps them apart from the
        face's own nodes (``Pendant``, the event type)."""
        return f"{self.name}@{self.created_at}"

    def slot(self, table: str, number: int) -> SlotState | None:
        return next((s for s in self.slots if s.table == table and s.number == number), None)


def slot_version(e: FrameEntry) -> int:
    """The slot's version as REST's ETag carries it (0 where the schema has none yet)."""
    return int(getattr(e, "version", 0) or 0)


def slot_state(e: FrameEntry) -> SlotState:
    def vec(*vals: Any) -> tuple[float, float, float]:
        return tuple(float(v or 0.0) for v in vals)  # type: ignore[return-value]

    return SlotState(
        table=e.entry_table, number=e.number, name=e.name, kind=e.kind,
        pose=tuple(float(v) for v in e.pose_values()), mass_kg=e.mass_kg,
        com_mm=vec(e.com_x_mm, e.com_y_mm, e.com_z_mm),
        inertia_kgm2=vec(e.inertia_x_kgm2, e.inertia_y_kgm2, e.inertia_z_kgm2),
        version=slot_version(e), method=e.method, error_rms_mm=e.error_rms_mm,
        error_max_mm=e.error_max_mm, updated_at=e.updated_at.isoformat() if e.updated_at else "")


def created_at(c: Controller) -> str:
    """When the controller's row was made, UTC, as ``YYYYMMDDTHHMMSSffffffZ``."""
    return c.created_at.strftime("%Y%m%dT%H%M%S%fZ")


def controller_state(db: Session, c: Controller,
                     slots: tuple[SlotState, ...] | None = None) -> ControllerState:
    """``c`` as the face shows it; ``slots`` when the caller knows they did not change."""
    robot = robot_of(c)
    live = db.execute(
        select(CalibSession.id, CalibSession.method, CalibSession.target_table,
               CalibSession.target_no, CalibSession.state, func.count(TaughtPoint.id))
        .outerjoin(TaughtPoint, TaughtPoint.session_id == CalibSession.id)
        .where(CalibSession.controller_id == c.id,
               CalibSession.state.in_(("open", "computed")))
        .group_by(CalibSession.id).order_by(CalibSession.id)).all()
    sessions = tuple(SessionState(sid, method, f"{table} {no}", st, n)
                     for sid, method, table, no, st, n in live)
    last = db.execute(select(AuditRecord.user_name, AuditRecord.role)
                      .where(AuditRecord.controller_id == c.id, AuditRecord.user_name.is_not(None))
                      .order_by(AuditRecord.id.desc()).limit(1)).first()
    if slots is None:
        slots = tuple(slot_state(e) for e in crud.list_entries(db, c.id))
    return ControllerState(
        id=c.id, name=c.name, robot_name=robot.name,
        robot_key="custom" if c.custom_robot else (c.robot_key or "kuka_kr6_r900_sixx"),
        created_at=created_at(c),
        current_user=(last[1] or "") if last else "",
        joints_deg=tuple(float(q) for q in c.joints_deg),
        joint_limits_deg=tuple((float(lo), float(hi)) for lo, hi in robot.limits_deg()),
        active_tool_no=c.active_tool_no, active_base_no=c.active_base_no,
        slots=slots, sessions=sessions)


def read_cells(make_session: sessionmaker[Session]) -> dict[int, ControllerState]:
    """Every controller's state by id, in one read transaction."""
    with make_session() as db:
        return {c.id: controller_state(db, c) for c in crud.list_controllers(db)}


class CellReader:
    """:func:`read_cells` for a poll: a few whole-table queries tell which controllers changed
    since the last read (their row, their slots' versions, their open sessions, a new audit
    record naming them); only those are read again, the others' states are the same objects
    as before (``is``: nothing to compare). A poll of 300 unchanged cells reads no slot, and a
    changed cell whose slots kept their rows and versions (a touch-up, a jog) keeps its slots
    (the ORM bumps a slot's version on every change)."""

    def __init__(self) -> None:
        self.states: dict[int, ControllerState] = {}
        self.marks: dict[int, tuple] = {}
        self.slot_rows: dict[int, list | None] = {}  # (id, version) of each controller's slots
        self.audit_id = -1

    def read(self, make_session: sessionmaker[Session]) -> dict[int, ControllerState]:
        with make_session() as db:
            marks: dict[int, list] = {
                row[0]: [tuple(row)] for row in db.execute(select(
                    Controller.id, Controller.version, Controller.name, Controller.created_at,
                    Controller.joints_deg, Controller.active_tool_no, Controller.active_base_no,
                    Controller.robot_key))}
            for cid, n, versions in db.execute(
                    select(FrameEntry.controller_id, func.count(), func.sum(FrameEntry.version))
                    .group_by(FrameEntry.controller_id)):
                if cid in marks:
                    marks[cid].append((n, versions))
            for cid, sid, state, version in db.execute(
                    select(CalibSession.controller_id, CalibSession.id, CalibSession.state,
                           CalibSession.version)
                    .where(CalibSession.state.in_(("open", "computed")))
                    .order_by(CalibSession.id)):
                if cid in marks:
                    marks[cid].append((sid, state, version))
            audit_id = int(db.scalar(select(func.max(AuditRecord.id))) or 0)
            audited: set[int] = set()
            if audit_id != self.audit_id and self.audit_id >= 0:
                audited = set(db.scalars(select(AuditRecord.controller_id).distinct().where(
                    AuditRecord.id > self.audit_id, AuditRecord.controller_id.is_not(None))))
            fresh = {cid: tuple(m) for cid, m in marks.items()}
            stale = [cid for cid, m in fresh.items()
                     if self.marks.get(cid) != m or cid in audited or cid not in self.states]
            if self.audit_id < 0:
                stale = list(fresh)
            read: dict[int, ControllerState] = {}
            slot_rows = {cid: [] for cid in stale}
            if stale:
                for cid, sid, version in db.execute(
                        select(FrameEntry.controller_id, FrameEntry.id, FrameEntry.version)
                        .where(FrameEntry.controller_id.in_(stale)).order_by(FrameEntry.id)):
                    slot_rows[cid].append((sid, version))
                rows = db.scalars(select(Controller).where(Controller.id.in_(stale))).all()
                for c in rows:  # a slot row of the same id and version is the same slot,
                    # of the same controller (SQLite hands out a deleted one's ids again)
                    old = self.states.get(c.id)
                    same = (old is not None and self.slot_rows.get(c.id) == slot_rows[c.id]
                            and (old.name, old.created_at) == (c.name, created_at(c)))
                    read[c.id] = controller_state(db, c, old.slots if same else None)
        states = {cid: read.get(cid) or self.states[cid] for cid in fresh
                  if cid in read or cid in self.states}
        self.states, self.audit_id = states, audit_id
        self.marks = {cid: m for cid, m in fresh.items() if cid in states}
        self.slot_rows = {cid: slot_rows[cid] if cid in slot_rows else self.slot_rows.get(cid)
                          for cid in states}
        return states


@dataclass(frozen=True)
class EventState:
    id: int
    kind: str
    controller: str | None
    payload: dict[str, Any]
    created_at: str


def latest_event_id(make_session: sessionmaker[Session]) -> int:
    """The newest event's id: the face raises what comes after it (no replay at start)."""
    with make_session() as db:
        return int(db.scalar(select(func.max(Event.id))) or 0)


def events_after(make_session: sessionmaker[Session], after_id: int,
                 limit: int = 500) -> list[EventState]:
    with make_session() as db:
        rows = db.scalars(select(Event).where(Event.id > after_id).order_by(Event.id).limit(limit))
        return [EventState(e.id, e.kind, e.controller_name, e.payload, e.created_at.isoformat())
                for e in rows]
