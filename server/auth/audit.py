"""The audit trail: an append-only record of every change, written in the change's transaction.

A ``before_flush`` hook on every ORM session turns the changed rows into ``AuditRecord`` rows,
so the routes do not write the audit themselves and no change can skip it:

- a new ``EntryHistory`` row (calibration save, numeric edit, restore of a history entry,
  controller-file import) -> ``frame.<reason>`` with the slot's changed fields before -> after,
  and for a calibration the report's quality figures (RMS, max, 95 % bound);
- a controller created or deleted -> ``controller.create`` / ``controller.delete``;
- the emulated arm's physics changed -> ``emulator.physics``;
- users, tokens and roles added or revoked -> ``user.*`` / ``token.*`` / ``role.add``;
- a JSON backup restore (the route marks the operation ``backup.restore``) -> one record per
  slot it changed, plus the route's summary record (history rows before -> after).

Who, from where and under which request come from :data:`CONTEXT`, set by the auth guard
(REST, pendant) or the CLI. The table has no foreign key, so a controller delete or a backup
restore cascades through the controller's tables and never reaches the audit.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from sqlalchemy import event, inspect, select
from sqlalchemy.orm import Session

from db.auth_models import ApiToken, AuditRecord, Role, User
from db.models import CalibSession, Controller, EntryHistory, FrameEntry

PENDING_IDS = "pendant_audit_pending_ids"
AUDITED = "pendant_audit_recorded"  # Session.info: this transaction has an audit record
WROTE = "pendant_audit_wrote"  # Session.info: this transaction changed a row
QUALITY_KEYS = ("rms_error_mm", "max_error_mm", "position_bound95_mm", "angle_bound95_deg")


@dataclass
class AuditContext:
    """Who is changing things, through which face, under which request."""

    user_name: str | None
    role: str | None
    source: str  # api | pendant | cli | opcua | system
    request_id: str | None = None
    client: str | None = None
    operation: str | None = None  # set by a route for a multi-row operation (backup.restore)
    extra: dict[str, Any] = field(default_factory=dict)


SYSTEM = AuditContext(None, None, "system")
CONTEXT: contextvars.ContextVar[AuditContext] = contextvars.ContextVar("pendant_audit",
                                                                       default=SYSTEM)


def current() -> AuditContext:
    return CONTEXT.get()


def mark_operation(operation: str) -> None:
    """Name the multi-row operation this request performs (its rows are audited under it)."""
    ctx = CONTEXT.get()
    if ctx is not SYSTEM:
        ctx.operation = operation


def actor() -> dict[str, Any]:
    """The current actor as plain values, for work done later elsewhere (a restore job)."""
    ctx = CONTEXT.get()
    return {"user_name": ctx.user_name, "role": ctx.role, "source": ctx.source,
            "request_id": ctx.request_id, "client": ctx.client}


@contextlib.contextmanager
def acting_as(who: dict[str, Any] | None, operation: str | None = None) -> Iterator[None]:
    """Audit what is flushed inside as ``who`` (an :func:`actor`), e.g. in a job's process."""
    token = CONTEXT.set(AuditContext(**who, operation=operation) if who else SYSTEM)
    try:
        yield
    finally:
        CONTEXT.reset(token)


def _jsonable(v: Any) -> Any:
    return v.isoformat() if isinstance(v, datetime) else v


def _diff(before: dict[str, Any], after: dict[str, Any]) -> tuple[dict, dict]:
    keys = [k for k in after if k != "updated_at" and before.get(k) != after.get(k)]
    return ({k: _jsonable(before.get(k)) for k in keys}, {k: _jsonable(after[k]) for k in keys})


def _record(db: Session, ctx: AuditContext, action: str, **kw: Any) -> AuditRecord:
    rec = AuditRecord(user_name=ctx.user_name, role=ctx.role, source=ctx.source,
                      request_id=ctx.request_id, client=ctx.client, action=action, **kw)
    db.add(rec)
    db.info[AUDITED] = True
    return rec


def _wrote(db: Session, _ctx: object) -> None:
    """``after_flush``: note that the transaction changed a row (for :func:`operation`)."""
    if db.new or db.deleted or any(db.is_modified(o) for o in db.dirty):
        db.info[WROTE] = True


def operation(db: Session, name: str, **kw: Any) -> None:
    """The audit record of an operation (a request, a face's command) that changed rows the
    row hooks do not record (a touch-up, a jog, a compute, an opened session...): one record
    ``op.<name>`` of the current actor, in the operation's own transaction, unless a hook
    already recorded the change (a frame, a controller, a user...). Called by the request
    path (``server.api.deps``) just before the commit, so every write is audited."""
    db.flush()
    wrote, audited = db.info.pop(WROTE, False), db.info.pop(AUDITED, False)
    if wrote and not audited:
        record(db, f"op.{name}"[:32], **{k: v for k, v in kw.items() if v is not None})


def _after_flush(db: Session, _ctx: object) -> None:
    """A new controller's id exists only after the flush: copy it into its audit record
    (the commit flushes that change too, in the same transaction)."""
    for rec, obj in db.info.pop(PENDING_IDS, []):
        rec.controller_id = obj.id


