"""The ``pendant-backup/1`` JSON document (``GET .../export?format=json``), checked before restore.

:func:`parse_backup` reads the text of an import and returns the document as plain JSON values
that :func:`db.crud.restore_backup` can store as they are, or raises
:class:`~solvers.errors.CalibrationError` naming the field, e.g.
``("text", "sessions", 0, "points", 2, "pose")``. Nothing that a later read, compute, export or
restore cannot handle gets into the DB: unknown fields, NaN and Infinity, numbers out of range
(slot values: server/service/bounds.py, the same bounds as the API and the file import), an unknown
method or kind, a slot number the table does not have, a session result without its report.
"""

from __future__ import annotations

import json
from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from sqlalchemy.orm import Session

from db import jobs
from db.crud import ABB_SLOTS, KINDS_OF_TABLE, MAX_ID
from db.models import EXT_KIN_SLOTS, Controller, Job
from server.auth.audit import actor, mark_operation
from server.menus import METHODS
from server.service.bounds import MAX_T_S, MECH_UNIT_CHARS, Deg, Kg, Kgm2, Mm
from server.service.export import export_text
from server.service.robot import robot_of
from server.api.schemas import (EntryKind, MethodName, ReportOut, SessionParamsIn, SlotName,
                            TableName)
from solvers.errors import CalibrationError

FORMAT = "pendant-backup/1"
RowId = Annotated[int, Field(ge=1, le=MAX_ID)]
Amount = Annotated[float, Field(ge=-1e6, le=1e6)]  # mm of an error


