"""SQLAlchemy 2 typed models: one row per controller, table slot, history change, session, touch-up.

Poses are columns (``x_mm ... c_deg``), never JSON. JSON is kept for documents that are not
frames: a custom DH table, session parameters, the computed report and history snapshots.
"""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any

from sqlalchemy import (JSON, BigInteger, DateTime, Double, ForeignKey, LargeBinary, MetaData,
                        String, Text, TypeDecorator, UniqueConstraint)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}

TOOL_SLOTS = 16  # KUKA TOOL_DATA[1..16]
BASE_SLOTS = 32  # KUKA BASE_DATA[1..32]


def utcnow() -> datetime:
    return datetime.now(timezone.utc)


class UTCDateTime(TypeDecorator):
    """A UTC time stamp; SQLite stores no zone, so one read back is marked UTC again."""

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_result_value(self, value: datetime | None, dialect: object) -> datetime | None:
        if value is not None and value.tzinfo is None:
            return value.replace(tzinfo=timezone.utc)
        return value


def _controller_fk() -> ForeignKey:
    return ForeignKey("controller.id", ondelete="CASCADE")


def _session_fk(ondelete: str) -> ForeignKey:
    return ForeignKey("calib_session.id", ondelete=ondelete)


# SQLite gives a new row the largest id + 1, so deleting the newest controller (session, job,
# webhook, event, ...) handed its id to the next one made: an ETag, an audit query, an MES
# subscription or a webhook consumer's event id kept for the old row then named the new one.
# With AUTOINCREMENT SQLite never gives an id twice (revision 0012); PostgreSQL's sequences
# never did. Every table whose primary key is an integer id has it.
NO_ID_REUSE = {"sqlite_autoincrement": True}


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)
    # float -> DOUBLE as the migrations have it (SQLAlchemy 2.1's default; 2.0 would say FLOAT)
    type_annotation_map = {dict[str, Any]: JSON, list[float]: JSON, datetime: UTCDateTime(),
                           float: Double()}


class PoseColumns:
    """x, y, z in mm and KUKA a, b, c in degrees as six float columns."""

    x_mm: Mapped[float] = mapped_column(default=0.0)
    y_mm: Mapped[float] = mapped_column(default=0.0)
    z_mm: Mapped[float] = mapped_column(default=0.0)
    a_deg: Mapped[float] = mapped_column(default=0.0)
    b_deg: Mapped[float] = mapped_column(default=0.0)
    c_deg: Mapped[float] = mapped_column(default=0.0)

    def pose_values(self) -> tuple[float, float, float, float, float, float]:
        return (self.x_mm, self.y_mm, self.z_mm, self.a_deg, self.b_deg, self.c_deg)

    def set_pose_values(self, v: object) -> None:
        self.x_mm, self.y_mm, self.z_mm, self.a_deg, self.b_deg, self.c_deg = (float(x) for x in v)


class Controller(Base):
    """An emulated robot controller: its arm, its emulated cell and the pendant's state."""

    __tablename__ = "controller"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    robot_key: Mapped[str | None] = mapped_column(String(64))  # solvers.robots.ROBOTS key
    custom_robot: Mapped[dict[str, Any] | None]  # custom DH table (a document, not a frame)
    cell_seed: Mapped[int] = mapped_column(BigInteger, default=1)  # the cell's hidden truth
    joints_deg: Mapped[list[float]]  # the emulated robot's current joint values
    active_tool_no: Mapped[int] = mapped_column(default=0)  # 0 = flange
    active_base_no: Mapped[int] = mapped_column(default=0)  # 0 = world (robot base)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    # the arm's hidden physics (revision 0002): a solvers.physics.Imperfections document
    # (None = rigid), the emulated clock since power-on, the direction each joint last moved
    # (backlash) and a count of motions (seeds the operator's aim)
    physics: Mapped[dict[str, Any] | None]
    clock_s: Mapped[float] = mapped_column(default=0.0, server_default="0")
    motion_sign: Mapped[list[float] | None]
    motion_count: Mapped[int] = mapped_column(default=0, server_default="0")

    # revision 0003: bumped by every UPDATE of the row (the ETag of controller and robot)
    version: Mapped[int] = mapped_column(default=1, server_default="1")
    # revision 0008: the external axes' values {"E1": deg, ..., "E4": mm} (None = the cell has
    # none) and their hidden errors (emulator.external.ERROR_FIELDS; None = seeded defaults)
    external_axes: Mapped[dict[str, Any] | None]
    external_errors: Mapped[dict[str, Any] | None]

    entries: Mapped[list[FrameEntry]] = relationship(back_populates="controller",
                                                     cascade="all, delete-orphan")
    __mapper_args__ = {"version_id_col": version}