def _changes(obj: object, attrs: tuple[str, ...]) -> tuple[dict, dict]:
    state = inspect(obj)
    before, after = {}, {}
    for a in attrs:
        h = state.attrs[a].history
        if h.has_changes():
            before[a] = _jsonable(h.deleted[0]) if h.deleted else None
            after[a] = _jsonable(h.added[0]) if h.added else None
    return before, after


def _quality(db: Session, session_id: int | None) -> dict[str, Any] | None:
    s = db.get(CalibSession, session_id) if session_id else None
    report = (s.report or {}) if s is not None else {}
    q = {k: report.get(k) for k in QUALITY_KEYS if report.get(k) is not None}
    return q or None


def _before_flush(db: Session, _ctx: object, _instances: object) -> None:
    ctx = CONTEXT.get()
    restoring = ctx.operation == "backup.restore"
    for obj in list(db.new):
        if isinstance(obj, EntryHistory):
            obj.changed_by = None if restoring else ctx.user_name
            if restoring:
                continue  # rows of the backup document, not changes (see the summary record)
            before, after = _diff(obj.before or {}, obj.after or {})
            _record(db, ctx, f"frame.{obj.reason}", controller_id=obj.controller_id,
                    entry_table=obj.entry_table, number=obj.number, session_id=obj.session_id,
                    before=before, after=after,
                    quality=_quality(db, obj.session_id) if obj.reason == "calibration" else None)
        elif isinstance(obj, Controller):
            rec = _record(db, ctx, "controller.create",
                          after={"name": obj.name, "robot": obj.robot_key,
                                 "custom_robot": obj.custom_robot is not None})
            db.info.setdefault(PENDING_IDS, []).append((rec, obj))
        elif isinstance(obj, User):
            _record(db, ctx, "user.add", after={"name": obj.name, "role": obj.role})
        elif isinstance(obj, ApiToken):
            _record(db, ctx, "token.create", after={"user_id": obj.user_id, "label": obj.label,
                                                    "expires_at": _jsonable(obj.expires_at)})
        elif isinstance(obj, Role):
            _record(db, ctx, "role.add",
                    after={"name": obj.name, "permissions": list(obj.permissions)})
    for obj in list(db.dirty):
        if isinstance(obj, FrameEntry) and db.is_modified(obj, include_collections=False):
            obj.updated_by = ctx.user_name
            if restoring:
                before, after = _changes(obj, FRAME_ATTRS)
                if after:
                    _record(db, ctx, "backup.restore", controller_id=obj.controller_id,
                            entry_table=obj.entry_table, number=obj.number,
                            before=before, after=after)
        elif isinstance(obj, Controller):
            before, after = _changes(obj, ("physics",))
            if after:
                _record(db, ctx, "emulator.physics", controller_id=obj.id, before=before,
                        after=after)
        elif isinstance(obj, User):
            before, after = _changes(obj, ("role", "revoked_at"))
            if after:
                _record(db, ctx, "user.revoke" if "revoked_at" in after else "user.change",
                        before={"name": obj.name, **before}, after={"name": obj.name, **after})
        elif isinstance(obj, ApiToken):
            before, after = _changes(obj, ("revoked_at",))
            if after:
                _record(db, ctx, "token.revoke", before={"token_id": obj.id, **before},
                        after={"token_id": obj.id, **after})
    for obj in list(db.deleted):
        if isinstance(obj, Controller):
            n_hist = len(db.scalars(select(EntryHistory.id).where(
                EntryHistory.controller_id == obj.id)).all())
            _record(db, ctx, "controller.delete", controller_id=obj.id,
                    before={"name": obj.name, "robot": obj.robot_key, "history_rows": n_hist})


FRAME_ATTRS = ("name", "kind", "x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg", "mass_kg",
               "com_x_mm", "com_y_mm", "com_z_mm", "inertia_x_kgm2", "inertia_y_kgm2",
               "inertia_z_kgm2", "method", "session_id", "error_max_mm", "error_rms_mm")


def record(db: Session, action: str, **kw: Any) -> None:
    """An audit record of the current actor for an operation the row hooks do not see whole."""
    _record(db, CONTEXT.get(), action, **kw)


def install() -> None:
    """Hook every ORM session (idempotent)."""
    if not event.contains(Session, "before_flush", _before_flush):
        event.listen(Session, "before_flush", _before_flush)
        event.listen(Session, "after_flush_postexec", _after_flush)
        event.listen(Session, "after_flush", _wrote)


# ---------------------------------------------------------------------------------- reads

def query(db: Session, controller_id: int | None = None, entry_table: str | None = None,
          number: int | None = None, user: str | None = None, since: datetime | None = None,
          until: datetime | None = None, limit: int = 1000) -> list[AuditRecord]:
    q = select(AuditRecord)
    if controller_id is not None:
        q = q.where(AuditRecord.controller_id == controller_id)
    if entry_table is not None:
        q = q.where(AuditRecord.entry_table == entry_table)
    if number is not None:
        q = q.where(AuditRecord.number == number)
    if user is not None:
        q = q.where(AuditRecord.user_name == user)
    if since is not None:
        q = q.where(AuditRecord.at >= since)
    if until is not None:
        q = q.where(AuditRecord.at <= until)
    return list(db.scalars(q.order_by(AuditRecord.id).limit(limit)))
