"""External kinematics on the server: the EX_KIN slots (read, change with history, restore),
the emulated external axes of a controller, and what the ``ext.*`` menus need from the tables.

A slot change writes an ``entry_history`` row with ``entry_table = 'extkin'`` (so the audit
hook records it as ``frame.<reason>`` like a tool or base change) and a ``frame-committed``
event. No math here: the frames come from the solvers (``solvers.external``) and the emulator
(``emulator.external``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, get_args

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from db import crud
from db.models import (EXT_KIN_SLOTS, CalibSession, Controller, EntryHistory, ExternalKinematic,
                       utcnow)
from db.outbox import emit
from emulator import external as ext_emu
from server.api.schemas import EXT_AXIS_LIMIT, ExtAxis
from server.auth import audit
from solvers.base import perturbed
from solvers.errors import CalibrationError
from solvers.external.chain import propagate
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
    """The :class:`server.menus.external.ExtInputs` of an ``ext.*`` session: the kinematic of
    ``params.ext_no`` (the Offset menus) or of the target slot, and, when a root-point session
    wrote that slot, its covariance, dof and sigma (the Offset's bounds carry the root's
    uncertainty)."""
    from server.menus.external import ExtInputs

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
    cov, dof, sigma = None, 0, None
    if e.session_id is not None and e.method == "ext.root_point":
        root_session = db.get(CalibSession, e.session_id)
        report = root_session.report if root_session is not None else None
        if report and report.get("covariance"):
            cov = np.array(report["covariance"], dtype=float)
            dof = int((report.get("extras") or {}).get("dof") or 0)
            sigma = report.get("sigma_mm")
    axis = p.get("axis")
    if axis is not None and axis not in axes_of(e):
        raise CalibrationError(("params", "axis"), f"external kinematic {number} moves "
                               f"{', '.join(axes_of(e)) or 'no axis'}, not {axis}")
    root = None if not any(e.pose_values()) else root_matrix(e)  # no machine data: no nominal
    return ExtInputs(number=e.number, kind=e.kind, axes=tuple(axes_of(e)), root=root,
                     flange=flange_matrix(e), axis=axis, root_covariance=cov, root_dof=dof,
                     root_sigma_mm=None if sigma is None else float(sigma))


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
    from server.service.controller_files import to_frame_entry
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


# ------------------------------------------------------------------ the chain of a touch-up

#: menus that calibrate the rail itself, or take no touch-ups: no chain to compose
NO_CHAIN = ("ext.linear_unit",)
XYZ_PARAMETERS = ("x_mm", "y_mm", "z_mm")


@dataclass(frozen=True)
class Rail:
    """The robot's rail (the controller's linear unit): its slot, axis, travel direction in the
    robot base at 0, encoder scale, whether a person calibrated it, and the covariance of the
    fitted slope ``b = -k d`` (None: not calibrated by ``ext.linear_unit`` here)."""

    number: int
    name: str
    axis: str
    direction: np.ndarray
    scale: float
    calibrated: bool
    method: str | None
    slope_covariance: np.ndarray | None = None
    slope_dof: int | None = None

    @property
    def label(self) -> str:
        return f"the rail {self.axis} (EX_KIN {self.number}{' ' + self.name if self.name else ''})"


def rail_of(db: Session, controller_id: int) -> Rail | None:
    """The controller's rail: the external kinematic of kind ``linear_unit`` with one axis."""
    for e in list_slots(db, controller_id):
        axes = axes_of(e)
        if e.kind != "linear_unit" or len(axes) != 1:
            continue
        calibrated = e.method not in (None, "", "machine_data")
        cov, dof = None, None
        if e.method == "ext.linear_unit" and e.session_id is not None:
            rs = db.get(CalibSession, e.session_id)
            rep = rs.report if rs is not None else None
            if rep and rep.get("covariance"):
                cov = np.array(rep["covariance"], dtype=float)[3:, 3:]
                dof = int((rep.get("extras") or {}).get("dof") or 0) or None
        return Rail(e.number, e.name, axes[0], root_matrix(e)[:3, 2].copy(),
                    1.0 if e.scale is None else float(e.scale), calibrated, e.method, cov, dof)
    return None


