"""External kinematics on the server: the EX_KIN slots (read, change with history, restore),
the emulated external axes of a controller, and what the ``ext.*`` menus need from the tables.

A slot change writes an ``entry_history`` row with ``entry_table = 'extkin'`` (so the audit
hook records it as ``frame.<reason>`` like a tool or base change) and a ``frame-committed``
event. No math here: the frames come from the solvers (``solvers.external``) and the emulator
(``emulator.external``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from db import crud
from db.models import (EXT_KIN_SLOTS, CalibSession, Controller, EntryHistory, ExternalKinematic,
                       utcnow)
from db.outbox import emit
from emulator import external as ext_emu
from server.auth import audit
from solvers.errors import CalibrationError
from solvers.frames import Pose

TABLE = "extkin"  # entry_history.entry_table and calib_session.target_table of these slots
KINDS = ("none", "turntable", "positioner", "linear_unit")
POSE_KEYS = ("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg")
FLANGE_KEYS = tuple(f"flange_{k}" for k in POSE_KEYS)
FIELDS = crud.EXT_FIELDS
SLOT_NAMES = {1: "TURNTABLE", 2: "POSITIONER", 3: "TRACK"}


# ----------------------------------------------------------------------------- slots

def get_slot(db: Session, controller_id: int, number: int) -> ExternalKinematic:
    """EX_KIN ``number`` (1..6); NotFound naming ``number``."""
    if not 1 <= number <= EXT_KIN_SLOTS:
        raise crud.NotFound(("number",), f"external kinematics are numbered 1..{EXT_KIN_SLOTS}, "
                                         f"got {number}")
    crud.get_controller(db, controller_id)
    e = db.scalar(select(ExternalKinematic).where(ExternalKinematic.controller_id == controller_id,
                                                  ExternalKinematic.number == number))
    if e is None:  # never written: an empty slot, stored on its first change
        e = ExternalKinematic(controller_id=controller_id, number=number, name="", kind="none",
                              axes="", version=1)
        e.set_pose_values((0.0,) * 6)
        set_flange(e, (0.0,) * 6)
    return e


def list_slots(db: Session, controller_id: int) -> list[ExternalKinematic]:
    return [get_slot(db, controller_id, n) for n in range(1, EXT_KIN_SLOTS + 1)]


def set_flange(e: ExternalKinematic, values: object) -> None:
    for k, v in zip(FLANGE_KEYS, values):  # type: ignore[call-overload]
        setattr(e, k, float(v))


def change_slot(db: Session, e: ExternalKinematic, values: dict[str, Any], reason: str,
                session_id: int | None = None) -> EntryHistory:
    """Set ``values`` (:data:`FIELDS`) and record the change (history, audit, event)."""
    before = crud.ext_snapshot(e)
    if e not in db:
        db.add(e)
    for k, v in values.items():
        setattr(e, k, v)
    e.updated_at = utcnow()
    e.updated_by = audit.current().user_name
    h = EntryHistory(controller_id=e.controller_id, entry_table=TABLE, number=e.number,
                     reason=reason, session_id=session_id, before=before,
                     after=crud.ext_snapshot(e))
    db.add(h)
    db.flush()
    controller = db.get(Controller, e.controller_id)
    emit(db, "frame-committed", controller, {
        "table": TABLE, "number": e.number, "reason": reason, "session_id": session_id,
        **{k: v for k, v in h.after.items() if k != "session_id"}})
    return h


def restore_slot(db: Session, e: ExternalKinematic, history_id: int) -> EntryHistory:
    """Put the slot back as it was before history row ``history_id`` (recorded as a change)."""
    h = get_history(db, e, history_id)
    values = {f: h.before[f] for f in FIELDS if f in h.before and f != "updated_at"}
    return change_slot(db, e, values, reason="restore", session_id=h.session_id)


def get_history(db: Session, e: ExternalKinematic, history_id: int) -> EntryHistory:
    h = db.get(EntryHistory, history_id) if 0 < history_id < crud.max_id(db) else None
    if h is None or (h.controller_id, h.entry_table, h.number) != (e.controller_id, TABLE,
                                                                   e.number):
        raise crud.NotFound(("history_id",),
                            f"no history entry {history_id} for external kinematic {e.number}")
    return h


AXIS_COUNT = {"none": 0, "turntable": 1, "positioner": 2, "linear_unit": 1}


def check_axes(db: Session, e: ExternalKinematic, kind: str, axes: list[str]) -> None:
    """CalibrationError naming ``axes`` unless the kinematic of ``kind`` has that many axes,
    none twice and none that another kinematic of the controller moves."""
    if len(axes) != AXIS_COUNT[kind] or len(set(axes)) != len(axes):
        raise CalibrationError(("axes",), f"a {kind} moves {AXIS_COUNT[kind]} distinct external "
                               f"axes, got {', '.join(axes) or 'none'}")
    for other in list_slots(db, e.controller_id):
        taken = set(axes_of(other)) & set(axes)
        if other.number != e.number and taken:
            raise CalibrationError(("axes",), f"{', '.join(sorted(taken))} already moves "
                                   f"external kinematic {other.number} "
                                   f"({other.name or other.kind})")


def root_matrix(e: ExternalKinematic) -> np.ndarray:
    return Pose(*e.pose_values()).as_matrix()


def flange_matrix(e: ExternalKinematic) -> np.ndarray:
    return Pose(*e.flange_values()).as_matrix()


def axes_of(e: ExternalKinematic) -> list[str]:
    return [a for a in e.axes.split(",") if a]


# -------------------------------------------------------------------- emulated external axes

def cell_of(c: Controller, reach_mm: float) -> ext_emu.ExternalCell:
    return ext_emu.external_cell(reach_mm, c.external_errors, int(c.cell_seed))


def enable(db: Session, c: Controller, reach_mm: float) -> None:
    """Give controller ``c`` the emulated external axes (at 0) and their nominal machine data
    in EX_KIN 1..3 (created with the controller, so no history row)."""
    c.external_axes = ext_emu.home()
    db.flush()
    for n, data in ext_emu.nominal_kinematics(cell_of(c, reach_mm)).items():
        e = get_slot(db, c.id, n)
        e.name, e.kind, e.axes = SLOT_NAMES[n], data["kind"], ",".join(data["axes"])
        e.set_pose_values(Pose.from_matrix(data["root"]).as_array())
        set_flange(e, Pose.from_matrix(data["flange"]).as_array())
        e.method = "machine_data"
        db.add(e)
    db.flush()


def target_names() -> list[str]:
    """The approach targets that ride on the external axes (``turntable_mark``, ...)."""
    return ext_emu.target_names()


def values_of(c: Controller, loc: str = "axis") -> dict[str, float]:
    """The controller's external axis values; CalibrationError naming ``loc`` if it has none."""
    if not c.external_axes:
        raise CalibrationError((loc,), f"controller {c.name!r} has no external axes (create it "
                               "with external_axes: true; the demo cell-1 has E1..E4)")
    return {k: float(v) for k, v in c.external_axes.items()}


