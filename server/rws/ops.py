"""The operations the controller faces (RWS, KVP) call: the one place they touch pendant.

Both faces translate a protocol into these calls and never open the database themselves.
Each function takes the service's sessionmaker, the :class:`Caller` (who, through which
face) and typed input, checks the permission REST's route needs (the one table,
:mod:`server.auth.permissions`), runs the REST route's own operation (``server.service``) in
a write as every face runs one (:func:`server.service.transaction.writing`: the controller's
row locked, version bumped, history, audit with the face as its source, the
``frame-committed`` event), and returns plain values.
"""

from __future__ import annotations

import uuid
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

import emulator
from db import crud
from db.auth_models import User
from server import formats
from server.service import controller_files, transaction
from server.auth import audit, tokens
from server.auth.permissions import C, required
from server.api.schemas import EntryIn
from server.service import robot as robot_service
from server.service import slots as slot_service
from server.service.preconditions import PreconditionFailed, etag
from server.service.robot import active_frames, robot_of
from solvers.dh import forward_kinematics
from solvers.errors import CalibrationError

Maker = sessionmaker[Session]

# the permission of each operation: the REST route's, from the one table
EDIT_SLOT = {"tool": required("PUT", C + "/tools/{number}"),
             "base": required("PUT", C + "/bases/{number}")}
READ = required("GET", C + "/robot")
SET_ACTIVE = required("PUT", C + "/robot/active")
IMPORT = required("POST", C + "/import")


class Refused(Exception):
    """The caller's role lacks the permission (REST's 403)."""

    def __init__(self, permission: str, caller: Caller):
        super().__init__(f"needs permission {permission}; {caller.name} acts as {caller.role}")
        self.permission = permission


class Stale(Exception):
    """The slot changed since the version the caller gave (REST's 412)."""


@dataclass(frozen=True)
class Caller:
    """A pendant user acting through a face (``source`` rws | kvp) from ``client``."""

    name: str
    role: str
    permissions: frozenset[str]
    source: str
    client: str | None = None
    request_id: str = field(default_factory=lambda: uuid.uuid4().hex)

    def require(self, permission: str | None) -> None:
        if permission is None or permission not in self.permissions:
            raise Refused(str(permission), self)

    def who(self) -> dict[str, Any]:
        """As :func:`server.auth.audit.actor` has it."""
        return {"user_name": self.name, "role": self.role, "source": self.source,
                "request_id": self.request_id, "client": self.client}


def caller(maker: Maker, name: str, source: str, client: str | None = None) -> Caller | None:
    """The user ``name`` with the role and permissions in force now; None if gone or revoked."""
    with maker() as db:
        u = db.scalar(select(User).where(User.name == name))
        if u is None or u.revoked_at is not None:
            return None
        return Caller(u.name, u.role, tokens.role_permissions(db, u.role), source, client)


def no_auth_caller(source: str, client: str | None = None) -> Caller:
    """``serve --no-auth``: everyone an Administrator, as on REST."""
    from server.auth.permissions import PERMISSIONS

    return Caller("no-auth", "Administrator", frozenset(PERMISSIONS), source, client)


def rws_ha1(maker: Maker, name: str) -> str | None:
    """The stored HA1 of the user's RWS secret (None: no secret, or the user is revoked)."""
    with maker() as db:
        u = db.scalar(select(User).where(User.name == name))
        return None if u is None or u.revoked_at is not None else u.rws_ha1


def set_rws_ha1(db: Session, name: str, ha1: str) -> None:
    """Store a user's RWS HA1 (``pendant users rws-password``), audited as ``user.rws_secret``."""
    u = tokens.get_user(db, name)
    u.rws_ha1 = ha1
    audit.record(db, "user.rws_secret", after={"name": u.name})


# ------------------------------------------------------------------------------------ reads