def rail_from_document(doc: object, loc: tuple[str, ...] = ("inputs", "rail")) -> Rail:
    """The rail a file describes (``pendant calibrate``'s ``inputs.rail``): ``{"axis": "E1",
    "direction": [x, y, z], "scale": 1.0, "calibrated": false, "number": 1}``. ``direction``
    is the travel in the robot base at 0 (normalised here), ``scale`` mm of travel per unit of
    the axis value, ``calibrated`` whether the direction and scale come from a calibration
    (``ext.linear_unit``) rather than machine data, ``number`` its EX_KIN slot (for the report).
    CalibrationError naming the field otherwise."""
    if not isinstance(doc, dict):
        raise CalibrationError(loc, 'must be an object {"axis": "E1", "direction": [x, y, z]}')
    unknown = sorted(set(doc) - {"axis", "direction", "scale", "calibrated", "number"})
    if unknown:
        raise CalibrationError(loc + (unknown[0],), "unknown field; a rail has axis, direction, "
                               "scale, calibrated, number")
    axis = doc.get("axis")
    if axis not in get_args(ExtAxis):
        raise CalibrationError(loc + ("axis",), f"must be one of E1..E6, got {axis!r}")
    given = doc.get("direction")
    d = (np.array([_finite(v) for v in given])
         if isinstance(given, list) and len(given) == 3 else np.full(3, np.nan))
    if not np.all(np.isfinite(d)) or not np.any(d):
        raise CalibrationError(loc + ("direction",), "must be three finite numbers, not all 0 "
                               f"(the travel in the robot base), got {given!r}")
    d = d / np.max(np.abs(d))  # then its norm cannot overflow
    scale = _finite(doc.get("scale", 1.0))
    if not scale > 0 or scale > 1e6:
        raise CalibrationError(loc + ("scale",), f"must be a positive number up to 1e6 (mm per "
                               f"unit of {axis}), got {doc.get('scale')!r}")
    calibrated = doc.get("calibrated", False)
    if not isinstance(calibrated, bool):
        raise CalibrationError(loc + ("calibrated",), f"must be true or false, got {calibrated!r}")
    number = doc.get("number", 1)
    if isinstance(number, bool) or not isinstance(number, int) or not 1 <= number <= EXT_KIN_SLOTS:
        raise CalibrationError(loc + ("number",), f"must be an EX_KIN number 1..{EXT_KIN_SLOTS}, "
                               f"got {number!r}")
    return Rail(number, "", axis, d / np.linalg.norm(d), float(scale), calibrated,
                "given in the file" if calibrated else None)