# ----------------------------------------------------------------------- sessions

def require_slot_kind(db: Session, controller_id: int, number: int, loc: tuple,
                      kinds: tuple[str, ...]) -> ExternalKinematic:
    e = get_slot(db, controller_id, number)
    if e.kind not in kinds:
        raise CalibrationError(loc, f"external kinematic {number} is {e.kind!r}; this menu "
                               f"needs a {' or '.join(kinds)}")
    return e


def save_values(s: CalibSession, result_values: tuple[float, ...], report: dict[str, Any]) -> dict:
    """The slot values a computed ``ext.*`` session writes (provenance included)."""
    values: dict[str, Any] = dict(zip(POSE_KEYS, result_values))
    extras = report.get("extras") or {}
    if s.method == "ext.positioner_2axis":  # the tilt root is the slot's root, the turn the flange
        values = dict(zip(POSE_KEYS, extras["tilt_root"]))  # x, y, z, a, b, c of T_base_tiltroot
        values.update(zip(FLANGE_KEYS, result_values))
    if extras.get("scale") is not None and s.method in ("ext.root_point", "ext.linear_unit"):
        values["scale"] = abs(float(extras["scale"]))
    values.update(method=s.method, session_id=s.id, error_max_mm=report.get("max_error_mm"),
                  error_rms_mm=report.get("rms_error_mm"))
    return values


#: the kinds of kinematic each menu calibrates (the numeric root point: any)
METHOD_KINDS = {"ext.root_point": ("turntable", "positioner"), "ext.offset": ("turntable",
                "positioner"), "ext.offset_numeric": ("turntable", "positioner"),
                "ext.linear_unit": ("linear_unit",), "ext.positioner_2axis": ("positioner",)}


