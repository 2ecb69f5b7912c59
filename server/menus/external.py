"""The external-kinematics menus (KUKA *Calibrate > External kinematics*): their steps and the
adapters onto :mod:`solvers.external`. Registered into ``server.menus.METHODS``.

==========================  ===========  ==============================================
method                      writes       steps (demo cell: the wizard's Move to)
==========================  ===========  ==============================================
``ext.root_point``          EX_KIN n     the table's mark at E1 = -135, -45, 45 (+ up to 9)
``ext.root_point_numeric``  EX_KIN n     none: ``params.pose`` is T_base_root
``ext.offset``              BASE n       origin, +X, XY of the plate on the table at E1 = 30
``ext.offset_numeric``      BASE n       none: ``params.pose`` is T_flange_base
``ext.linear_unit``         EX_KIN n     the cell's mark at E4 = -250, 0, 250 mm (+ up to 9)
``ext.positioner_2axis``    EX_KIN n     the table's mark at E2 = -75, -25, 25, 75, then at
                                         E3 = -135, -45, 45, 135
==========================  ===========  ==============================================

Every touch-up carries the external axis values (``TaughtData.external_axes``); the adapters
pick the kinematic's axis, take the nominal machine data from its EX_KIN slot
(:class:`ExtInputs`, resolved by ``server.service.external.ext_inputs``) and rename the solvers'
fields to the API's (``("points", k, "external_axes", "E1")``). No math beyond composing the
slot's frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from server.menus.methods import (MethodInputs, MethodSpec, Step, TaughtData, _need, _poses, _sigma,
                            _tcp)
from solvers.dh import tcp_of
from solvers.errors import CalibrationError
from solvers.external import (linear_unit, offset, offset_numeric, positioner_2axis, root_point,
                              root_point_numeric)
from solvers.external.common import rz
from solvers.frames import Pose, invert
from solvers.report import CalibrationResult
from solvers.validate import FloatArray

ROTARY_LIMITS = (-185.0, 185.0)


@dataclass(frozen=True)
class ExtInputs:
    """The external kinematic a session works on, from its EX_KIN slot: kind, axes, root frame
    ``T_base_root`` and flange offset (a positioner's turn root in its tilt flange), the axis
    the menu reads (``axis``), the root point's covariance, dof and sigma (for the Offset's
    bounds)."""

    number: int
    kind: str
    axes: tuple[str, ...]
    root: FloatArray | None  # None: no machine data to compare with (an empty root frame)
    flange: FloatArray = field(default_factory=lambda: np.eye(4))
    axis: str | None = None
    root_covariance: FloatArray | None = None
    root_dof: int = 0
    root_sigma_mm: float | None = None


def _ext(inp: MethodInputs) -> ExtInputs:
    return _need(inp.external, "ext_no", "the external kinematic (EX_KIN 1..6)")


def _values(points: Sequence[TaughtData], axis: str) -> FloatArray:
    """The recorded value of ``axis`` at every touch-up (CalibrationError naming the point)."""
    out = []
    for k, p in enumerate(points):
        v = (p.external_axes or {}).get(axis)
        if v is None:
            raise CalibrationError(("points", k, "external_axes", axis), f"point {k + 1} was "
                                   f"taught without a value of {axis}: touch up on a controller "
                                   f"with external axes, or send external_axes with the joints")
        out.append(float(v))
    return np.array(out)


def _renamed(err: CalibrationError, axis: str, offset_k: int = 0) -> CalibrationError:
    """The solver's field as the API's: points_mm -> points, axis_values -> the E axis."""
    loc = list(err.loc)
    if loc and loc[0] in ("points_mm", "tilt_points_mm", "turn_points_mm"):
        loc[0] = "points"
    elif loc and loc[0] in ("axis_values_deg", "axis_values_mm", "tilt_values_deg",
                            "turn_values_deg"):
        loc = ["points", *loc[1:], "external_axes", axis] if len(loc) > 1 else \
              ["points", "external_axes", axis]
    if offset_k and len(loc) > 1 and isinstance(loc[1], int):
        loc[1] += offset_k
    return CalibrationError(tuple(loc), err.reason)


def _touched(points: Sequence[TaughtData], inp: MethodInputs) -> FloatArray:
    return tcp_of(_poses(points), _tcp(inp))


def _nominal_root(ex: ExtInputs, axis: str, values: dict[str, float]) -> FloatArray:
    """The machine data's frame of ``axis``: a positioner's turn axis rides on its tilt
    (identity when there is no machine data)."""
    root = np.eye(4) if ex.root is None else ex.root
    if ex.kind == "positioner" and len(ex.axes) == 2 and axis == ex.axes[1]:
        return root @ rz([values.get(ex.axes[0], 0.0)])[0] @ ex.flange
    return root


def _nominal_point(ex: ExtInputs, nominal: FloatArray) -> FloatArray | None:
    """A point on the nominal axis, or None without machine data (no root offset to name)."""
    return None if ex.root is None else nominal[:3, 3]


def _top_view(res: CalibrationResult, P: FloatArray) -> CalibrationResult:
    """Add ``extras["top_view"]``: the marks in the root frame's XY plane (the fitted circle is
    centred at its origin with ``radius_mm``), for the pendant's drawing."""
    local = (invert(res.frame) @ np.c_[P, np.ones(len(P))].T).T[:, :3]
    extras = dict(res.report.extras)
    extras["top_view"] = {"points_mm": local[:, :2], "height_mm": local[:, 2],
                          "radius_mm": extras.get("radius_mm")}
    return replace(res, report=replace(res.report, extras=extras))


