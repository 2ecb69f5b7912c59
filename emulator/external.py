"""The emulated cell's external axes: a turntable, a tilt-and-turn positioner and a rail.

A controller created with ``external_axes`` (the demo controller ``cell-1`` is) has four
external axes, grouped as a KUKA controller groups them into external kinematics
(``EX_KIN`` 1..6, machine data ``$ET1_...``):

====  ===================  ==========================  ============================
axis  kinematic            moves                        unit, software limits
====  ===================  ==========================  ============================
E1    EX_KIN 1, turntable  the table about its axis    deg, -185 .. 185
E2    EX_KIN 2, positioner the tilt axis               deg, -90 .. 90
E3    EX_KIN 2, positioner the turn axis (on the tilt) deg, -185 .. 185
E4    EX_KIN 3, rail       the carriage carrying the   mm, -400 .. 400
                           robot
====  ===================  ==========================  ============================

The truth is :mod:`solvers.external_sim`'s machines with the hidden errors of
:data:`ERROR_FIELDS` (seeded small ones by default; ``PUT .../cell/external`` sets them). The
controller knows only the nominal machine data (:func:`nominal_kinematics`), which the
external-kinematics menus calibrate. World is the robot base at rail position 0; with the rail
moved, everything fixed in the cell (the turntable, the positioner, the reference tip, the
plate, ...) is seen from the moved robot base (:func:`target`). Pure: numpy and
:mod:`solvers` only.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.spatial.transform import Rotation

from emulator.controller import Cell, Target
from solvers.errors import CalibrationError
from solvers.external_sim import (LinearUnit, Positioner, Turntable, make_linear_unit,
                                  make_positioner, make_turntable)
from solvers.frames import invert, rotation_matrix
from solvers.validate import FloatArray

AXES = ("E1", "E2", "E3", "E4")
LIMITS: dict[str, tuple[float, float]] = {"E1": (-185.0, 185.0), "E2": (-90.0, 90.0),
                                          "E3": (-185.0, 185.0), "E4": (-400.0, 400.0)}
UNITS = {"E1": "deg", "E2": "deg", "E3": "deg", "E4": "mm"}
#: kinematic slot (EX_KIN n) -> (kind, its axes)
KINEMATICS: dict[int, tuple[str, tuple[str, ...]]] = {1: ("turntable", ("E1",)),
                                                      2: ("positioner", ("E2", "E3")),
                                                      3: ("linear_unit", ("E4",))}
AXIS_SPEED = {"deg": 60.0, "mm": 250.0}  # per second, for the emulated clock
MOVE_OVERHEAD_S = 0.5

#: the hidden errors, per machine, and their neutral value
ERROR_FIELDS: dict[str, dict[str, float]] = {
    "turntable": {"tilt_deg": 0.0, "root_offset_mm": 0.0, "sign": 1.0, "scale": 1.0},
    "positioner": {"tilt_deg": 0.0, "root_offset_mm": 0.0, "sign": 1.0, "scale": 1.0,
                   "turn_tilt_deg": 0.0, "axis_offset_mm": 0.0, "turn_sign": 1.0},
    "rail": {"direction_tilt_deg": 0.0, "sign": 1.0, "scale": 1.0},
}
_SIGNS = ("sign", "turn_sign")
_LIMIT = {"deg": 10.0, "mm": 50.0, "scale": 0.1}  # an error beyond these is a typo, not a cell

# where things are, drawn for the KR 6 R900 sixx (reach 901 mm) and scaled to the arm's reach
TABLE_ROOT_MM = (520.0, 380.0, 80.0)  # turntable: axis +z through here, the table's top
TABLE_MARK_MM = (150.0, 0.0, 0.0)  # the mark on the table (flange frame)
TABLE_PLATE = ((40.0, -60.0, 0.0), 25.0)  # a base plate on the table: origin (flange), yaw deg
TABLE_PLATE_POINTS = {"origin": (0.0, 0.0, 0.0), "x": (150.0, 0.0, 0.0), "xy": (40.0, 110.0, 0.0)}
TABLE_PLATE_AXIS_DEG = 30.0  # the axis value at which the Offset menu touches the plate
POSITIONER_ROOT_MM = (420.0, -420.0, 220.0)  # tilt axis along base +x through here
POSITIONER_TABLE_MM = 100.0  # turn table above the tilt axis
POSITIONER_MARK_MM = (110.0, 0.0, 0.0)
RAIL_MARK_MM = (560.0, 100.0, 250.0)  # a mark fixed in the cell (world = base at rail 0)


def _check_errors(doc: dict) -> dict[str, dict[str, float]]:
    """``doc`` with every field filled; CalibrationError naming a wrong field."""
    if not isinstance(doc, dict):
        raise CalibrationError((), "must be an object with turntable, positioner, rail")
    out: dict[str, dict[str, float]] = {}
    for machine, fields in ERROR_FIELDS.items():
        given = doc.get(machine) or {}
        if not isinstance(given, dict):
            raise CalibrationError((machine,), "must be an object")
        unknown = sorted(set(given) - set(fields))
        if unknown:
            raise CalibrationError((machine, unknown[0]), f"unknown field; {machine} has "
                                   f"{', '.join(fields)}")
        vals = dict(fields)
        for k, v in given.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise CalibrationError((machine, k), "must be a finite number")
            v = float(v)
            if k in _SIGNS and v not in (1.0, -1.0):
                raise CalibrationError((machine, k), f"must be +1 or -1, got {v:g}")
            if k == "scale" and abs(v - 1.0) > _LIMIT["scale"]:
                raise CalibrationError((machine, k), f"must be within 1 ± {_LIMIT['scale']:g}")
            unit = "deg" if k.endswith("_deg") else "mm" if k.endswith("_mm") else None
            if unit and abs(v) > _LIMIT[unit]:
                raise CalibrationError((machine, k), f"at most ±{_LIMIT[unit]:g} {unit}")
            vals[k] = v
        out[machine] = vals
    unknown = sorted(set(doc) - set(ERROR_FIELDS))
    if unknown:
        raise CalibrationError((unknown[0],), "unknown machine; the cell has "
                               + ", ".join(ERROR_FIELDS))
    return out


def check_errors(doc: dict) -> dict[str, dict[str, float]]:
    """The hidden errors document, every field filled (``PUT .../cell/external``).

    >>> check_errors({"turntable": {"tilt_deg": 1}})["turntable"]["tilt_deg"]
    1.0
    """
    return _check_errors(doc)


def default_errors(seed: int) -> dict[str, dict[str, float]]:
    """The demo's hidden errors: small and seeded (a cell as it was bolted down)."""
    rng = np.random.default_rng([int(seed), 13])
    return _check_errors({
        "turntable": {"tilt_deg": round(float(rng.uniform(0.3, 0.8)), 3),
                      "root_offset_mm": round(float(rng.uniform(1.5, 3.0)), 3)},
        "positioner": {"axis_offset_mm": round(float(rng.uniform(1.0, 2.0)), 3),
                       "turn_tilt_deg": round(float(rng.uniform(0.2, 0.5)), 3)},
        "rail": {"direction_tilt_deg": round(float(rng.uniform(0.3, 0.6)), 3),
                 "scale": round(float(1.0 + rng.uniform(0.001, 0.003)), 5)}})