def _finite(v: object) -> float:
    """``v`` as a float if it is a finite JSON number (not a bool, not a string), else NaN."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return float("nan")
    try:
        f = float(v)
    except OverflowError:  # an int beyond a float
        return float("nan")
    return f if math.isfinite(f) else float("nan")


def check_external_axes(values: object, loc: tuple) -> dict[str, float] | None:
    """A touch-up's external axis values from a file: ``{"E1": number, ...}`` (E1..E6, finite
    numbers within the bounds REST's touch-up takes, :data:`EXT_AXIS_LIMIT`), or None;
    CalibrationError naming the field otherwise."""
    if values is None:
        return None
    if not isinstance(values, dict):
        raise CalibrationError(loc, f'must be an object {{"E1": value, ...}}, got {values!r}')
    out = {}
    for key, v in values.items():
        if key not in get_args(ExtAxis):
            raise CalibrationError(loc + (str(key),), "external axes are E1..E6")
        f = _finite(v)
        if not abs(f) <= EXT_AXIS_LIMIT:
            raise CalibrationError(loc + (key,), f"must be a finite number (deg, or mm for a "
                                   f"rail) within ±{EXT_AXIS_LIMIT:g}, got {v!r}")
        out[key] = f
    return out


def unplaced_positions(points: list) -> list:
    """Findings for points touched with an external axis away from 0 (or at several values)
    that nothing puts in the world (no rail given to ``pendant calibrate``): the menu solves
    in the robot base as it stood, which is off by the travel when the axis carries the
    robot."""
    from solvers.report import Finding

    values: dict[str, list[float]] = {}
    for p in points:
        for axis, v in (p.external_axes or {}).items():
            values.setdefault(axis, []).append(float(v))
    out = []
    for axis, vals in sorted(values.items()):
        if max(vals) - min(vals) > 1e-6 or max(abs(v) for v in vals) > 1e-9:
            at = ", ".join(f"{v:g}" for v in sorted(set(vals)))
            out.append(Finding(
                "external_axes_ignored", f"the points were touched at {axis} = {at}, and nothing "
                f"says what {axis} moves: solved in the robot base as it stood at each point. If "
                f"{axis} carries the robot (a rail), the frame is off by its travel: give the "
                f'rail (inputs.rail {{"axis": "{axis}", "direction": [x, y, z]}} or --rail '
                f"{axis}:X,Y,Z)", ("points",)))
    return out


def entry_covariance(db: Session, controller_id: int, table: str,
                     number: int) -> tuple[np.ndarray | None, float | None, str]:
    """The stored covariance (3, 3, mm²) of the position of tool (TCP in the flange) or base
    (a fixed tool's TCP in the world) ``number``: that of the last saved session that wrote
    the position the slot holds now, with the chain's terms when that session had them
    (``extras.position_covariance_total_mm2``), the degrees of freedom of its sigma (None:
    known) and where it comes from; (None, None, why) when there is none (typed in, imported,
    or edited since)."""
    e = crud.get_entry(db, controller_id, table, number)
    what = f"{'tool' if table == 'tool' else 'base'} {number}"
    sessions = db.scalars(select(CalibSession).where(
        CalibSession.controller_id == controller_id, CalibSession.target_table == table,
        CalibSession.target_no == number, CalibSession.state == "saved")
        .order_by(CalibSession.id.desc())).all()
    for s in sessions:
        rep = s.report or {}
        total = (rep.get("extras") or {}).get("position_covariance_total_mm2")
        if tuple(rep.get("parameter_names") or ())[:3] != XYZ_PARAMETERS and total is None:
            continue  # an ABC menu: it kept the position
        vals = s.result_values()
        if vals is None or not np.allclose(vals[:3], (e.x_mm, e.y_mm, e.z_mm), atol=1e-6):
            break  # the slot holds another TCP since: not this session's
        where = f"{s.method} session {s.id}"
        if total is not None:
            dof = (rep.get("extras") or {}).get("position_covariance_total_dof")
            return np.array(total, dtype=float), (None if dof is None else float(dof)), where
        if not rep.get("covariance"):
            break
        C = np.array(rep["covariance"], dtype=float)[:3, :3]
        dof = rep.get("dof") or (rep.get("extras") or {}).get("position_dof")  # an Offset's
        return C, (float(dof) if dof else None), where
    return None, None, (f"{what} has no stored covariance (not calibrated here, or edited "
                  "since): its position counts as exact in the bound")


def chain_points(rail: Rail | None, points: list, method: str) -> tuple[list, list, dict]:
    """The touch-ups put in the world through the rail (:func:`solvers.external.chain.to_world`),
    the findings that say what the chain assumed, and the rail's values (``{"values_mm"}``).

    Raises CalibrationError naming the point and the rail's axis when the rail is not
    calibrated and the touch-ups were taken at different rail positions."""
    from server.menus.methods import TaughtData
    from solvers.external.chain import to_world
    from solvers.report import Finding

    if rail is None or method in NO_CHAIN:
        return points, [], {}
    taught = [(k, p) for k, p in enumerate(points) if p is not None and p.external_axes]
    vals = {k: float(p.external_axes.get(rail.axis, 0.0)) for k, p in taught}
    if not vals or all(v == 0.0 for v in vals.values()):
        return points, [], {}
    first_k = min(vals)
    for k, v in vals.items():
        if not rail.calibrated and abs(v - vals[first_k]) > 1e-6:
            raise CalibrationError(("points", k, "external_axes", rail.axis),
                                   f"{rail.label} is not calibrated: point {k + 1} was touched "
                                   f"at {rail.axis} = {v:g} mm and point {first_k + 1} at "
                                   f"{vals[first_k]:g} mm, which its machine data cannot put in "
                                   f"one frame. Calibrate the rail (External kinematics > "
                                   f"Linear unit into EX_KIN {rail.number}) or touch every point "
                                   f"at one {rail.axis} position")
    out = list(points)
    for k, p in taught:
        T = to_world(p.T_base_flange[None], [vals[k]], rail.direction, rail.scale)[0]
        out[k] = TaughtData(T, p.beam_id, p.edge, p.velocity_mm_s, p.external_axes)
    used = sorted(set(vals.values()))
    at = ", ".join(f"{v:g}" for v in used)
    d = ", ".join(f"{x:.4f}" for x in rail.direction)
    if rail.calibrated:
        finding = Finding("rail_chain", f"touched at {rail.axis} = {at} mm: put in the world "
                          f"through {rail.label} as calibrated ({rail.method}: travel ({d}), "
                          f"scale {rail.scale:.5f})", (), "info")
    else:
        finding = Finding("rail_assumed", f"touched at {rail.axis} = {at} mm with {rail.label} "
                          f"not calibrated: assumed its machine data (travel ({d}), scale "
                          f"{rail.scale:g}); the result is off by the rail's own error. "
                          f"Calibrate it (External kinematics > Linear unit) or touch at "
                          f"{rail.axis} = 0", ("points",))
    info = {"rail": {"number": rail.number, "name": rail.name, "axis": rail.axis,
                     "calibrated": rail.calibrated, "method": rail.method,
                     "direction": rail.direction.tolist(), "scale": rail.scale,
                     "values_mm": [vals[k] for k, _ in taught]}}
    return out, [finding], info


def assumed_sigma_mm(c: Controller | None) -> float:
    """The touch scatter (mm per coordinate) a menu assumes where its points cannot estimate
    it: the cell's aim model, a person's eye on the mark (``POST .../robot/approach``'s
    default ``noise_mm``, :data:`server.api.schemas.AIM_NOISE_MM`) and the emulated arm's own
    noise (``.../cell/physics`` ``noise_mm``) together."""
    from server.api.schemas import AIM_NOISE_MM

    doc = (c.physics if c is not None else None) or {}
    noise = doc.get("noise_mm") if isinstance(doc, dict) else None
    return float(np.hypot(AIM_NOISE_MM, float(noise or 0.0)))


def _label_rail(rail: Rail) -> str:
    return f"rail EX_KIN {rail.number}"


def _root_terms(db: Session, k: ExternalKinematic, spec: Any, pts: list, inputs: Any,
                params: dict, terms: dict, dofs: dict, notes: dict) -> None:
    """Add to ``terms`` the chain terms of the root point that wrote EX_KIN ``k`` (the tool it
    was touched with, its rail), each carried through this Offset's solve by moving the root
    frame: the root's stored covariance (``ExtInputs.root_covariance``, in the Offset's own
    share) is its touch share only, the error of the tool that touched the root is its
    ``extras.covariance_terms`` (since 2026-11; a root computed before names the term as not
    in the bound). A term of the same tool, from the same session, as this Offset's own tool
    term is left out: the root and the base then move together with the TCP, the errors
    partly cancel and the Offset's own tool term already holds them."""
    rs = db.get(CalibSession, k.session_id) if k.session_id is not None else None
    extras = ((rs.report if rs is not None else None) or {}).get("extras") or {}
    stored = extras.get("covariance_terms") or {}
    named = extras.get("bound_terms") or {}
    ex = inputs.external
    for name, info in named.items():
        if name == "touch":
            continue
        label = f"EX_KIN {k.number} root: {name}"
        term = stored.get(name)
        if term is None:
            if info.get("position_bound95_mm") is not None:
                notes[label] = ("not stored with the root point (computed before the chain "
                                "kept its terms): not in the bound; compute the root again")
            continue
        source = info.get("source")
        mine = notes.get(name)
        if mine is not None and mine == source and name in terms:
            notes[label] = (f"{source}: the same tool as this base's, its error partly "
                            f"cancels; the {name} term holds it")
            continue
        root = np.asarray(ex.root, dtype=float)

        def moved(d: np.ndarray) -> np.ndarray:
            r = replace(ex, root=perturbed(root, d))
            return spec.solve(pts, replace(inputs, external=r), params).frame
        try:
            terms[label] = propagate(moved, np.zeros(6), np.array(term["covariance"], float))
            dofs[label] = term.get("dof")
            notes[label] = f"{source} (root point session {k.session_id})"
        except (CalibrationError, np.linalg.LinAlgError) as err:
            notes[label] = f"not propagated: {err}"