def _root_point(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    ex = _ext(inp)
    axis = ex.axis or ex.axes[0]
    P = _touched(points, inp)
    theta = _values(points, axis)
    nominal = _nominal_root(ex, axis, points[0].external_axes or {})
    try:
        res = root_point(P, theta, nominal_axis=nominal[:3, 2],
                         nominal_root_mm=_nominal_point(ex, nominal), axis_limits_deg=ROTARY_LIMITS,
                         **_sigma(inp))
    except CalibrationError as err:
        raise _renamed(err, axis) from None
    return _top_view(res, P)


def _same_position(points: Sequence[TaughtData], axes: Sequence[str]) -> dict[str, float]:
    """The axis values all points were touched at (CalibrationError naming the one that moved)."""
    first = {a: float(v) for a, v in _values_dict(points[0], axes).items()}
    for k, p in enumerate(points[1:], start=1):
        for a, v in _values_dict(p, axes).items():
            if abs(v - first[a]) > 1e-6:
                raise CalibrationError(("points", k, "external_axes", a), f"point {k + 1} was "
                                       f"touched at {a} = {v:g}, point 1 at {first[a]:g}: touch "
                                       "all three points at one axis position")
    return first


def _values_dict(p: TaughtData, axes: Sequence[str]) -> dict[str, float]:
    return {a: float(_values([p], a)[0]) for a in axes}


def _offset(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    ex = _ext(inp)  # a turntable or a positioner (server.service.external.ext_inputs checks)
    values = _same_position(points, ex.axes)
    origin, x_point, xy_point = _touched(points, inp)
    turning = ex.axes[-1]
    root = _nominal_root(ex, turning, values)
    return offset(origin, x_point, xy_point, values[turning], root,
                  root_covariance=ex.root_covariance, root_dof=ex.root_dof,
                  root_sigma_mm=ex.root_sigma_mm, **_sigma(inp))


def _linear_unit(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    ex = _ext(inp)
    axis = ex.axis or ex.axes[0]
    try:
        return linear_unit(_touched(points, inp), _values(points, axis),
                           nominal_direction=_nominal_root(ex, axis, {})[:3, 2], **_sigma(inp))
    except CalibrationError as err:
        raise _renamed(err, axis) from None


N_TILT = 4  # ext.positioner_2axis: steps 1..4 turn the tilt axis, 5..8 the turn axis


def _result_summary(res: CalibrationResult) -> dict[str, Any]:
    r = res.report
    return {"frame": Pose.from_matrix(res.frame), "position_bound95_mm": r.position_bound95_mm,
            "angle_bound95_deg": r.angle_bound95_deg, "radius_mm": r.extras.get("radius_mm"),
            "scale": r.extras.get("scale"), "axis_tilt_deg": r.extras.get("axis_tilt_deg"),
            "warnings": [w.code for w in r.warnings]}


def _positioner(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    ex = _ext(inp)
    if ex.kind != "positioner" or len(ex.axes) != 2:
        raise CalibrationError(("target_no",), f"external kinematic {ex.number} is {ex.kind!r} "
                               f"with axes {', '.join(ex.axes) or 'none'}: the positioner menu "
                               "needs a positioner with a tilt and a turn axis")
    tilt_axis, turn_axis = ex.axes
    P = _touched(points, inp)
    tilt_pts, turn_pts = points[:N_TILT], points[N_TILT:]
    tau = _values(turn_pts[:1], tilt_axis)[0]
    for k, v in enumerate(_values(turn_pts, tilt_axis)):
        if abs(v - tau) > 1e-6:
            raise CalibrationError(("points", N_TILT + k, "external_axes", tilt_axis),
                                   f"the turn axis is taught at one tilt: {tilt_axis} was "
                                   f"{tau:g} at point {N_TILT + 1} and {v:g} here")
    tilt_nominal = _nominal_root(ex, tilt_axis, {})
    turn_nominal = _nominal_root(ex, turn_axis, {})
    try:
        res = positioner_2axis(P[:N_TILT], _values(tilt_pts, tilt_axis), P[N_TILT:],
                               _values(turn_pts, turn_axis), tau,
                               nominal_tilt_axis=tilt_nominal[:3, 2],
                               nominal_turn_axis=turn_nominal[:3, 2],
                               nominal_root_mm=_nominal_point(ex, tilt_nominal), **_sigma(inp))
    except CalibrationError as err:
        is_turn = str(err.loc[0]).startswith("turn") if err.loc else False
        raise _renamed(err, turn_axis if is_turn else tilt_axis,
                       N_TILT if is_turn else 0) from None
    extras = dict(res.report.extras)
    extras["tilt"] = _result_summary(extras["tilt"])
    extras["turn"] = _result_summary(extras["turn"])
    extras["tilt_root"] = Pose.from_matrix(extras["tilt_root"]).as_array()
    return replace(res, report=replace(res.report, extras=extras))


def inputs_from_document(doc: dict[str, Any] | None,
                         points: Sequence[TaughtData]) -> ExtInputs:
    """:class:`ExtInputs` of a file (``pendant calibrate``): ``inputs.kinematic`` =
    ``{"kind", "axes", "root": {x..c}, "flange": {x..c}}``, every field optional (default: a
    turntable moving the first point's first external axis, no machine data)."""
    doc = dict(doc or {})
    first = sorted((points[0].external_axes or {}) if points else {})
    axes = tuple(doc.get("axes") or first[:1] or ("E1",))
    try:
        root = None if doc.get("root") is None else Pose(**doc["root"]).as_matrix()
        flange = np.eye(4) if doc.get("flange") is None else Pose(**doc["flange"]).as_matrix()
    except TypeError as err:
        raise CalibrationError(("inputs", "kinematic"), f"root and flange are poses "
                               f"{{x, y, z, a, b, c}}: {err}") from None
    return ExtInputs(number=int(doc.get("number", 1)), kind=str(doc.get("kind", "turntable")),
                     axes=axes, root=root, flange=flange, axis=doc.get("axis"))


def _pose(inp: MethodInputs, what: str) -> Pose:
    return _need(inp.pose, "pose", what)


def _root_point_numeric(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    return root_point_numeric(_pose(inp, "the root frame as x, y, z, a, b, c"))


def _offset_numeric(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    return offset_numeric(_pose(inp, "the base in the kinematic's flange frame"))


# ----------------------------------------------------------------------------------- steps

_MARK = "Touch the mark on the table with {axis} at {value:g} {unit}"
_ROOT_VALUES = (-135.0, -45.0, 45.0)
_ROOT_EXTRA = (135.0, 0.0, 90.0, -90.0, 170.0, -170.0, 20.0, -20.0, 65.0)
_RAIL_VALUES = (-250.0, 0.0, 250.0)
_RAIL_EXTRA = (-125.0, 125.0, -190.0, 190.0, -60.0, 60.0, 220.0, -220.0, 90.0)
_AROUND = (0.0, 90.0, 180.0, 270.0, 45.0, 135.0, 225.0, 315.0, 20.0, 200.0, 110.0, 290.0)


#: the rail carrying the robot: every step of a kinematic it does not calibrate puts it at 0
#: (Move to sets every axis of the chain, not only the menu's own)
RAIL_AXIS = "E4"


def _touch(prompt: str, target: str, k: int, **axes: float) -> Step:
    chain = {**axes} if RAIL_AXIS in axes else {**axes, RAIL_AXIS: 0.0}
    return Step(prompt, target, tilt_deg=10.0, around_deg=_AROUND[k % len(_AROUND)],
                external_axes=tuple(chain.items()))


def _root_step(k: int, value: float, optional: bool = False) -> Step:
    prompt = _MARK.format(axis="E1", value=value, unit="deg") + (" (optional)" if optional else "")
    return _touch(prompt, "turntable_mark", k, E1=value)


def _rail_step(k: int, value: float, optional: bool = False) -> Step:
    prompt = (f"Touch the mark in the cell with the rail E4 at {value:g} mm"
              + (" (optional)" if optional else ""))
    return _touch(prompt, "rail_mark", k, E4=value)


_PLATE = (("origin", "the origin of the base on the table"),
          ("x", "a point on the positive X axis of that base"),
          ("xy", "a point in its XY plane with a positive Y value"))

EXTERNAL_METHODS: tuple[MethodSpec, ...] = (
    MethodSpec("ext.root_point", "ext", "External kinematics > Root point", "extkin", "extkin",
               "frame", tuple(_root_step(k, v) for k, v in enumerate(_ROOT_VALUES)),
               _root_point, extra_steps=len(_ROOT_EXTRA), required=("tool_no",),
               extra_prompt=_MARK,
               extra_step_fn=lambda k: _root_step(k + 3, _ROOT_EXTRA[k], True)),
    MethodSpec("ext.root_point_numeric", "ext", "External kinematics > Root point (numeric)",
               "extkin", "extkin", "frame", (), _root_point_numeric, required=("pose",)),
    MethodSpec("ext.offset", "ext", "External kinematics > Offset", "base", "coordinated_base",
               "frame", tuple(_touch(f"With E1 at 30 deg, bring the TCP to {what}",
                                     f"turntable_base_{key}", k, E1=30.0)
                              for k, (key, what) in enumerate(_PLATE)),
               _offset, required=("tool_no", "ext_no")),
    MethodSpec("ext.offset_numeric", "ext", "External kinematics > Offset (numeric)", "base",
               "coordinated_base", "frame", (), _offset_numeric, required=("pose", "ext_no")),
    MethodSpec("ext.linear_unit", "ext", "External kinematics > Linear unit", "extkin",
               "extkin", "frame", tuple(_rail_step(k, v) for k, v in enumerate(_RAIL_VALUES)),
               _linear_unit, extra_steps=len(_RAIL_EXTRA), required=("tool_no",),
               extra_step_fn=lambda k: _rail_step(k + 3, _RAIL_EXTRA[k], True)),
    MethodSpec("ext.positioner_2axis", "ext", "External kinematics > Positioner (tilt, then turn)",
               "extkin", "extkin", "frame",
               tuple(_touch(f"Tilt axis: touch the mark on the table with E2 at {v:g} deg "
                            "(E3 at 0)", "positioner_mark", k, E2=v, E3=0.0)
                     for k, v in enumerate((-75.0, -25.0, 25.0, 75.0)))
               + tuple(_touch(f"Turn axis: touch the mark with E3 at {v:g} deg (E2 at 0)",
                              "positioner_mark", k, E2=0.0, E3=v)
                       for k, v in enumerate((-135.0, -45.0, 45.0, 135.0))),
               _positioner, required=("tool_no",)),
)
