"""Reads and writes of the pendant's tables. Every change of a slot leaves a history row.

Functions take a SQLAlchemy ``Session`` and commit nothing themselves unless they say so;
a request commits once, in its route's thread (``server.api.deps.one_thread``).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Any

from sqlalchemy import Connection, bindparam, func, select, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, joinedload

from db.models import (BASE_SLOTS, TOOL_SLOTS, CalibSession, Controller, ControllerFile,
                       EntryHistory, ExternalKinematic, FrameEntry, StoredDocument, TaughtPoint,
                       utcnow)
from db.outbox import emit

SLOTS = {"tool": TOOL_SLOTS, "base": BASE_SLOTS}  # the tables of a new controller (KUKA's)
# An ABB controller has no tool or work-object table: it holds as many tooldata and wobjdata
# as its modules declare. An ABB-kind controller's tables grow to what an imported module
# declares, up to this many slots each (a bound on the database, not RAPID's).
ABB_SLOTS = 999
SESSION_WITH_POINTS = [joinedload(CalibSession.points)]
ENTRY = select(FrameEntry).where(  # one slot (built once: every slot read and write uses it)
    FrameEntry.controller_id == bindparam("controller_id"),
    FrameEntry.entry_table == bindparam("table"), FrameEntry.number == bindparam("number"))
MAX_ID = 2**63 - 1  # SQLite INTEGER: a larger id cannot be a row (and would overflow the driver)
MAX_ID_OF = {"postgresql": 2**31 - 1}  # INTEGER primary keys of other backends (PostgreSQL int4)
DEFAULT_KIND = {"tool": "tool", "base": "base"}
KINDS_OF_TABLE = {"tool": ("tool", "workpiece"),
                  "base": ("base", "fixed_tool", "coordinated_base")}


class NotFound(LookupError):
    """Something addressed by the path does not exist; ``loc`` names the path parameter."""

    def __init__(self, loc: tuple[str | int, ...], reason: str):
        super().__init__(reason)
        self.loc, self.reason = tuple(loc), reason


class StateConflict(Exception):
    """The request does not fit the current state (saving an uncomputed session, ...)."""

    def __init__(self, loc: tuple[str | int, ...], reason: str):
        super().__init__(reason)
        self.loc, self.reason = tuple(loc), reason


# ----------------------------------------------------------------------------- controllers

def create_controller(db: Session, name: str, robot_key: str | None, custom_robot: dict | None,
                      cell_seed: int, joints_deg: Sequence[float]) -> Controller:
    """A controller with empty tool (16) and base (32) tables."""
    if db.scalar(select(Controller).where(Controller.name == name)) is not None:
        raise StateConflict(("body", "name"), f"a controller named {name!r} exists already")
    c = Controller(name=name, robot_key=robot_key, custom_robot=custom_robot, cell_seed=cell_seed,
                   joints_deg=[float(q) for q in joints_deg], active_tool_no=0, active_base_no=0)
    for table, n in SLOTS.items():
        for k in range(1, n + 1):
            e = FrameEntry(entry_table=table, number=k, name="", kind=DEFAULT_KIND[table])
            e.set_pose_values((0.0,) * 6)
            c.entries.append(e)
    db.add(c)
    try:
        with db.begin_nested():
            db.flush()
    except IntegrityError:  # another process created the same name meanwhile
        raise StateConflict(("body", "name"), f"a controller named {name!r} exists already") \
            from None
    return c


def max_id(db: Session | Connection) -> int:
    """The largest row id of this backend (ids are INTEGER primary keys)."""
    bind = db.get_bind() if isinstance(db, Session) else db
    return MAX_ID_OF.get(bind.dialect.name, MAX_ID)


def _row_id(value: int, db: Session | Connection | None = None) -> int | None:
    """``value`` if it can be a row id of ``db``'s backend, else None (not found, rather than an
    overflow in the driver or the server)."""
    limit = MAX_ID if db is None else max_id(db)
    return value if -limit <= value <= limit else None


def _get(db: Session, model: type, row_id: int, **kw: Any) -> Any:
    rid = _row_id(row_id, db)
    return None if rid is None else db.get(model, rid, **kw)


def lock_controller(db: Session | Connection, controller_id: int) -> None:
    """Start the request's write: lock the controller's row until commit (``SELECT ... FOR
    UPDATE`` on PostgreSQL; on SQLite the transaction's ``BEGIN IMMEDIATE`` already locks the
    database). Everything the request then reads of this controller is what it will change."""
    rid = _row_id(controller_id, db)
    if rid is not None:
        db.execute(select(Controller.id).where(Controller.id == rid).with_for_update())


def get_controller(db: Session, controller_id: int) -> Controller:
    c = _get(db, Controller, controller_id)
    if c is None:
        raise NotFound(("controller_id",), f"no controller {controller_id}")
    return c


def find_controller(db: Session, name_or_id: str) -> Controller:
    c = db.scalar(select(Controller).where(Controller.name == name_or_id))
    if c is None and name_or_id.isdigit():
        c = _get(db, Controller, int(name_or_id))
    if c is None:
        raise NotFound(("controller",), f"no controller named {name_or_id!r}")
    return c


def list_controllers(db: Session) -> list[Controller]:
    return list(db.scalars(select(Controller).order_by(Controller.id)))


def delete_controller(db: Session, controller: Controller) -> None:
    db.delete(controller)


# -------------------------------------------------------------------------------- entries

def is_abb(c: Controller) -> bool:
    """An ABB-kind controller (an ABB arm of the library): its tables hold what its RAPID
    modules declare (:data:`ABB_SLOTS`); any other holds KUKA's 16 tools and 32 bases."""
    return (c.robot_key or "").startswith("abb_")