def controller_id(maker: Maker, name_or_id: str | int | None, prefix: str) -> int:
    """The controller a face serves: the one named (or numbered; an int is an id only), else
    the lowest id whose robot is ``prefix``'s (``abb``, ``kuka``); NotFound when there is
    none. A face keeps the id it got for None (:func:`pinned`)."""
    with maker() as db:
        if isinstance(name_or_id, int):
            return crud.get_controller(db, name_or_id).id
        if name_or_id is not None:
            return crud.find_controller(db, str(name_or_id)).id
        for c in crud.list_controllers(db):
            if (c.robot_key or "").startswith(prefix):
                return c.id
    raise crud.NotFound(("controller",), f"no {prefix.upper()} controller; create one or name it")


def pinned(face: Any, prefix: str) -> int:
    """``face.controller``'s id; without one, the first ``prefix`` controller's, kept in
    ``face.controller``: looked up again at every request, a face went on to the next
    controller (another robot's slots) once the first was deleted."""
    if face.controller is None:
        face.controller = controller_id(face.make_session, None, prefix)
    return controller_id(face.make_session, face.controller, prefix)


@dataclass(frozen=True)
class Slot:
    """A slot as the faces show it."""

    table: str
    number: int
    version: int
    used: bool
    entry: formats.FrameEntry | None  # None when unused


def slots(maker: Maker, caller_: Caller, cid: int, table: str | None = None,
          for_write: bool = False) -> list[Slot]:
    """Every slot (of ``table``); ``for_write``: read by a write, as :func:`slot`."""
    if not for_write:
        caller_.require(READ)
    with maker() as db:
        crud.get_controller(db, cid)
        return [Slot(e.entry_table, e.number, e.version, controller_files.is_used(e),
                     controller_files.to_frame_entry(e) if controller_files.is_used(e) else None)
                for e in crud.list_entries(db, cid, table)]


def slot(maker: Maker, caller_: Caller, cid: int, table: str, number: int,
         for_write: bool = False) -> Slot:
    """Slot ``number`` of ``table``; ``for_write``: read by a write, to merge the components
    it gives with the others, which needs no read permission (REST's PUT merges so too)."""
    if not for_write:
        caller_.require(READ)
    with maker() as db:
        e = crud.get_entry(db, cid, table, number)
        used = controller_files.is_used(e)
        return Slot(table, number, e.version, used,
                    controller_files.to_frame_entry(e) if used else None)


def export(maker: Maker, caller_: Caller, cid: int, fmt: str, for_write: bool = False) -> str:
    """The controller's file in ``fmt``, as ``GET /controllers/{id}/export`` gives it;
    ``for_write``: read by a write to find its slot (RWS's set by symbol name), unanswered."""
    if not for_write:
        caller_.require(required("GET", C + "/export"))
    with maker() as db:
        crud.get_controller(db, cid)
        return controller_files.export_file(db, cid, fmt)


@dataclass(frozen=True)
class RobotState:
    joints_deg: list[float]
    active_tool_no: int
    active_base_no: int
    T_base_flange: np.ndarray
    T_world_tcp_active: np.ndarray  # the active TCP in world
    T_base_tcp_active: np.ndarray  # ... in the active base
    external_axes: dict[str, float] | None


def robot(maker: Maker, caller_: Caller, cid: int) -> RobotState:
    """The emulated arm as ``GET /controllers/{id}/robot`` shows it."""
    caller_.require(READ)
    return robot_state(maker, cid)


def robot_state(maker: Maker, cid: int) -> RobotState:
    """The arm's state without a permission check: the answer of a write that committed."""
    with maker() as db:
        c = crud.get_controller(db, cid)
        rob = robot_of(c)
        tool, base = active_frames(db, c)
        return RobotState(list(c.joints_deg), c.active_tool_no, c.active_base_no,
                          forward_kinematics(rob, c.joints_deg),
                          forward_kinematics(rob, c.joints_deg, tool),
                          emulator.tcp_pose(rob, c.joints_deg, tool, base),
                          dict(c.external_axes) if c.external_axes else None)


def frame_matrix(entry: formats.FrameEntry | None) -> np.ndarray:
    """T of a slot's frame (identity for none: flange, world)."""
    return np.eye(4) if entry is None else entry.pose.as_matrix()