class FrameEntry(PoseColumns, Base):
    """A tool slot (KUKA TOOL_DATA[n]) or a base slot (BASE_DATA[n]).

    ``entry_table`` 'tool' holds robot-held tools and robot-held workpieces (T_flange_frame);
    'base' holds bases and fixed (external) tools (T_world_frame).
    """

    __tablename__ = "frame_entry"
    __table_args__ = (UniqueConstraint("controller_id", "entry_table", "number"), NO_ID_REUSE)

    id: Mapped[int] = mapped_column(primary_key=True)
    controller_id: Mapped[int] = mapped_column(_controller_fk(), index=True)
    entry_table: Mapped[str] = mapped_column(String(8))  # 'tool' | 'base'
    number: Mapped[int]  # 1..16 tools, 1..32 bases, as on the pendant
    name: Mapped[str] = mapped_column(String(64), default="")
    kind: Mapped[str] = mapped_column(String(16))  # tool|workpiece|base|fixed_tool|coordinated_base
    mass_kg: Mapped[float | None]
    com_x_mm: Mapped[float | None]
    com_y_mm: Mapped[float | None]
    com_z_mm: Mapped[float | None]
    inertia_x_kgm2: Mapped[float | None]
    inertia_y_kgm2: Mapped[float | None]
    inertia_z_kgm2: Mapped[float | None]
    # revision 0003_files: KUKA CM A, B, C (ABB aom) of the principal inertia axes, and the
    # mechanical unit that moves a coordinated_base (ABB ufmec, KUKA MACHINE_FRAME_DAT PARENT)
    inertia_a_deg: Mapped[float | None]
    inertia_b_deg: Mapped[float | None]
    inertia_c_deg: Mapped[float | None]
    mech_unit: Mapped[str | None] = mapped_column(String(32))
    method: Mapped[str | None] = mapped_column(String(32))  # provenance: which menu wrote it
    session_id: Mapped[int | None] = mapped_column(_session_fk("SET NULL"))
    error_max_mm: Mapped[float | None]
    error_rms_mm: Mapped[float | None]
    updated_at: Mapped[datetime | None]
    version: Mapped[int] = mapped_column(default=1, server_default="1")  # 0003: the slot's ETag
    updated_by: Mapped[str | None] = mapped_column(String(64))  # revision 0003_auth: the user

    controller: Mapped[Controller] = relationship(back_populates="entries")
    __mapper_args__ = {"version_id_col": version}


class EntryHistory(Base):
    """One change of a table slot: the slot before and after (snapshots), why, when."""

    __tablename__ = "entry_history"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    controller_id: Mapped[int] = mapped_column(_controller_fk(), index=True)
    entry_table: Mapped[str] = mapped_column(String(8))
    number: Mapped[int]
    reason: Mapped[str] = mapped_column(String(16))  # calibration | edit | restore | import
    session_id: Mapped[int | None] = mapped_column(_session_fk("SET NULL"))
    changed_at: Mapped[datetime] = mapped_column(default=utcnow)
    before: Mapped[dict[str, Any]]
    after: Mapped[dict[str, Any]]
    changed_by: Mapped[str | None] = mapped_column(String(64))  # revision 0003_auth: the user