def slot_limit(c: Controller, table: str) -> int:
    """The highest slot number ``table`` of controller ``c`` may have."""
    return ABB_SLOTS if is_abb(c) else SLOTS[table]


def find_entry(db: Session, controller_id: int, table: str, number: int) -> FrameEntry | None:
    """Slot ``number`` of the controller's ``table``, or None where the table has no such row."""
    return db.scalar(ENTRY, {"controller_id": controller_id, "table": table, "number": number})


def empty_entry(table: str, number: int) -> FrameEntry:
    """An unused slot, not in the database (what a table would grow with)."""
    e = FrameEntry(entry_table=table, number=number, name="", kind=DEFAULT_KIND[table])
    e.set_pose_values((0.0,) * 6)
    return e


def ensure_entry(db: Session, c: Controller, table: str, number: int) -> FrameEntry:
    """Slot ``number`` of ``c``, made (unused) when an ABB-kind controller's table grows to
    it; NotFound past :func:`slot_limit`."""
    limit = slot_limit(c, table)
    if not 1 <= number <= limit:
        raise NotFound(("number",), f"{table} slots of controller {c.name!r} are numbered "
                       f"1..{limit}, got {number}")
    e = find_entry(db, c.id, table, number)
    if e is None:
        e = empty_entry(table, number)
        e.controller_id = c.id
        db.add(e)
        db.flush()
    return e


def check_slot_address(db: Session | Connection, controller_id: int, table: str,
                       number: int) -> None:
    """404 naming the path parameter for a slot number out of every table's range (an
    existing number is checked by the read), or a controller id no row of this backend can
    have."""
    if not 1 <= number <= ABB_SLOTS:
        raise NotFound(("number",), f"{table} slots are numbered 1..{ABB_SLOTS} at most, "
                       f"got {number}")
    if _row_id(controller_id, db) is None:
        raise NotFound(("controller_id",), f"no controller {controller_id}")


def get_entry(db: Session, controller_id: int, table: str, number: int) -> FrameEntry:
    check_slot_address(db, controller_id, table, number)
    e = db.scalar(ENTRY, {"controller_id": controller_id, "table": table, "number": number})
    if e is None:
        raise NotFound(("number",), _missing_slot(db, controller_id, table, number))
    return e


def _missing_slot(db: Session, controller_id: int, table: str, number: int) -> str:
    """Why slot ``number`` is not there: past the controller kind's numbering (KUKA's 16
    tools and 32 bases), or past what an ABB-kind controller's table has grown to."""
    c = get_controller(db, controller_id)
    limit = slot_limit(c, table)
    if number > limit:
        return f"{table} slots of controller {c.name!r} are numbered 1..{limit}, got {number}"
    count = db.scalar(select(func.count()).select_from(FrameEntry).where(
        FrameEntry.controller_id == controller_id, FrameEntry.entry_table == table))
    return (f"no {table} {number} on controller {c.name!r}: its {table} table has {count} "
            f"slots (an import of its controller's module grows it, up to {limit})")


def list_entries(db: Session, controller_id: int, table: str | None = None,
                 kind: str | None = None) -> list[FrameEntry]:
    q = select(FrameEntry).where(FrameEntry.controller_id == controller_id)
    if table:
        q = q.where(FrameEntry.entry_table == table)
    if kind:
        q = q.where(FrameEntry.kind == kind)
    return list(db.scalars(q.order_by(FrameEntry.entry_table.desc(), FrameEntry.number)))