@dataclass(frozen=True)
class ExternalCell:
    """The true machines, their nominal machine data and the marks (mm; world = base at rail 0)."""

    turntable: Turntable
    positioner: Positioner
    rail: LinearUnit
    scale: float  # the layout's scale (the arm's reach / 901 mm)
    T_flange_plate: FloatArray  # the plate on the turntable, in its true flange frame

    def mark_flange(self, what: str) -> FloatArray:
        m = TABLE_MARK_MM if what == "turntable" else POSITIONER_MARK_MM
        return np.asarray(m, float) * self.scale

    def T_world_base(self, values: dict[str, float]) -> FloatArray:
        """The robot base in the world at the rail position E4 (true, hidden errors included)."""
        return self.rail.base_pose([values.get("E4", 0.0)])[0]

    def world_points(self, values: dict[str, float]) -> dict[str, FloatArray]:
        """Every external target's true position in the world at these axis values."""
        t = self.turntable.flange([values.get("E1", 0.0)])[0]
        out = {"turntable_mark": t[:3, :3] @ self.mark_flange("turntable") + t[:3, 3]}
        P = t @ self.T_flange_plate
        for k, v in TABLE_PLATE_POINTS.items():
            out[f"turntable_base_{k}"] = P[:3, :3] @ (np.asarray(v) * self.scale) + P[:3, 3]
        p = self.positioner.flange([values.get("E2", 0.0)], [values.get("E3", 0.0)])[0]
        out["positioner_mark"] = p[:3, :3] @ self.mark_flange("positioner") + p[:3, 3]
        out["rail_mark"] = np.asarray(RAIL_MARK_MM, float) * self.scale
        return out


def _frame(R: FloatArray, t: object) -> FloatArray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


@lru_cache(maxsize=64)
def _build(reach_mm: float, errors_json: str) -> ExternalCell:
    e = json.loads(errors_json)
    s = (reach_mm or 901.0) / 901.0
    tt = e["turntable"]
    table = make_turntable(tilt_deg=tt["tilt_deg"], root_offset_mm=tt["root_offset_mm"],
                           sign=int(tt["sign"]), scale=tt["scale"],
                           nominal_root=_frame(np.eye(3), np.asarray(TABLE_ROOT_MM) * s))
    p = e["positioner"]
    tilt_root = _frame(Rotation.from_euler("y", 90, degrees=True).as_matrix(),
                       np.asarray(POSITIONER_ROOT_MM) * s)
    pos = make_positioner(tilt_deg=p["tilt_deg"], root_offset_mm=p["root_offset_mm"],
                          sign=int(p["sign"]), scale=p["scale"], turn_tilt_deg=p["turn_tilt_deg"],
                          axis_offset_mm=p["axis_offset_mm"], turn_sign=int(p["turn_sign"]),
                          table_height_mm=POSITIONER_TABLE_MM * s, nominal_tilt_root=tilt_root)
    r = e["rail"]
    rail = make_linear_unit(direction_tilt_deg=r["direction_tilt_deg"], sign=int(r["sign"]),
                            scale=r["scale"])
    origin, yaw = TABLE_PLATE
    plate = rotation_matrix(Rotation.from_euler("z", yaw, degrees=True), np.asarray(origin) * s)
    return ExternalCell(table, pos, rail, s, plate)