class CalibSession(Base):
    """One run of a calibration menu: method, target slot, parameters, result once computed.

    The computed frame is stored as pose columns; the report (residuals, bounds, warnings)
    as the JSON document the API returns.
    """

    __tablename__ = "calib_session"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    controller_id: Mapped[int] = mapped_column(_controller_fk(), index=True)
    method: Mapped[str] = mapped_column(String(32))
    target_table: Mapped[str] = mapped_column(String(8))
    target_no: Mapped[int]
    params: Mapped[dict[str, Any]]
    state: Mapped[str] = mapped_column(String(16), default="open")  # open|computed|saved|discarded
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    computed_at: Mapped[datetime | None]
    closed_at: Mapped[datetime | None]
    result_x_mm: Mapped[float | None]
    result_y_mm: Mapped[float | None]
    result_z_mm: Mapped[float | None]
    result_a_deg: Mapped[float | None]
    result_b_deg: Mapped[float | None]
    result_c_deg: Mapped[float | None]
    report: Mapped[dict[str, Any] | None]
    # revision 0003: the session's ETag (bumped by every change, taught points included via
    # updated_at) and the target slot's version when the result was computed (save refuses a
    # slot that changed since)
    version: Mapped[int] = mapped_column(default=1, server_default="1")
    updated_at: Mapped[datetime | None]
    target_version: Mapped[int | None]
    # revision 0011: who opened it (the user name the audit records; NULL before 0011)
    opened_by: Mapped[str | None] = mapped_column(String(64))

    points: Mapped[list[TaughtPoint]] = relationship(back_populates="session",
                                                     order_by="TaughtPoint.step",
                                                     cascade="all, delete-orphan")
    __mapper_args__ = {"version_id_col": version}

    def result_values(self) -> tuple[float, ...] | None:
        v = (self.result_x_mm, self.result_y_mm, self.result_z_mm, self.result_a_deg,
             self.result_b_deg, self.result_c_deg)
        return None if v[0] is None else tuple(float(x) for x in v)  # type: ignore[arg-type]

    def set_result_values(self, v: object | None) -> None:
        vals = [None] * 6 if v is None else [float(x) for x in v]  # type: ignore[union-attr]
        (self.result_x_mm, self.result_y_mm, self.result_z_mm, self.result_a_deg, self.result_b_deg,
         self.result_c_deg) = vals


class TaughtPoint(PoseColumns, Base):
    """A touch-up: the flange pose (columns) of one step, its joints, or a beam trigger."""

    __tablename__ = "taught_point"
    __table_args__ = (UniqueConstraint("session_id", "step"), NO_ID_REUSE)

    id: Mapped[int] = mapped_column(primary_key=True)
    session_id: Mapped[int] = mapped_column(_session_fk("CASCADE"), index=True)
    step: Mapped[int]  # 0-based step of the menu
    source: Mapped[str] = mapped_column(String(16))  # touch_up | joints | flange_pose | beam
    joints_deg: Mapped[list[float] | None]
    beam_id: Mapped[str | None] = mapped_column(String(32))
    edge: Mapped[str | None] = mapped_column(String(8))  # enter | leave | tip
    vx_mm_s: Mapped[float | None]
    vy_mm_s: Mapped[float | None]
    vz_mm_s: Mapped[float | None]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    # revision 0002: the emulated clock at the touch-up / trigger (s since power-on) and the
    # direction each joint last moved before it (a recording's start_joints_deg)
    t_s: Mapped[float | None]
    motion_sign: Mapped[list[float] | None]
    # revision 0008: the external axes' values at the touch-up ({"E1": deg, "E4": mm})
    external_axes: Mapped[dict[str, Any] | None]

    session: Mapped[CalibSession] = relationship(back_populates="points")


EXT_KIN_SLOTS = 6  # KUKA EX_KIN 1..6 ($ET1_... .. $ET6_...)