ENTRY_FIELDS = ("name", "kind", "x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg", "mass_kg",
                "com_x_mm", "com_y_mm", "com_z_mm", "inertia_x_kgm2", "inertia_y_kgm2",
                "inertia_z_kgm2", "inertia_a_deg", "inertia_b_deg", "inertia_c_deg", "mech_unit",
                "method", "session_id", "error_max_mm", "error_rms_mm",
                "updated_at")


def snapshot(e: FrameEntry) -> dict[str, Any]:
    """The slot's values as a plain dict (the history's before/after)."""
    out = {f: getattr(e, f) for f in ENTRY_FIELDS}
    out["updated_at"] = e.updated_at.isoformat() if e.updated_at else None
    return out


EXT_POSE = ("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg")
EXT_FIELDS = ("name", "kind", "axes", *EXT_POSE, *(f"flange_{k}" for k in EXT_POSE), "scale",
              "method", "session_id", "error_max_mm", "error_rms_mm", "updated_at")


def ext_snapshot(e: ExternalKinematic) -> dict[str, Any]:
    """An external kinematic's values as a plain dict (its history's before/after, backups)."""
    out = {f: getattr(e, f) for f in EXT_FIELDS}
    out["updated_at"] = e.updated_at.isoformat() if e.updated_at else None
    return out


def list_external(db: Session, controller_id: int) -> list[ExternalKinematic]:
    """The external kinematics stored for a controller (slots never written are not rows)."""
    return list(db.scalars(select(ExternalKinematic).where(
        ExternalKinematic.controller_id == controller_id).order_by(ExternalKinematic.number)))


def apply_snapshot(e: FrameEntry, snap: dict[str, Any]) -> None:
    for f in ENTRY_FIELDS:
        if f == "updated_at" or f not in snap:
            continue
        setattr(e, f, snap[f])


def change_entry(db: Session, e: FrameEntry, values: dict[str, Any], reason: str,
                 session_id: int | None = None) -> EntryHistory:
    """Set ``values`` (ENTRY_FIELDS) on the slot and record the change with before and after.

    Raises ValueError for a kind the table does not hold (the route checks it first).
    """
    before = snapshot(e)
    if "kind" in values and values["kind"] not in KINDS_OF_TABLE[e.entry_table]:
        kinds = " or ".join(KINDS_OF_TABLE[e.entry_table])
        raise ValueError(f"a {e.entry_table} slot holds {kinds}, not {values['kind']!r}")
    for k, v in values.items():
        setattr(e, k, v)
    e.updated_at = utcnow()
    h = EntryHistory(controller_id=e.controller_id, entry_table=e.entry_table, number=e.number,
                     reason=reason, session_id=session_id, before=before, after=snapshot(e))
    db.add(h)
    db.flush()
    emit(db, "frame-committed", e.controller, {
        "table": e.entry_table, "number": e.number, "reason": reason, "session_id": session_id,
        **{k: v for k, v in h.after.items() if k != "session_id"}})
    return h


def history(db: Session, controller_id: int, table: str | None = None,
            number: int | None = None) -> list[EntryHistory]:
    q = select(EntryHistory).where(EntryHistory.controller_id == controller_id)
    if table:
        q = q.where(EntryHistory.entry_table == table)
    if number is not None:
        q = q.where(EntryHistory.number == number)
    return list(db.scalars(q.order_by(EntryHistory.id)))


def get_history(db: Session, e: FrameEntry, history_id: int) -> EntryHistory:
    """History row ``history_id`` of slot ``e``; NotFound naming ``history_id`` otherwise."""
    h = _get(db, EntryHistory, history_id)
    slot = (e.controller_id, e.entry_table, e.number)
    if h is None or (h.controller_id, h.entry_table, h.number) != slot:
        raise NotFound(("history_id",),
                       f"no history entry {history_id} for {e.entry_table} {e.number}")
    return h


def restore_entry(db: Session, e: FrameEntry, history_id: int) -> EntryHistory:
    """Put the slot back to the state *before* history row ``history_id`` (recorded as a change)."""
    h = get_history(db, e, history_id)
    values = {f: h.before[f] for f in ENTRY_FIELDS if f in h.before and f != "updated_at"}
    return change_entry(db, e, values, reason="restore", session_id=h.session_id)


# ------------------------------------------------------------------------ controller files