def external_cell(reach_mm: float, errors: dict | None, seed: int) -> ExternalCell:
    """The true external machines of a cell: ``errors`` (None = the seeded defaults)."""
    doc = default_errors(seed) if errors is None else _check_errors(errors)
    return _build(float(reach_mm), json.dumps(doc, sort_keys=True))


def nominal_kinematics(ext: ExternalCell) -> dict[int, dict]:
    """The machine data the controller starts with (EX_KIN 1..3): per slot ``kind``, ``axes``,
    ``root`` (T_base_root, or T_base_rail for the rail: z the travel direction) and ``flange``
    (the positioner: the turn axis' root in the tilt flange; else identity)."""
    rail_root = np.eye(4)
    d = ext.rail.nominal_in_base
    x = np.array([0.0, 0.0, 1.0]) - d[2] * d
    x /= np.linalg.norm(x)
    rail_root[:3, :3] = np.column_stack([x, np.cross(d, x), d])
    return {1: {"kind": "turntable", "axes": ["E1"], "root": ext.turntable.nominal_root,
                "flange": np.eye(4)},
            2: {"kind": "positioner", "axes": ["E2", "E3"],
                "root": ext.positioner.tilt.nominal_root,
                "flange": ext.positioner.nominal_turn_in_tilt},
            3: {"kind": "linear_unit", "axes": ["E4"], "root": rail_root, "flange": np.eye(4)}}


def target_names() -> list[str]:
    return (["turntable_mark"] + [f"turntable_base_{k}" for k in TABLE_PLATE_POINTS]
            + ["positioner_mark", "rail_mark"])


def target(ext: ExternalCell, cell: Cell, name: str, values: dict[str, float]) -> Target:
    """The target ``name`` as the robot sees it at these axis values (robot base): an external
    mark (touched from above, tool straight down) or a cell target seen from the moved base."""
    B = invert(ext.T_world_base(values))
    if name in target_names():
        p = ext.world_points(values)[name]
        return Target(name, B[:3, :3] @ p + B[:3, 3], B[:3, :3])
    t = cell.target(name)  # KinematicsError naming the target when unknown
    if values.get("E4", 0.0) == 0.0 and np.allclose(B, np.eye(4)):
        return t
    return Target(t.name, B[:3, :3] @ t.point_mm + B[:3, 3], B[:3, :3] @ t.R_world_target,
                  t.held, t.held_point_mm, t.align)


def check_values(values: dict[str, float], loc: tuple = ("external_axes",)) -> dict[str, float]:
    """Axis values as floats, each known and inside its limits (CalibrationError naming it)."""
    out = {}
    for k, v in values.items():
        if k not in LIMITS:
            raise CalibrationError((*loc, k), f"unknown external axis; the cell has "
                                   f"{', '.join(AXES)}")
        lo, hi = LIMITS[k]
        if not lo <= float(v) <= hi:
            raise CalibrationError((*loc, k), f"{k} at {float(v):g} {UNITS[k]} is outside its "
                                   f"software limit [{lo:g}, {hi:g}] {UNITS[k]}")
        out[k] = float(v)
    return out


def jog(values: dict[str, float], axis: str, increment: float) -> dict[str, float]:
    """One increment of external axis ``axis`` (deg, or mm for the rail).

    >>> jog({"E1": 0.0, "E2": 0.0, "E3": 0.0, "E4": 0.0}, "E1", 10.0)["E1"]
    10.0
    """
    if axis not in LIMITS:
        raise CalibrationError(("axis",), f"unknown external axis {axis!r}; the cell has "
                               f"{', '.join(AXES)}")
    new = dict(values)
    new[axis] = float(values.get(axis, 0.0)) + float(increment)
    lo, hi = LIMITS[axis]
    if not lo <= new[axis] <= hi:
        raise CalibrationError(("increment",), f"{axis} {increment:+g}: {axis} at "
                               f"{new[axis]:g} {UNITS[axis]} is outside its software limit "
                               f"[{lo:g}, {hi:g}] {UNITS[axis]}")
    return new


def motion_s(before: dict[str, float], after: dict[str, float]) -> float:
    """Emulated time of an external-axis move (the slowest axis, plus the overhead)."""
    t = max((abs(after.get(k, 0.0) - before.get(k, 0.0)) / AXIS_SPEED[UNITS[k]] for k in AXES),
            default=0.0)
    return 0.0 if t == 0.0 else MOVE_OVERHEAD_S + t


def home() -> dict[str, float]:
    return {k: 0.0 for k in AXES}


__all__ = ["AXES", "LIMITS", "UNITS", "KINEMATICS", "ERROR_FIELDS", "ExternalCell",
           "check_errors", "default_errors", "external_cell", "nominal_kinematics",
           "target_names", "target", "check_values", "jog", "motion_s", "home"]