class ExternalKinematic(PoseColumns, Base):
    """An external kinematic (KUKA EX_KIN[n], machine data ``$ETn_...``; ABB a mechanical unit):
    a turntable, a two-axis positioner or a linear unit, revision 0008.

    The pose columns are its root frame ``T_base_root`` (z the axis; a linear unit's
    ``T_base_rail``, z the travel direction); ``flange_*`` the flange offset (a positioner: the
    turn axis' root in the tilt flange, ``T_tiltflange_turnroot``; else identity). ``axes``
    names its external axes ("E1" or "E2,E3"). History rows are ``entry_history`` rows with
    ``entry_table = 'extkin'``.
    """

    __tablename__ = "external_kinematic"
    __table_args__ = (UniqueConstraint("controller_id", "number"), NO_ID_REUSE)

    id: Mapped[int] = mapped_column(primary_key=True)
    controller_id: Mapped[int] = mapped_column(_controller_fk(), index=True)
    number: Mapped[int]  # 1..6 as EX_KIN on the pendant
    name: Mapped[str] = mapped_column(String(64), default="")
    # none | turntable | positioner | linear_unit
    kind: Mapped[str] = mapped_column(String(16), default="none")
    axes: Mapped[str] = mapped_column(String(32), default="")  # "E1", "E2,E3"
    flange_x_mm: Mapped[float] = mapped_column(default=0.0)
    flange_y_mm: Mapped[float] = mapped_column(default=0.0)
    flange_z_mm: Mapped[float] = mapped_column(default=0.0)
    flange_a_deg: Mapped[float] = mapped_column(default=0.0)
    flange_b_deg: Mapped[float] = mapped_column(default=0.0)
    flange_c_deg: Mapped[float] = mapped_column(default=0.0)
    scale: Mapped[float | None]  # the calibrated travel/turn per counted unit (None = 1)
    method: Mapped[str | None] = mapped_column(String(32))  # provenance: which menu wrote it
    session_id: Mapped[int | None] = mapped_column(_session_fk("SET NULL"))
    error_max_mm: Mapped[float | None]
    error_rms_mm: Mapped[float | None]
    updated_at: Mapped[datetime | None]
    updated_by: Mapped[str | None] = mapped_column(String(64))
    version: Mapped[int] = mapped_column(default=1, server_default="1")
    __mapper_args__ = {"version_id_col": version}

    def flange_values(self) -> tuple[float, float, float, float, float, float]:
        return (self.flange_x_mm, self.flange_y_mm, self.flange_z_mm, self.flange_a_deg,
                self.flange_b_deg, self.flange_c_deg)


class StoredDocument(Base):
    """A JSON document kept as sent: a ``robot-recording/1`` or an ``analysis-report/1``.

    ``collection`` is 'recordings' or 'analyses' (see :func:`db.crud.store_document`).
    """

    __tablename__ = "stored_document"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    collection: Mapped[str] = mapped_column(String(16), index=True)
    doc: Mapped[dict[str, Any]]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class ControllerFile(Base):
    """The controller file last imported in a format, kept as sent (revision 0003_files).

    Export in that format patches the changed values into this text (docs/formats.md), so
    everything else in the file goes back onto the controller unchanged.
    """

    __tablename__ = "controller_file"
    __table_args__ = (UniqueConstraint("controller_id", "format"), NO_ID_REUSE)

    id: Mapped[int] = mapped_column(primary_key=True)
    controller_id: Mapped[int] = mapped_column(_controller_fk(), index=True)
    format: Mapped[str] = mapped_column(String(8))  # kuka | abb | fanuc | ur
    text: Mapped[str] = mapped_column(Text)
    encoding: Mapped[str] = mapped_column(String(16), default="utf-8",
                                          server_default="utf-8")  # utf-8 | cp1252 (0010)
    imported_at: Mapped[datetime] = mapped_column(default=utcnow)


class IdempotencyKey(Base):
    """A POST that carried ``Idempotency-Key``: its fingerprint and, once answered, the response.

    The row is inserted in the request's own transaction (so it exists only if the command's
    changes were committed) and the response is stored right after it is sent; see
    :mod:`server.api.idempotency`.
    """

    __tablename__ = "idempotency_key"

    key: Mapped[str] = mapped_column(String(255), primary_key=True)
    fingerprint: Mapped[str] = mapped_column(String(64))  # sha256 of method, path and body
    method: Mapped[str] = mapped_column(String(8))
    path: Mapped[str] = mapped_column(String(512))
    status: Mapped[int | None]
    headers: Mapped[dict[str, Any] | None]
    body: Mapped[bytes | None] = mapped_column(LargeBinary)
    created_at: Mapped[datetime] = mapped_column(default=utcnow, index=True)