class _Doc(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


def _iso(v: str | None) -> str | None:
    if v is not None:
        try:
            datetime.fromisoformat(v)
        except ValueError:
            raise ValueError(f"must be an ISO 8601 time, got {v!r}") from None
    return v


def _checked(model: type[BaseModel], value: dict[str, Any]) -> BaseModel:
    """``model`` of ``value``; its first error as a ValueError naming the inner field."""
    try:
        return model.model_validate(value)
    except ValidationError as exc:
        err = exc.errors(include_url=False)[0]
        where = ".".join(str(k) for k in err["loc"])
        raise ValueError(f"{where}: {err['msg']}" if where else str(err["msg"])) from None


class SnapshotIn(_Doc):
    """A slot's values (the history's before/after; an entry without table and number)."""

    name: SlotName
    kind: EntryKind
    x_mm: Mm
    y_mm: Mm
    z_mm: Mm
    a_deg: Deg
    b_deg: Deg
    c_deg: Deg
    mass_kg: Kg | None = None
    com_x_mm: Mm | None = None
    com_y_mm: Mm | None = None
    com_z_mm: Mm | None = None
    inertia_x_kgm2: Kgm2 | None = None
    inertia_y_kgm2: Kgm2 | None = None
    inertia_z_kgm2: Kgm2 | None = None
    inertia_a_deg: Deg | None = None
    inertia_b_deg: Deg | None = None
    inertia_c_deg: Deg | None = None
    mech_unit: str | None = Field(None, min_length=1, max_length=MECH_UNIT_CHARS)
    method: str | None = Field(None, max_length=32)
    session_id: RowId | None = None
    error_max_mm: Amount | None = None
    error_rms_mm: Amount | None = None
    updated_at: str | None = None

    _check_time = field_validator("updated_at")(_iso)


class ExtSnapshotIn(SnapshotIn):
    """An external kinematic's values (EX_KIN n; its history's before/after): a slot's
    fields (no load, no unit) plus its axes, flange offset and scale."""

    kind: Literal["none", "turntable", "positioner", "linear_unit"]  # type: ignore[assignment]
    axes: str = Field(max_length=32, pattern=r"^(E[1-6](,E[1-6])?)?$")
    flange_x_mm: Mm = 0.0
    flange_y_mm: Mm = 0.0
    flange_z_mm: Mm = 0.0
    flange_a_deg: Deg = 0.0
    flange_b_deg: Deg = 0.0
    flange_c_deg: Deg = 0.0
    scale: float | None = Field(None, gt=0.5, lt=2.0)

    @model_validator(mode="after")
    def _no_load(self) -> "ExtSnapshotIn":
        if self.mass_kg is not None or self.mech_unit is not None:
            raise ValueError("an external kinematic has no load and no mechanical unit")
        return self


class ExtEntryIn(ExtSnapshotIn):
    number: int = Field(ge=1, le=EXT_KIN_SLOTS)


def _kind_fits(table: str, kind: str) -> None:
    if table == "extkin":
        return
    if kind not in KINDS_OF_TABLE[table]:
        raise ValueError(f"a {table} slot holds {' or '.join(KINDS_OF_TABLE[table])}, "
                         f"not {kind!r}")


def _number_fits(table: str, number: int) -> None:
    slots = EXT_KIN_SLOTS if table == "extkin" else ABB_SLOTS  # a KUKA-kind: 16 / 32
    if not 1 <= number <= slots:
        raise ValueError(f"{table} slots are numbered 1..{slots}, got {number}")


class EntryIn(SnapshotIn):
    table: TableName
    number: int

    @model_validator(mode="after")
    def _fits(self) -> "EntryIn":
        _number_fits(self.table, self.number)
        _kind_fits(self.table, self.kind)
        return self


class HistoryIn(_Doc):
    id: int | None = None
    table: TableName
    number: int
    reason: str = Field(max_length=16)
    session_id: RowId | None = None
    changed_at: str | None = None
    before: SnapshotIn
    after: SnapshotIn

    _check_time = field_validator("changed_at")(_iso)

    @model_validator(mode="after")
    def _fits(self) -> "HistoryIn":
        _number_fits(self.table, self.number)
        _kind_fits(self.table, self.before.kind)
        _kind_fits(self.table, self.after.kind)
        return self


class ExtHistoryIn(HistoryIn):
    """A change of an external kinematic (``external_history`` of the backup)."""

    table: Literal["extkin"]  # type: ignore[assignment]
    before: ExtSnapshotIn
    after: ExtSnapshotIn


class PointIn(_Doc):
    step: int = Field(ge=0, le=1000)
    source: Literal["touch_up", "joints", "flange_pose", "beam"]
    pose: Annotated[list[Annotated[float, Field(ge=-1e6, le=1e6)]],
                    Field(min_length=6, max_length=6)]
    joints_deg: list[Deg] | None = Field(None, min_length=1, max_length=7)
    beam_id: str | None = Field(None, min_length=1, max_length=32)
    edge: Literal["enter", "leave", "tip"] | None = None
    velocity_mm_s: Annotated[list[Mm], Field(min_length=3, max_length=3)] | None = None
    t_s: float | None = Field(None, ge=0.0, le=MAX_T_S)
    motion_sign: list[Annotated[float, Field(ge=-1.0, le=1.0)]] | None = Field(
        None, min_length=1, max_length=7)
    external_axes: dict[Literal["E1", "E2", "E3", "E4", "E5", "E6"],
                        Annotated[float, Field(ge=-1e4, le=1e4)]] | None = None


class SessionIn(_Doc):
    id: RowId
    method: MethodName
    target_table: Literal["tool", "base", "extkin"]
    target_no: int
    params: dict[str, Any] = Field(default_factory=dict)
    state: Literal["open", "computed", "saved", "discarded"]
    created_at: str | None = None
    opened_by: str | None = Field(None, max_length=64)  # absent before revision 0011
    result: Annotated[list[Annotated[float, Field(ge=-1e6, le=1e6)]],
                      Field(min_length=6, max_length=6)] | None = None
    report: dict[str, Any] | None = None
    points: list[PointIn] = Field(default_factory=list)

    _check_time = field_validator("created_at")(_iso)

    @field_validator("params")
    @classmethod
    def _params(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _checked(SessionParamsIn, v).model_dump(mode="json", exclude_none=True)

    @field_validator("report")
    @classmethod
    def _report(cls, v: dict[str, Any] | None) -> dict[str, Any] | None:
        return None if v is None else _checked(ReportOut, v).model_dump(mode="json")

    @model_validator(mode="after")
    def _consistent(self) -> "SessionIn":
        spec = METHODS[self.method]
        if self.target_table != spec.table:
            raise ValueError(f"{self.method} writes the {spec.table} table, not "
                             f"{self.target_table!r}")
        _number_fits(self.target_table, self.target_no)
        if (self.result is None) != (self.report is None):
            raise ValueError("result and report come together (both or neither)")
        if self.state == "computed" and self.result is None:
            raise ValueError("a computed session needs its result and report")
        steps = [p.step for p in self.points]
        if len(set(steps)) != len(steps):
            raise ValueError("two points of the session have the same step")
        return self


class ControllerIn(_Doc):
    name: str | None = None
    robot: str | None = None
    custom_robot: dict[str, Any] | None = None
    cell_seed: int | None = None
    joints_deg: list[Deg] | None = Field(None, min_length=1, max_length=7)
    active_tool_no: int = Field(0, ge=0, le=ABB_SLOTS)
    active_base_no: int = Field(0, ge=0, le=ABB_SLOTS)
    external_axes: dict[Literal["E1", "E2", "E3", "E4", "E5", "E6"],
                        Annotated[float, Field(ge=-1e4, le=1e4)]] | None = None
    external_errors: dict[str, dict[str, float]] | None = None

    @field_validator("external_errors")
    @classmethod
    def _errors(cls, v: dict[str, dict[str, float]] | None) -> dict | None:
        from emulator.external import check_errors

        if v is not None:
            try:
                check_errors(v)
            except CalibrationError as err:
                raise ValueError(f"{'.'.join(map(str, err.loc))}: {err.reason}") from None
        return v


class FileIn(_Doc):
    """A kept controller file (the last one imported in its format): it must read back."""

    format: Literal["kuka", "abb", "fanuc", "ur"]
    text: str = Field(max_length=5_000_000)
    encoding: Literal["utf-8", "cp1252"] = "utf-8"  # of the file's bytes (an export's)

    @model_validator(mode="after")
    def _reads(self) -> "FileIn":
        from server.formats import READERS

        try:
            READERS[self.format](self.text)
        except CalibrationError as err:
            raise ValueError(f"the kept {self.format} file does not read: "
                             f"{'.'.join(str(x) for x in err.loc)}: {err.reason}") from None
        return self


class BackupIn(_Doc):
    format: Literal["pendant-backup/1"]
    controller: ControllerIn | None = None
    entries: list[EntryIn]
    external_kinematics: list[ExtEntryIn] = Field(default_factory=list)
    history: list[HistoryIn] = Field(default_factory=list)
    external_history: list[ExtHistoryIn] = Field(default_factory=list)
    sessions: list[SessionIn] = Field(default_factory=list)
    files: list[FileIn] = Field(default_factory=list)

    @model_validator(mode="after")
    def _unique_sessions(self) -> "BackupIn":
        ids = [s.id for s in self.sessions]
        if len(set(ids)) != len(ids):
            raise ValueError("two sessions have the same id")
        formats = [f.format for f in self.files]
        if len(set(formats)) != len(formats):
            raise ValueError("two kept files have the same format")
        return self


def _no_constant(name: str) -> None:
    raise CalibrationError(("text",), f"{name} is not a number: a backup holds finite numbers only")


def _nul_at(doc: Any) -> tuple[str | int, ...] | None:
    """The path of the first string (key or value) of ``doc`` holding a NUL, which a PostgreSQL
    text field cannot store (the restore failed there with a 500); None if none does."""
    todo: list[tuple[tuple[str | int, ...], Any]] = [((), doc)]
    while todo:  # a loop, not recursion: the document may be nested deep
        path, v = todo.pop()
        if isinstance(v, str) and "\x00" in v:
            return path
        items = v.items() if isinstance(v, dict) else enumerate(v) if isinstance(v, list) else ()
        for k, item in items:
            if isinstance(k, str) and "\x00" in k:
                return path
            todo.append(((*path, k), item))
    return None


def parse_backup(text: str) -> dict[str, Any]:
    """The checked ``pendant-backup/1`` document of ``text`` as plain JSON values.

    Raises CalibrationError with ``loc = ("text", ...path)``: not JSON, NaN/Infinity, not a
    backup, or the first field that breaks the format, with the reason.
    """
    try:
        doc = json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as err:
        raise CalibrationError(("text",), f"not JSON: {err.msg} at line {err.lineno}") from None
    except RecursionError:  # a backup is at most a few levels deep
        raise CalibrationError(("text",), "nested too deep for a backup (arrays or objects "
                               "inside each other hundreds of levels deep)") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise CalibrationError(("text", "format"), f"must be a {FORMAT} document "
                               "(GET .../export?format=json)")
    nul = _nul_at(doc)
    if nul is not None:
        raise CalibrationError(("text", *nul), "contains the character U+0000 (NUL)")
    try:
        backup = BackupIn.model_validate(doc)
    except ValidationError as exc:
        err = exc.errors(include_url=False)[0]
        msg = str(err["msg"])
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, "):]
        raise CalibrationError(("text", *err["loc"]), msg) from None
    return backup.model_dump(mode="json", exclude_unset=True)


# --------------------------------------------------------------- pendant backup / restore

def check_controller_joints(robot: Any, doc: dict[str, Any]) -> None:
    """The backup's ``controller.joints_deg`` fits ``robot`` (count and limits), else
    CalibrationError at ``("text", "controller", "joints_deg", ...)``; the same check as
    ``POST .../import``."""
    from solvers.dh import check_joint_limits

    joints = (doc.get("controller") or {}).get("joints_deg")
    if joints is None:
        return
    loc = ("text", "controller", "joints_deg")
    if len(joints) != robot.dof:
        raise CalibrationError(loc, f"has {len(joints)} values; this controller's robot has "
                               f"{robot.dof} joints")
    try:
        check_joint_limits(robot, joints)
    except CalibrationError as err:
        raise CalibrationError(loc + tuple(err.loc[1:]), err.reason) from None


def restore_later(db: Session, c: Controller, text: str,
                  dry_run: bool = False) -> tuple[int, Job | None]:
    """``POST .../import`` of a JSON backup: the document checked now (CalibrationError naming
    the field; nothing a later read cannot handle is stored), then restored by a job
    (``server.jobs.kinds.run_restore``, audited as the current actor, ``backup.restore``).
    The backup's slot count and the queued job (None for a ``dry_run``: nothing queued)."""
    mark_operation("backup.restore")
    doc = parse_backup(text)
    check_controller_joints(robot_of(c), doc)  # the same check as pendant restore
    if dry_run:
        return len(doc["entries"]), None
    return len(doc["entries"]), jobs.enqueue(db, "restore", {"controller_id": c.id, "doc": doc,
                                                             "actor": actor()})


def run_backup(args: Any) -> int:
    """``pendant backup CONTROLLER [-o FILE]``: the controller's ``pendant-backup/1`` (what
    ``GET .../export?format=json`` answers), written whole or not at all."""
    import os
    import sys

    from db import crud
    from server.auth.cli import cli_session

    with cli_session(args.db, write=False) as db:
        c = crud.find_controller(db, args.controller)
        text = export_text(db, c.id, "json")
        n_hist = len(crud.history(db, c.id))
    if args.output is None:
        sys.stdout.write(text)
        return 0
    tmp = args.output.with_name(args.output.name + ".part")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, args.output)
    print(f"{c.name}: backup with {n_hist} history rows -> {args.output} "
          f"({len(text)} characters)", file=sys.stderr)
    return 0


def run_restore_file(args: Any) -> int:
    """``pendant restore FILE --controller NAME [--dry-run]``: the same checks as
    ``POST .../import`` with ``format=json``, then the restore job's own step, here, in one
    transaction (audited as ``cli:<os user>``, ``backup.restore``). No body limit applies."""
    from db import crud
    from server.auth import audit
    from server.auth.cli import cli_session
    from server.jobs.kinds import run_restore

    text = args.file.read_text(encoding="utf-8")
    with cli_session(args.db, write=not args.dry_run, operation="restore") as db:
        c = crud.find_controller(db, args.controller)
        doc = parse_backup(text)
        check_controller_joints(robot_of(c), doc)
        if args.dry_run:
            print(f"{args.file.name}: a {FORMAT} of {len(doc['entries'])} slots and "
                  f"{len(doc.get('history', [])) + len(doc.get('external_history', []))} "
                  f"history rows would replace {c.name}'s (dry run: nothing written)")
            return 0
        apply = run_restore(None, {"controller_id": c.id, "doc": doc,  # type: ignore[arg-type]
                                   "actor": audit.actor()}, lambda *_: None)
        result = apply(db)
    print(f"{c.name}: restored {result['entries']} slots and {result['history']} history rows "
          f"from {args.file.name}")
    return 0


def add_backup_commands(subparsers: Any) -> None:
    """Register ``backup`` and ``restore`` on the ``pendant`` command's subparsers."""
    from pathlib import Path

    b = subparsers.add_parser("backup", help="write a controller's JSON backup (tables, "
                                             "history, sessions)")
    b.add_argument("controller", help="controller name (or id), e.g. cell-1")
    b.add_argument("-o", "--output", type=Path, help="the file (default: standard output)")
    b.add_argument("--db", metavar="URL", help="database URL")
    b.set_defaults(func=run_backup)
    r = subparsers.add_parser("restore", help="replace a controller's tables, history and "
                                              "sessions by a JSON backup")
    r.add_argument("file", type=Path)
    r.add_argument("--controller", required=True, help="controller name (or id)")
    r.add_argument("--dry-run", action="store_true", help="check the backup; write nothing")
    r.add_argument("--db", metavar="URL", help="database URL")
    r.set_defaults(func=run_restore_file)