def get_controller_file(db: Session, controller_id: int, fmt: str) -> ControllerFile | None:
    """The file last imported in ``fmt`` (kept to patch values into on export), if any."""
    return db.scalar(select(ControllerFile).where(ControllerFile.controller_id == controller_id,
                                                  ControllerFile.format == fmt))


def list_controller_files(db: Session, controller_id: int) -> list[ControllerFile]:
    return list(db.scalars(select(ControllerFile).where(
        ControllerFile.controller_id == controller_id).order_by(ControllerFile.format)))


def store_controller_file(db: Session, controller_id: int, fmt: str, text: str,
                          encoding: str = "utf-8") -> None:
    """Keep ``text`` as the controller's ``fmt`` file (replacing an earlier one), with the
    encoding its bytes were in (an export writes it back in that encoding)."""
    row = get_controller_file(db, controller_id, fmt)
    if row is None:
        db.add(ControllerFile(controller_id=controller_id, format=fmt, text=text,
                              encoding=encoding))
    else:
        row.text, row.encoding, row.imported_at = text, encoding, utcnow()
    db.flush()


# ------------------------------------------------------------------------------- sessions

def open_session(db: Session, controller: Controller, method: str, target_table: str,
                 target_no: int, params: dict[str, Any],
                 opened_by: str | None = None) -> CalibSession:
    s = CalibSession(controller_id=controller.id, method=method, target_table=target_table,
                     target_no=target_no, params=params, state="open", opened_by=opened_by)
    db.add(s)
    db.flush()
    return s


def get_session(db: Session, controller_id: int, session_id: int) -> CalibSession:
    """The session with its taught points (one query: every use of a session reads them)."""
    s = _get(db, CalibSession, session_id, options=SESSION_WITH_POINTS)
    if s is None or s.controller_id != controller_id:
        raise NotFound(("session_id",), f"no session {session_id} on controller {controller_id}")
    return s


def list_sessions(db: Session, controller_id: int, state: str | None = None) -> list[CalibSession]:
    q = select(CalibSession).where(CalibSession.controller_id == controller_id)
    if state:
        q = q.where(CalibSession.state == state)
    return list(db.scalars(q.order_by(CalibSession.id)))


def require_open(s: CalibSession) -> None:
    if s.state in ("saved", "discarded"):
        raise StateConflict(("path", "session_id"), f"session {s.id} is {s.state}; open a new one")


def put_point(db: Session, s: CalibSession, step: int, source: str, pose_values: Sequence[float],
              joints_deg: Sequence[float] | None = None, beam_id: str | None = None,
              edge: str | None = None, velocity_mm_s: Sequence[float] | None = None,
              t_s: float | None = None,
              motion_sign: Sequence[float] | None = None,
              external_axes: dict[str, float] | None = None) -> TaughtPoint:
    """Fill (or re-teach) one step; a new touch-up makes an earlier result stale.

    ``t_s`` is the emulated clock at the touch-up and ``motion_sign`` the direction each
    joint last moved before it (both for the session's ``robot-recording/1`` export)."""
    require_open(s)
    p = next((p for p in s.points if p.step == step), None)
    if p is None:
        p = TaughtPoint(step=step)
        s.points.append(p)
    else:  # a re-teach: the row is overwritten in place (one UPDATE, not DELETE + INSERT)
        p.created_at = utcnow()
    p.source = source
    p.joints_deg = None if joints_deg is None else [float(q) for q in joints_deg]
    p.beam_id, p.edge = beam_id, edge
    p.t_s = None if t_s is None else float(t_s)
    p.motion_sign = None if motion_sign is None else [float(v) for v in motion_sign]
    p.external_axes = None if not external_axes else {k: float(v)
                                                      for k, v in external_axes.items()}
    p.set_pose_values(pose_values)
    p.vx_mm_s, p.vy_mm_s, p.vz_mm_s = ((None, None, None) if velocity_mm_s is None
                                       else (float(v) for v in velocity_mm_s))
    _stale(s)
    return p  # flushed with the request's next query, ETag or commit


def touch_session(s: CalibSession) -> None:
    """Mark a change of the session (its points too): bumps its version (the ETag)."""
    s.updated_at = utcnow()


def delete_point(db: Session, s: CalibSession, step: int) -> None:
    require_open(s)
    p = next((p for p in s.points if p.step == step), None)
    if p is None:
        raise NotFound(("step",), f"step {step} of session {s.id} is not taught")
    s.points.remove(p)
    _stale(s)
    db.flush()