class Job(Base):
    """Heavy work off the request path: an analysis, a JSON restore (see :mod:`db.jobs`).

    ``state`` goes queued -> running -> done | failed | cancelled. A worker process claims a
    queued job (``worker``, ``lease_until``: it renews the lease while it runs; a job whose
    lease ran out is claimed again), reports ``progress`` (0..1) and ``message``, and stores
    ``result`` (what the job made, e.g. ``{"analysis_id": 7}``) or ``error`` (the
    ``{"status", "detail"}`` the request would have answered).
    """

    __tablename__ = "job"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    kind: Mapped[str] = mapped_column(String(32))  # analysis | restore
    state: Mapped[str] = mapped_column(String(16), default="queued", index=True)
    # loaded when used (the worker that runs the job): a restore's are the whole backup, and
    # reading the job's state (a client polling its progress) read and decoded them each time
    params: Mapped[dict[str, Any]] = mapped_column(deferred=True)
    progress: Mapped[float] = mapped_column(default=0.0)
    message: Mapped[str] = mapped_column(String(200), default="")
    result: Mapped[dict[str, Any] | None]
    error: Mapped[dict[str, Any] | None]
    cancel_requested: Mapped[bool] = mapped_column(default=False)
    worker: Mapped[str | None] = mapped_column(String(128))
    attempts: Mapped[int] = mapped_column(default=0)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]
    lease_until: Mapped[datetime | None]


class Event(Base):
    """The outbox: one row per event (frame committed, calibration computed, import applied,
    analysis finished), written in the transaction of the change it reports.

    No foreign key: an event outlives a deleted controller. Webhook and MQTT deliveries are
    rows of their own; the OPC UA face reads new events by id.
    """

    __tablename__ = "event"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    kind: Mapped[str] = mapped_column(String(32), index=True)
    controller_id: Mapped[int | None]
    controller_name: Mapped[str | None] = mapped_column(String(64))
    payload: Mapped[dict[str, Any]]
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Webhook(Base):
    """A subscriber: events (all, or the kinds listed) are POSTed to ``url``, signed with
    HMAC-SHA256 under ``secret``."""

    __tablename__ = "webhook"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    url: Mapped[str] = mapped_column(String(2048))
    secret: Mapped[str] = mapped_column(String(128))
    kinds: Mapped[dict[str, Any] | None]  # {"kinds": [...]} or None for every kind
    active: Mapped[bool] = mapped_column(default=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Delivery(Base):
    """One event to one sink (a webhook, or the MQTT broker): attempts, back-off, outcome.

    ``state``: pending → sending (claimed by one dispatcher) → delivered | pending (retry at
    ``next_attempt_at``) | failed (attempts exhausted).
    """

    __tablename__ = "delivery"
    __table_args__ = NO_ID_REUSE

    id: Mapped[int] = mapped_column(primary_key=True)
    event_id: Mapped[int] = mapped_column(ForeignKey("event.id", ondelete="CASCADE"), index=True)
    sink: Mapped[str] = mapped_column(String(16))  # webhook | mqtt
    webhook_id: Mapped[int | None] = mapped_column(ForeignKey("webhook.id", ondelete="CASCADE"),
                                                   index=True)
    state: Mapped[str] = mapped_column(String(16), default="pending", index=True)
    attempts: Mapped[int] = mapped_column(default=0)
    next_attempt_at: Mapped[datetime] = mapped_column(default=utcnow)
    claimed_at: Mapped[datetime | None]
    delivered_at: Mapped[datetime | None]
    last_status: Mapped[int | None]
    last_error: Mapped[str | None] = mapped_column(String(512))