def tcp_in(maker: Maker, caller_: Caller, cid: int, T_flange_tool: np.ndarray) -> np.ndarray:
    """T_world_tcp of the arm now with the tool ``T_flange_tool`` (not the active one)."""
    caller_.require(READ)
    with maker() as db:
        c = crud.get_controller(db, cid)
        return forward_kinematics(robot_of(c), c.joints_deg, T_flange_tool)


# ----------------------------------------------------------------------------------- writes

def commit_slot(maker: Maker, caller_: Caller, cid: int, table: str, number: int,
                body: EntryIn, *, clear_load: bool = False,
                expected_version: int | None = None) -> Slot:
    """A hand edit of slot ``table`` ``number``: the REST ``PUT .../tools|bases/{n}``.

    ``expected_version`` is the protocol's If-Match (None: the protocol has none, so the
    version the edit reads under the lock). ``clear_load`` drops the slot's load (a RAPID
    literal with ABB's "nothing known" load, KUKA's ``M -1``). Raises :class:`Refused`,
    :class:`Stale`, ``crud.NotFound`` and CalibrationError naming the field."""
    caller_.require(EDIT_SLOT.get(table))
    if_match = "*" if expected_version is None else etag(expected_version)
    try:
        with transaction.writing(maker, cid, operation="edit_slot", who=caller_.who()) as db:
            e = slot_service.edit_slot(db, cid, table, number, body, if_match,
                                       clear_load=clear_load)
    except PreconditionFailed as err:
        raise Stale(f"{table} {number} is at version {err.version}, "
                    f"not {expected_version}") from None
    used = controller_files.is_used(e)
    return Slot(table, number, e.version, used,
                controller_files.to_frame_entry(e) if used else None)


def set_active(maker: Maker, caller_: Caller, cid: int, tool_no: int | None = None,
               base_no: int | None = None) -> RobotState:
    """Select the active tool and base: the REST ``PUT .../robot/active``."""
    caller_.require(SET_ACTIVE)
    for n, table, loc in ((tool_no, "tool", "tool_no"), (base_no, "base", "base_no")):
        if n is not None and not 0 <= n <= crud.SLOTS[table]:
            raise CalibrationError((loc,), f"must be 0..{crud.SLOTS[table]}, got {n}")
    with transaction.writing(maker, cid, operation="set_active", who=caller_.who()) as db:
        robot_service.set_active(db, cid, tool_no, base_no)
    return robot_state(maker, cid)  # the write's own answer, as REST's PUT answers it


def import_file(maker: Maker, caller_: Caller, cid: int, fmt: str, text: str) -> int:
    """A controller file import, as ``pendant import`` and ``POST .../import`` do it: the
    whole file is read first (FormatError naming the line), then every slot it names is
    replaced. Returns how many slots it wrote."""
    caller_.require(IMPORT)
    parsed = controller_files.parse_file(fmt, text)
    with transaction.writing(maker, cid, operation="import_tables", who=caller_.who()) as db:
        c = crud.get_controller(db, cid)
        result = controller_files.apply_import(db, c, fmt, text, parsed)
    return result.entries


def entry_body(fe: formats.FrameEntry, name: str | None = None) -> tuple[EntryIn, bool]:
    """The hand edit (and whether it clears the load) that writes ``fe``'s pose, kind, load and
    unit into its slot; ``name`` replaces the name when given."""
    p = fe.pose
    load = None
    if fe.load is not None:
        ld = fe.load
        load = {"mass_kg": ld.mass_kg, "com_mm": list(ld.com_mm),
                "inertia_kgm2": list(ld.inertia_kgm2), "inertia_axes_deg": list(ld.inertia_axes_deg)}
    body = EntryIn(name=name, kind=fe.kind, pose={"x": p.x, "y": p.y, "z": p.z, "a": p.a,
                                                  "b": p.b, "c": p.c},
                   load=load, mech_unit=fe.mech_unit)
    return body, fe.load is None and fe.kind in formats.LOADED