def solve_in_chain(db: Session, s: CalibSession, spec: Any, points: list,
                   inputs: Any) -> Any:
    """Solve session ``s`` with its touch-ups in the world (:func:`chain_points`), then widen
    the bounds by every calibrated element of the chain: the touching (reference, fixed) tool's
    stored covariance and the rail's slope, each carried through the menu's own solve
    (:func:`solvers.external.chain.propagate`). The solve's own covariance is read as it is
    reported, unwidened, with its degrees of freedom (``solvers.external.chain.report_dofs``:
    per block for the Offset and the positioner, whose covariances sum shares of different
    dof), so the total's F quantile is the Welch-Satterthwaite one of every share. The report
    says what the chain assumed (``warnings``), which term adds how much
    (``extras.bound_terms``) and the sigma the touch term assumed (``extras.assumed_sigma_mm``)."""

    from solvers.external.chain import (combined_bounds, own_covariance, propagate,
                                         report_dofs, welch_dof)
    from solvers.report import Finding

    if inputs.touch_sigma_mm is None:
        inputs = replace(inputs, touch_sigma_mm=assumed_sigma_mm(db.get(Controller,
                                                                         s.controller_id)))
    rail = rail_of(db, s.controller_id)
    pts, findings, info = chain_points(rail, points, s.method)
    result = spec.solve(pts, inputs, s.params)
    p = s.params
    candidates = []  # (inputs field, term name, table, slot number)
    if inputs.tcp_mm is not None:
        n = p.get("tool_no") or (s.target_no if s.target_table == "tool" else None)
        if n:
            candidates.append(("tcp_mm", f"tool {n} TCP", "tool", int(n)))
    if inputs.reference_tcp_mm is not None and p.get("reference_tool_no"):
        n = int(p["reference_tool_no"])
        candidates.append(("reference_tcp_mm", f"tool {n} TCP (reference)", "tool", n))
    if inputs.fixed_tcp_mm is not None and p.get("fixed_tool_no"):
        n = int(p["fixed_tool_no"])
        candidates.append(("fixed_tcp_mm", f"fixed tool (base {n})", "base", n))
    terms: dict[str, np.ndarray] = {}
    dofs: dict[str, float | None] = {}
    notes: dict[str, str] = {}
    for fld, name, table, n in candidates:
        C, nu, source = entry_covariance(db, s.controller_id, table, n)
        if C is None:
            notes[name] = source
            continue
        x0 = np.asarray(getattr(inputs, fld), dtype=float)
        try:
            terms[name] = propagate(lambda x, f=fld: spec.solve(  # type: ignore[misc]
                pts, replace(inputs, **{f: x}), s.params).frame, x0, C)
            dofs[name] = nu
            notes[name] = source
        except (CalibrationError, np.linalg.LinAlgError) as err:
            notes[name] = f"not propagated: {err}"
    if info and rail is not None:
        name = _label_rail(rail)
        if rail.slope_covariance is not None:
            b0 = -rail.scale * rail.direction

            def with_slope(b: np.ndarray) -> np.ndarray:
                k = float(np.linalg.norm(b))
                r = replace(rail, direction=-b / k, scale=k)
                return spec.solve(chain_points(r, points, s.method)[0], inputs, s.params).frame
            try:
                terms[name] = propagate(with_slope, b0, rail.slope_covariance)
                dofs[name] = rail.slope_dof
                notes[name] = f"ext.linear_unit (EX_KIN {rail.number})"
            except (CalibrationError, np.linalg.LinAlgError) as err:
                notes[name] = f"not propagated: {err}"
        else:
            notes[name] = ("not calibrated: machine data assumed, its error is not in the bound"
                           if not rail.calibrated else
                           f"{rail.method}: no stored covariance, counts as exact")
    ex = inputs.external
    if ex is not None and s.target_table != TABLE:  # a base riding on EX_KIN n (the Offset)
        k = get_slot(db, s.controller_id, ex.number)
        if k.method == "ext.root_point" and ex.root is not None:
            _root_terms(db, k, spec, pts, inputs, s.params, terms, dofs, notes)
        if k.method in (None, "", "machine_data"):
            findings.append(Finding(
                "kinematic_assumed", f"EX_KIN {k.number} ({k.name or k.kind}) is not "
                f"calibrated: the base is placed on its machine data (root frame as entered); "
                f"calibrate its root point first for a base that stays on the table as it "
                f"turns", ("params", "ext_no")))
            notes[f"EX_KIN {k.number} root"] = "not calibrated: machine data assumed, its error " \
                                              "is not in the bound"
    r = result.report
    extras = dict(r.extras)
    if info:
        extras["chain"] = info
    sigma_note = None
    if r.sigma_source == "assumed" and r.sigma_mm is not None:
        extras["assumed_sigma_mm"] = float(r.sigma_mm)
        sigma_note = Finding("assumed_sigma", f"assumed σ = {r.sigma_mm:g} mm per coordinate "
                             "(the cell's aim): the points leave no residual to estimate the "
                             "touch scatter, so the touch term of the bound rests on it; "
                             "touch more points to measure it", (), "info")
    own_dofs = report_dofs(r)  # (position, angle): the Offset's and the positioner's per block
    bounds = combined_bounds(r.position_bound95_mm, r.angle_bound95_deg, terms, own_dofs,
                             own_covariance(r), dofs)
    for name, note in notes.items():
        bounds["terms"].setdefault(name, {"position_bound95_mm": None,  # type: ignore[index]
                                          "angle_bound95_deg": None})
        bounds["terms"][name]["source"] = note  # type: ignore[index]
    extras["bound_terms"] = bounds["terms"]
    if terms:  # each term's own covariance (6, 6), for a frame that rests on this one
        extras["covariance_terms"] = {name: {"covariance": C.tolist(), "dof": dofs.get(name)}
                                      for name, C in terms.items()}
    if terms:
        parts = [(C[:3, :3], dofs.get(name)) for name, C in terms.items()]
        names = tuple(r.parameter_names)[:3]
        if r.covariance is not None and names == XYZ_PARAMETERS:
            parts.append((np.asarray(r.covariance, dtype=float)[:3, :3], own_dofs[0]))
        total = sum(C for C, _ in parts)
        extras["position_covariance_total_mm2"] = total.tolist()
        extras["position_covariance_total_dof"] = welch_dof(
            [float(np.trace(C)) for C, _ in parts], [nu for _, nu in parts])
    kept = tuple(w for w in r.warnings if not (sigma_note and w.code == sigma_note.code))
    new_findings = tuple(findings) + ((sigma_note,) if sigma_note else ())
    report = replace(r, position_bound95_mm=bounds["position_bound95_mm"],
                     angle_bound95_deg=bounds["angle_bound95_deg"], extras=extras,
                     warnings=kept + new_findings)
    return replace(result, report=report)
