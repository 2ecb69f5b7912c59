"""The calibration menus: per method its steps (the pendant's prompts), its table and its solver.

``server.menus.METHODS[name]`` is a :class:`MethodSpec`. A session of that method fills ``steps`` in order
(plus up to ``extra_steps`` more for the N-point methods), then :meth:`MethodSpec.solve`
calls the one solver of the method with the taught flange poses and the inputs the server
resolved from the tables (:class:`MethodInputs`). No math here: adapters only rearrange data.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from solvers import base, fixed_tool, light_barrier, tcp, workpiece
from solvers.dh import tcp_of
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.report import CalibrationResult
from solvers.validate import FloatArray

Menu = Literal["tool", "base", "fixed_tool", "workpiece", "ext"]
Table = Literal["tool", "base", "extkin"]  # extkin: the external kinematics (EX_KIN 1..6)
Param = Literal["tool_no", "reference_tool_no", "fixed_tool_no", "known_points_mm", "pose",
                "ext_no"]


@dataclass(frozen=True)
class Step:
    """One prompt of the menu and, for the emulator wizard, how a person would get there."""

    prompt: str
    target: str | None = None  # emulated cell target (POST /robot/approach)
    tilt_deg: float = 0.0
    around_deg: float = 0.0
    spin_deg: float = 0.0
    tool_point_mm: tuple[float, float, float] | None = None
    external_axes: tuple[tuple[str, float], ...] | None = None  # ext menus: E axes to move first


@dataclass(frozen=True)
class TaughtData:
    """A filled step as the solver needs it: the flange pose and, for beam triggers, the event;
    the external axis values at the touch-up (``{"E1": deg}``) for the ext menus."""

    T_base_flange: FloatArray
    beam_id: str | None = None
    edge: str | None = None
    velocity_mm_s: tuple[float, float, float] | None = None
    external_axes: dict[str, float] | None = None


@dataclass(frozen=True)
class MethodInputs:
    """Everything besides the taught poses, resolved by the server from params and tables."""

    tcp_mm: FloatArray | None = None  # the touching tool's TCP (ABC menus: the target's own)
    reference_tcp_mm: FloatArray | None = None  # XYZ Reference: the reference tool's TCP
    fixed_tcp_mm: FloatArray | None = None  # workpiece menus: the calibrated fixed tool's TCP
    known_mm: FloatArray | None = None  # indirect menus: the points in the frame being calibrated
    pose: Pose | None = None  # numeric menus
    beams: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)
    tool_diameter_mm: float | None = None
    external: Any = None  # ext menus: server.menus.external.ExtInputs
    #: the touch scatter (mm per coordinate) the bounds assume where the points cannot estimate
    #: it: the cell's aim (server.service.external.assumed_sigma_mm); None: the solver's default
    touch_sigma_mm: float | None = None


Solve = Callable[[Sequence[TaughtData], MethodInputs], CalibrationResult]


@dataclass(frozen=True)
class MethodSpec:
    name: str
    menu: Menu
    title: str
    table: Table  # the table the result is written into
    kind: str  # the entry type it writes (tool | workpiece | base | fixed_tool)
    writes: Literal["xyz", "frame"]  # XYZ menus keep the entry's A, B, C
    steps: tuple[Step, ...]
    solve_fn: Solve
    extra_steps: int = 0
    extra_prompt: str = ""
    required: tuple[Param, ...] = ()
    steps_from_known_points: str | None = None  # indirect menus: one step per known point
    extra_step_fn: Callable[[int], Step] | None = None  # optional step k, when not a tilt cone

    def step_prompts(self, params: dict) -> list[Step]:
        """The steps of a session with these params (indirect menus: one per known point)."""
        if self.steps_from_known_points:
            pts = params.get("known_points_mm") or []
            return [Step(self.steps_from_known_points.format(k=k + 1, x=p[0], y=p[1], z=p[2]),
                         target=f"{'base' if self.menu == 'base' else 'workpiece'}_point_{k + 1}")
                    for k, p in enumerate(pts)]
        return list(self.steps)

    def extra_step(self, k: int) -> Step:
        """Optional step k (0-based beyond the required ones)."""
        if self.extra_step_fn is not None:
            return self.extra_step_fn(k)
        first = self.steps[0] if self.steps else Step(self.extra_prompt)
        return Step(self.extra_prompt.format(k=k + len(self.steps) + 1), first.target,
                    tilt_deg=25.0, around_deg=(45.0 + 90.0 * k) % 360.0,
                    spin_deg=(60.0 * k) % 360.0 - 180.0)

    def check_taught(self, points: Sequence[TaughtData | None], params: dict) -> None:
        """Raise CalibrationError(("points", k)) naming the first required step not taught."""
        steps = self.step_prompts(params)
        n = sum(p is not None for p in points)
        if n > len(steps) + self.extra_steps:
            raise CalibrationError(("points",), f"{self.name} takes at most "
                                   f"{len(steps) + self.extra_steps} points, got {n}")
        for k, step in enumerate(steps):
            if k >= len(points) or points[k] is None:
                raise CalibrationError(("points", k),
                                       f"step {k + 1} is not taught yet: {step.prompt}")

    def solve(self, points: Sequence[TaughtData | None], inputs: MethodInputs,
              params: dict) -> CalibrationResult:
        """Check every required step is taught, then call the solver."""
        self.check_taught(points, params)
        return self.solve_fn([p for p in points if p is not None], inputs)


def _poses(points: Sequence[TaughtData]) -> FloatArray:
    return np.array([p.T_base_flange for p in points])


def _need(value: object, loc: str, what: str) -> Any:
    """``value``, or CalibrationError(("params", loc)) saying what is missing."""
    if value is None:
        raise CalibrationError(("params", loc), f"required: {what}")
    return value


def _tcp(inp: MethodInputs) -> FloatArray:
    return _need(inp.tcp_mm, "tool_no", "the calibrated tool's TCP (tcp_mm)")


def _known(inp: MethodInputs) -> FloatArray:
    return _need(inp.known_mm, "known_points_mm", PARAM_HELP["known_points_mm"])


def _fixed(inp: MethodInputs) -> FloatArray:
    return _need(inp.fixed_tcp_mm, "fixed_tool_no", PARAM_HELP["fixed_tool_no"])


def _sigma(inp: MethodInputs) -> dict[str, float]:
    """``touch_sigma_mm=`` for the solvers that assume a scatter (empty: their default)."""
    return {} if inp.touch_sigma_mm is None else {"touch_sigma_mm": float(inp.touch_sigma_mm)}


def _touched(points: Sequence[TaughtData], inp: MethodInputs) -> FloatArray:
    """Positions (base) of the calibrated touching TCP at each touch-up."""
    return tcp_of(_poses(points), _tcp(inp))


# ----------------------------------------------------------------------------------- adapters

def _xyz_4point(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    return tcp.tcp_xyz_4point(_poses(points))


def _xyz_reference(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    ref = _need(inp.reference_tcp_mm, "reference_tool_no", "the calibrated reference tool")
    reference_point = tcp_of(points[0].T_base_flange, ref)  # step 0: the reference tool's touch
    return tcp.tcp_xyz_reference(reference_point, _poses(points[1:]))


def _abc_world(mode: Literal["5d", "6d"]) -> Solve:
    def solve(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
        return tcp.tool_abc_world(points[0].T_base_flange, _tcp(inp), mode)
    return solve


def _abc_2point(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    return tcp.tool_abc_2point(_tcp(inp), _poses(points), **_sigma(inp))


def _tool_numeric(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    return tcp.tool_numeric(_need(inp.pose, "pose", "the TCP as x, y, z, a, b, c"))


def _light_barrier(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    if not points:
        raise CalibrationError(("points",), "no beam triggers yet: run the measuring cycle "
                               "(POST .../run-cycle) or post a beam recording")
    velocities = None
    if all(p.velocity_mm_s is not None for p in points):
        velocities = np.array([p.velocity_mm_s for p in points], dtype=float)
    diameter = _need(inp.tool_diameter_mm, "tool_diameter_mm", "the shaft diameter")
    return light_barrier.tcp_light_barrier(_poses(points), [p.beam_id for p in points],
                                           [p.edge for p in points], inp.beams, diameter,
                                           velocities_mm_s=velocities)


def _base_3point(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    origin, x_point, xy_point = _touched(points, inp)
    return base.base_3point(origin, x_point, xy_point, **_sigma(inp))


def _base_indirect(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    return base.base_indirect(_touched(points, inp), _known(inp))


def _base_numeric(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    return base.base_numeric(_need(inp.pose, "pose", "the base as x, y, z, a, b, c"))


def _fixed_tool(mode: Literal["5d", "6d"]) -> Solve:
    def solve(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
        fn = fixed_tool.fixed_tool_5d if mode == "5d" else fixed_tool.fixed_tool_6d
        extra = _poses(points[2:]) if len(points) > 2 else None  # more touches of the fixed TCP
        return fn(points[0].T_base_flange, _tcp(inp), points[1].T_base_flange,
                  extra_touch_poses=extra)
    return solve


def _workpiece_direct(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    return workpiece.workpiece_direct(_fixed(inp), _poses(points), **_sigma(inp))


def _workpiece_indirect(points: Sequence[TaughtData], inp: MethodInputs) -> CalibrationResult:
    return workpiece.workpiece_indirect(_fixed(inp), _poses(points), _known(inp))


# ----------------------------------------------------------------------------------- registry

_TIP = "reference_tip"
# tilt, around, spin: a cone alone turns about one axis and leaves the TCP along it unobservable
_FOUR_ORIENTATIONS = ((0.0, 0.0, 0.0), (30.0, 0.0, 0.0), (30.0, 120.0, 90.0), (30.0, 240.0, -90.0))
_2PT_AXIS = (0.0, 0.0, -60.0)  # a mark on the tool axis 60 mm behind the TCP
_2PT_PLANE = (40.0, 0.0, -30.0)  # a mark on the tool's +X side, in its XZ plane
_TOUCH_FIXED = "Bring the TCP of the calibrated robot tool to the TCP of the fixed tool"
_MORE_FIXED = "Touch the fixed TCP again from another orientation ({k}, optional)"


def _spec(name: str, title: str, table: Table, kind: str, writes: Literal["xyz", "frame"],
          steps: Sequence[Step], solve_fn: Solve, **kw: Any) -> MethodSpec:
    menu = name.split(".")[0]
    return MethodSpec(name, menu, title, table, kind, writes,  # type: ignore[arg-type]
                      tuple(steps), solve_fn, **kw)


CALIBRATE_METHODS: dict[str, MethodSpec] = {m.name: m for m in (
    _spec("tool.xyz_4point", "Tool > XYZ 4-point", "tool", "tool", "xyz",
          [Step(f"Bring the TCP to the reference point from orientation {k + 1}", _TIP,
                tilt_deg=tilt, around_deg=around, spin_deg=spin)
           for k, (tilt, around, spin) in enumerate(_FOUR_ORIENTATIONS)],
          _xyz_4point, extra_steps=8,
          extra_prompt="Bring the TCP to the reference point from orientation {k} (optional)"),
    _spec("tool.xyz_reference", "Tool > XYZ Reference", "tool", "tool", "xyz",
          [Step("With the reference tool, bring its TCP to the reference point", _TIP,
                tilt_deg=10.0),
           Step("With the new tool, bring its TCP to the same reference point", _TIP,
                tilt_deg=20.0, around_deg=120.0)],
          _xyz_reference, extra_steps=4, required=("reference_tool_no",),
          extra_prompt="With the new tool, bring its TCP to the reference point again "
                       "({k}, optional)"),
    _spec("tool.abc_world_5d", "Tool > ABC World (5D)", "tool", "tool", "frame",
          [Step("Align the tool: its working direction (+Z) straight down, along world -Z",
                "world_axes")],
          _abc_world("5d")),
    _spec("tool.abc_world_6d", "Tool > ABC World (6D)", "tool", "tool", "frame",
          [Step("Align the tool with the world: +Z along world -Z, +X along world +X, "
                "+Y along world -Y", "world_axes")],
          _abc_world("6d")),
    _spec("tool.abc_2point", "Tool > ABC 2-point", "tool", "tool", "frame",
          [Step("Bring the TCP to the reference point", _TIP, tilt_deg=10.0),
           Step("Bring a point on the tool axis, behind the TCP, to the reference point", _TIP,
                tilt_deg=10.0, tool_point_mm=_2PT_AXIS),
           Step("Bring a point on the tool's +X side (in its XZ plane) to the reference point",
                _TIP, tilt_deg=10.0, tool_point_mm=_2PT_PLANE)],
          _abc_2point),
    _spec("tool.numeric", "Tool > Numeric input", "tool", "tool", "frame", [], _tool_numeric,
          required=("pose",)),
    _spec("tool.light_barrier", "Tool > Light barrier (runout and offset)", "tool", "tool", "frame",
          [], _light_barrier, extra_steps=256,
          extra_prompt="Beam trigger {k} (from the measuring cycle)"),
    _spec("base.3point", "Base > 3-point", "base", "base", "frame",
          [Step("Bring the TCP to the origin of the new base", "base_origin", tilt_deg=10.0),
           Step("Bring the TCP to a point on the positive X axis of the new base", "base_x",
                tilt_deg=10.0),
           Step("Bring the TCP to a point in the XY plane with a positive Y value", "base_xy",
                tilt_deg=10.0)],
          _base_3point, required=("tool_no",)),
    _spec("base.indirect", "Base > Indirect", "base", "base", "frame", [], _base_indirect,
          required=("tool_no", "known_points_mm"),
          steps_from_known_points="Bring the TCP to reference point {k} (base coordinates "
                                  "{x:g}, {y:g}, {z:g} mm)"),
    _spec("base.numeric", "Base > Numeric input", "base", "base", "frame", [], _base_numeric,
          required=("pose",)),
    _spec("fixed_tool.5d", "Fixed tool > External TCP 5D", "base", "fixed_tool", "frame",
          [Step(_TOUCH_FIXED, "fixed_tool", tilt_deg=10.0),
           Step("Align the flange with the fixed tool: flange +Z pointing into the fixed tool, "
                "i.e. flange -Z along the fixed tool's +Z (its working direction, out of its tip)",
                "fixed_tool_align")],
          _fixed_tool("5d"), extra_steps=4, extra_prompt=_MORE_FIXED, required=("tool_no",)),
    _spec("fixed_tool.6d", "Fixed tool > External TCP 6D", "base", "fixed_tool", "frame",
          [Step(_TOUCH_FIXED, "fixed_tool", tilt_deg=10.0),
           Step("Align the flange with the fixed tool: flange +Z pointing into the fixed tool "
                "(flange -Z along its +Z, its working direction out of its tip), flange +X along "
                "its +X, flange +Y along its -Y", "fixed_tool_align")],
          _fixed_tool("6d"), extra_steps=4, extra_prompt=_MORE_FIXED, required=("tool_no",)),
    _spec("workpiece.direct", "Workpiece > Direct", "tool", "workpiece", "frame",
          [Step("Bring the origin of the workpiece to the fixed TCP", "workpiece_origin"),
           Step("Bring a point on the workpiece's positive X axis to the fixed TCP", "workpiece_x"),
           Step("Bring a point in the workpiece's XY plane with a positive Y value to the fixed "
                "TCP", "workpiece_xy")],
          _workpiece_direct, required=("fixed_tool_no",)),
    _spec("workpiece.indirect", "Workpiece > Indirect", "tool", "workpiece", "frame", [],
          _workpiece_indirect, required=("fixed_tool_no", "known_points_mm"),
          steps_from_known_points="Bring workpiece point {k} (workpiece coordinates {x:g}, {y:g}, "
                                  "{z:g} mm) to the fixed TCP"),
)}

PARAM_HELP: dict[str, str] = {
    "tool_no": "the calibrated robot tool (tool table number) that touches the points",
    "reference_tool_no": "the calibrated reference tool (tool table number)",
    "fixed_tool_no": "the calibrated fixed tool (base table number, type fixed_tool)",
    "known_points_mm": "the points' coordinates in the frame being calibrated (mm), at least 4",
    "pose": "the frame as x, y, z (mm), a, b, c (deg)",
    "ext_no": "the external kinematic (EX_KIN 1..6) the base rides on",
}