def clear_points(db: Session, s: CalibSession) -> None:
    require_open(s)
    s.points.clear()
    _stale(s)
    db.flush()


def _stale(s: CalibSession) -> None:
    touch_session(s)
    if s.state == "computed":
        s.state = "open"
        s.report = None
        s.set_result_values(None)


def store_result(db: Session, s: CalibSession, pose_values: Sequence[float],
                 report: dict[str, Any]) -> CalibSession:
    require_open(s)
    s.set_result_values(pose_values)
    s.report = report
    s.state = "computed"
    s.computed_at = utcnow()
    touch_session(s)
    db.flush()
    return s


def close_session(db: Session, s: CalibSession, state: str) -> None:
    s.state = state
    s.closed_at = utcnow()
    touch_session(s)
    db.flush()


# ------------------------------------------------------------------------------ backup

def _iso(t: datetime | None) -> str | None:
    return t.isoformat() if t else None


def backup(db: Session, c: Controller) -> dict[str, Any]:
    """The whole controller as one JSON document: robot, tables, history, sessions and points."""
    def point(p: TaughtPoint) -> dict[str, Any]:
        vel = None if p.vx_mm_s is None else [p.vx_mm_s, p.vy_mm_s, p.vz_mm_s]
        return {"step": p.step, "source": p.source, "pose": list(p.pose_values()),
                "joints_deg": p.joints_deg, "beam_id": p.beam_id, "edge": p.edge,
                "velocity_mm_s": vel, "t_s": p.t_s, "motion_sign": p.motion_sign,
                "external_axes": p.external_axes}

    return {
        "format": "pendant-backup/1",
        "controller": {"name": c.name, "robot": c.robot_key, "custom_robot": c.custom_robot,
                       "cell_seed": c.cell_seed, "joints_deg": c.joints_deg,
                       "active_tool_no": c.active_tool_no, "active_base_no": c.active_base_no,
                       "external_axes": c.external_axes, "external_errors": c.external_errors},
        "entries": [{"table": e.entry_table, "number": e.number, **snapshot(e)}
                    for e in list_entries(db, c.id)],
        "external_kinematics": [{"number": e.number, **ext_snapshot(e)}
                                for e in list_external(db, c.id)],
        "history": [_history_doc(h) for h in history(db, c.id) if h.entry_table != "extkin"],
        "external_history": [_history_doc(h) for h in history(db, c.id, "extkin")],
        "sessions": [{"id": s.id, "method": s.method, "target_table": s.target_table,
                      "target_no": s.target_no, "params": s.params, "state": s.state,
                      "created_at": _iso(s.created_at), "opened_by": s.opened_by,
                      "result": s.result_values(),
                      "report": s.report, "points": [point(p) for p in s.points]}
                     for s in list_sessions(db, c.id)],
        "files": [{"format": f.format, "text": f.text, "encoding": f.encoding}
                  for f in list_controller_files(db, c.id)],
    }


def _history_doc(h: EntryHistory) -> dict[str, Any]:
    return {"id": h.id, "table": h.entry_table, "number": h.number, "reason": h.reason,
            "session_id": h.session_id, "changed_at": _iso(h.changed_at), "before": h.before,
            "after": h.after}


def _dt(s: str | None) -> datetime | None:
    return datetime.fromisoformat(s) if s else None