def ext_inputs(db: Session, s: CalibSession) -> Any:
    """The :class:`server.methods_ext.ExtInputs` of an ``ext.*`` session: the kinematic of
    ``params.ext_no`` (the Offset menus) or of the target slot, and, when a root-point session
    wrote that slot, its covariance and dof (the Offset's bounds carry the root's uncertainty)."""
    from server.methods_ext import ExtInputs

    p = s.params
    number = p.get("ext_no") if s.target_table != TABLE else s.target_no
    if number is None:
        return None
    loc = ("params", "ext_no") if s.target_table != TABLE else ("target_no",)
    e = get_slot(db, s.controller_id, int(number))
    if e.kind == "none" and not s.method.endswith("_numeric"):
        raise CalibrationError(loc, f"external kinematic {number} is not configured (kind "
                               "none): set its kind, axes and machine data first (PUT "
                               f".../external-kinematics/{number})")
    kinds = METHOD_KINDS.get(s.method)
    if kinds is not None and e.kind not in kinds and e.kind != "none":
        what = ("a base rides on a turntable or a positioner" if s.target_table != TABLE
                else f"{s.method} calibrates a {' or a '.join(kinds)}")
        raise CalibrationError(loc, f"external kinematic {number} is a {e.kind}: {what}")
    cov, dof = None, 0
    if e.session_id is not None and e.method == "ext.root_point":
        root_session = db.get(CalibSession, e.session_id)
        report = root_session.report if root_session is not None else None
        if report and report.get("covariance"):
            cov = np.array(report["covariance"], dtype=float)
            dof = int((report.get("extras") or {}).get("dof") or 0)
    axis = p.get("axis")
    if axis is not None and axis not in axes_of(e):
        raise CalibrationError(("params", "axis"), f"external kinematic {number} moves "
                               f"{', '.join(axes_of(e)) or 'no axis'}, not {axis}")
    root = None if not any(e.pose_values()) else root_matrix(e)  # no machine data: no nominal
    return ExtInputs(number=e.number, kind=e.kind, axes=tuple(axes_of(e)), root=root,
                     flange=flange_matrix(e), axis=axis, root_covariance=cov, root_dof=dof)


def mech_unit(db: Session, controller_id: int, number: int) -> str:
    """The mechanical unit a base on EX_KIN ``number`` names (KUKA MACHINE_FRAME_DAT PARENT,
    ABB ufmec): the kinematic's name, else ``EX_KIN<n>``."""
    return get_slot(db, controller_id, number).name or f"EX_KIN{number}"


# ------------------------------------------------------------------------------ exports

EXPORT_FORMATS = ("kuka_machine", "abb_moc")


def _formats_kinematic(e: ExternalKinematic) -> Any:
    """Slot ``e`` as :class:`server.formats.external.ExternalKinematic` (None when unused)."""
    from server.formats import external as fx

    axes = axes_of(e)
    name = e.name or f"EX_KIN{e.number}"
    if e.kind == "turntable" and len(axes) == 1:
        return fx.turntable(e.number, name, root_matrix(e), axes[0], Pose(*e.flange_values()))
    if e.kind == "positioner" and len(axes) == 2:
        return fx.positioner_2axis(e.number, name, root_matrix(e), flange_matrix(e),
                                   (axes[0], axes[1]))
    if e.kind == "linear_unit" and len(axes) == 1:
        return fx.linear_unit(e.number, name, root_matrix(e), axes[0])
    return None


def export_external(db: Session, controller_id: int, fmt: str) -> str:
    """The external kinematics (and the bases on them) as controller text:
    ``kuka_machine`` = the ``$machine.dat`` lines then the ``$config.dat`` lines (MACHINE_DEF,
    the bases with MACHINE_FRAME_DAT), each under a KRL comment naming its file;
    ``abb_moc`` = the ``MOC.cfg`` fragment (the units' base frames; the coordinated work
    objects are in the ``abb`` export). Writers: :mod:`server.formats.external`."""
    from server.controller_files import to_frame_entry
    from server.formats import external as fx

    kins = [k for k in map(_formats_kinematic, list_slots(db, controller_id)) if k is not None]
    names = {k.name for k in kins if not k.linear}
    bases = [to_frame_entry(b) for b in crud.list_entries(db, controller_id, "base",
                                                           "coordinated_base")
             if b.mech_unit in names]
    if fmt == "abb_moc":
        return fx.abb_mechanical_units(kins, bases).moc_cfg
    text = fx.kuka_external_kinematics(kins, bases)
    return (f"; ---- KRC:\\R1\\Mada\\$machine.dat ----\n{text.machine_dat}\n\n"
            f"; ---- KRC:\\R1\\System\\$config.dat ----\n{text.config_dat}\n")