def restore_backup(db: Session, c: Controller, doc: dict[str, Any]) -> tuple[int, int]:
    """Replace the controller's tables, history, sessions and kept controller files by a
    :func:`backup` document.

    Session ids are renumbered; provenance and history keep pointing at the right session.
    Returns (entries, history rows) restored. Raises KeyError/TypeError/ValueError on a
    malformed document (the route names the field).
    """
    for s in list_sessions(db, c.id):
        db.delete(s)
    for h in history(db, c.id):
        db.delete(h)
    db.flush()
    session_ids: dict[int, int] = {}
    for sd in doc.get("sessions", []):
        s = CalibSession(controller_id=c.id, method=sd["method"], target_table=sd["target_table"],
                         target_no=int(sd["target_no"]), params=sd.get("params") or {},
                         state=sd["state"], created_at=_dt(sd.get("created_at")) or utcnow(),
                         opened_by=sd.get("opened_by"),
                         report=sd.get("report"), updated_at=utcnow())  # made now (rows.py)
        s.set_result_values(sd.get("result"))
        for pd in sd.get("points", []):
            p = TaughtPoint(step=int(pd["step"]), source=pd["source"],
                            joints_deg=pd.get("joints_deg"), beam_id=pd.get("beam_id"),
                            edge=pd.get("edge"), t_s=pd.get("t_s"),
                            motion_sign=pd.get("motion_sign"),
                            external_axes=pd.get("external_axes"))
            p.set_pose_values(pd["pose"])
            if pd.get("velocity_mm_s"):
                p.vx_mm_s, p.vy_mm_s, p.vz_mm_s = (float(v) for v in pd["velocity_mm_s"])
            s.points.append(p)
        db.add(s)
        db.flush()
        session_ids[int(sd["id"])] = s.id
    n_entries = 0
    for ed in doc["entries"]:
        e = ensure_entry(db, c, ed["table"], int(ed["number"]))
        snap = dict(ed)
        snap["session_id"] = session_ids.get(ed.get("session_id")) if ed.get("session_id") else None
        apply_snapshot(e, snap)
        e.updated_at = _dt(ed.get("updated_at"))
        n_entries += 1
    # the re-made rows go on from the versions (ETags) of the rows they replace: back at 1, an
    # If-Match read before the restore could match a later state (a blind overwrite)
    versions = {}
    for e in list_external(db, c.id):
        versions[e.number] = e.version
        db.delete(e)
    db.flush()
    remade: list[ExternalKinematic] = []
    for xd in doc.get("external_kinematics", []):
        x = ExternalKinematic(controller_id=c.id, number=int(xd["number"]))
        for f in EXT_FIELDS:
            if f not in ("updated_at", "session_id") and f in xd:
                setattr(x, f, xd[f])
        x.session_id = session_ids.get(xd.get("session_id")) if xd.get("session_id") else None
        x.updated_at = _dt(xd.get("updated_at"))
        db.add(x)  # (the count stays the tool and base slots')
        remade.append(x)
    db.flush()
    for x in remade:  # (the ORM writes version 1 on every insert)
        if x.number in versions:
            db.execute(update(ExternalKinematic).where(ExternalKinematic.id == x.id)
                       .values(version=versions[x.number] + 1))
            db.expire(x, ["version"])
    n_hist = 0
    for hd in doc.get("history", []) + doc.get("external_history", []):
        db.add(EntryHistory(controller_id=c.id, entry_table=hd["table"], number=int(hd["number"]),
                            reason=hd["reason"], session_id=session_ids.get(hd.get("session_id")),
                            changed_at=_dt(hd.get("changed_at")) or utcnow(), before=hd["before"],
                            after=hd["after"]))
        n_hist += 1
    for f in list_controller_files(db, c.id):
        db.delete(f)
    db.flush()
    for fd in doc.get("files", []):
        db.add(ControllerFile(controller_id=c.id, format=fd["format"], text=fd["text"],
                              encoding=fd.get("encoding") or "utf-8"))
    ctl = doc.get("controller") or {}
    if "joints_deg" in ctl:
        c.joints_deg = [float(q) for q in ctl["joints_deg"]]
    c.active_tool_no = int(ctl.get("active_tool_no", c.active_tool_no))
    c.active_base_no = int(ctl.get("active_base_no", c.active_base_no))
    if "external_axes" in ctl:
        c.external_axes, c.external_errors = ctl["external_axes"], ctl.get("external_errors")
    db.flush()
    return n_entries, n_hist


# ----------------------------------------------------------------------- stored documents

COLLECTIONS = ("recordings", "analyses")


def store_document(db: Session, collection: str, doc: dict[str, Any]) -> int:
    """Keep a JSON document (a recording, an analysis report); returns its id."""
    if collection not in COLLECTIONS:
        raise ValueError(f"collection must be one of {COLLECTIONS}, got {collection!r}")
    row = StoredDocument(collection=collection, doc=doc)
    db.add(row)
    db.flush()
    return row.id


def exists_document(db: Session, collection: str, doc_id: int) -> bool:
    """Whether ``doc_id`` is a document of ``collection`` (without loading it)."""
    rid = _row_id(doc_id)
    return rid is not None and db.scalar(
        select(StoredDocument.id).where(StoredDocument.id == rid,
                                        StoredDocument.collection == collection)) is not None


def load_document(db: Session, collection: str, doc_id: int, loc: str) -> dict[str, Any]:
    """The document ``doc_id`` of ``collection``; NotFound naming ``loc`` if absent."""
    row = _get(db, StoredDocument, doc_id)
    if row is None or row.collection != collection:
        raise NotFound((loc,), f"no {collection[:-1]} {doc_id}")
    return row.doc
