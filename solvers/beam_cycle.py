"""The light-barrier measuring cycle as pure geometry: which moves to make, where beams trigger.

A light-barrier TCP sensor is two (or more) laser beams, usually horizontal and crossing.
The robot sweeps the tool's cylindrical shaft across the beams at two or three heights
(straight horizontal TCP moves, flange orientation held constant) and finally searches the
tip by moving along the tool axis towards one beam. This module

- plans that cycle for a *nominal* tool (:func:`plan_cycle`), and
- is the one beam-trigger simulator of the project: for the *true* tool, exactly where each
  beam switches, and where the controller records it, along a planned move while the flange
  follows any motion (:func:`trigger_events`; :func:`refine_trigger` moves a trigger onto
  an exact but costly motion; :func:`jittered_s` the trigger's jitter),

so the emulated controller (:func:`emulator.controller.run_beam_cycle`) and the recording
simulator (:func:`solvers.simulate.simulate_recording`) produce ``beam`` recordings
(``robot-recording/1``) whose poses satisfy the trigger conditions of the format exactly.
Each gives its own flange motion, the hidden physics built in: the emulator the arm as it
moves through the pass, the simulator the arm as the format's model sees the recorded
joints. The trigger latency is the format's (its item 7 in :mod:`solvers.physics`).

Trigger conditions (recording format ``robot-recording/1``, kind ``beam``)
--------------------------------------------------------------------------
The tool axis is the line ``c + lam * w`` (``c`` the TCP, ``w`` the unit axis pointing from
the flange towards the tip, both in base); a beam is the line ``p + mu * u`` (``u`` unit).
With ``n = (w x u) / |w x u|`` the signed distance of the axis from the beam is::

    sigma = (c - p) . n                                                     (B1)

- ``enter``: ``|sigma|`` falls through ``d/2`` (the shaft begins to cut the beam);
- ``leave``: ``|sigma|`` rises through ``d/2`` (it stops cutting it);

both only when the point of the axis closest to the beam lies on the shaft, i.e. between
the TCP and the flange plane (``lam`` in ``[-shaft_length, 0]``), never in the air beyond
the tip. **Approach side convention**: orient ``n`` along the motion, ``m = n sign(n . v)``
(``v`` the TCP velocity). Then ``(c - p) . m`` grows during a pass; ``enter`` happens at
``(c - p) . m = -d/2`` (axis still on the side it came from) and ``leave`` at ``+d/2`` (axis
on the far side). This is the sign the solvers in :mod:`solvers.light_barrier` use.

- ``tip``: on a tip search the TCP crosses the plane through the beam line perpendicular to
  the motion, ``(c - p) . n_v = 0`` with ``n_v = (v - (v.u) u) / |v - (v.u) u|``, and the tip
  is within ``d/2`` of the beam line sideways (``|(c - p) . (u x n_v)| <= d/2``). The search
  stops at the first such trigger.

- latency ``L``: the recorded pose is ``L`` after the trigger, so the conditions above hold
  for the TCP ``c - v L`` (``v`` the commanded TCP velocity; the tool keeps its
  orientation), and the recorded pose lies ``L |v|`` further along the motion.

Roots are bracketed on a grid along the path parameter ``s`` in [0, 1] (the time along the
pass over its duration) and refined with Brent's method to ``1e-14``, so any flange motion
(joint-interpolated, with rotation) is handled; for a straight translation the result is
exact to rounding.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation, Slerp

from solvers.errors import CalibrationError, KinematicsError
from solvers.validate import FloatArray, as_array

Edge = Literal["enter", "leave", "tip"]
PassKind = Literal["sweep", "tip"]
EDGES: tuple[str, ...] = ("enter", "leave", "tip")


@dataclass(frozen=True)
class Beam:
    """One laser beam in the robot base frame: a point on it (mm) and its unit direction."""

    id: str
    point_mm: FloatArray
    direction: FloatArray


def as_beams(beams: object, loc: str = "beams") -> dict[str, Beam]:
    """Checked beams from ``{id: (point_mm (3,), direction (3,))}`` (or ``Beam`` values).

    Directions are normalised; a zero or non-finite vector raises, naming the beam.

    Examples
    --------
    >>> b = as_beams({"bx": ([600, 0, 200], [2, 0, 0])})
    >>> b["bx"].direction.tolist()
    [1.0, 0.0, 0.0]
    """
    if not isinstance(beams, Mapping) or not beams:
        raise CalibrationError((loc,), "must map each beam id to (point_mm, direction)")
    out: dict[str, Beam] = {}
    for key, value in beams.items():
        if isinstance(value, Beam):
            point, direction = value.point_mm, value.direction
        else:
            try:
                point, direction = value  # type: ignore[misc]
            except (TypeError, ValueError):
                raise CalibrationError((loc, str(key)), "must be (point_mm, direction)") from None
        p = as_array(point, (loc, str(key), "point_mm"), (3,))
        u = as_array(direction, (loc, str(key), "direction"), (3,))
        norm = float(np.linalg.norm(u))
        if norm < 1e-9:
            raise CalibrationError((loc, str(key), "direction"), "is the zero vector")
        out[str(key)] = Beam(str(key), p, u / norm)
    return out


@dataclass(frozen=True)
class PlannedPass:
    """One straight move of the cycle: the flange goes from ``start_flange`` to ``end_flange``.

    ``kind`` is ``"sweep"`` (shaft across the beams, enter/leave triggers) or ``"tip"`` (along
    the tool axis towards ``target_beam``, stops at the tip trigger). ``nominal_tcp_mm`` is the
    commanded TCP in the flange frame; ``speed_mm_s`` its commanded speed; ``height_mm`` the
    height of the beam plane above the nominal TCP along the nominal axis (sweeps).
    """

    kind: PassKind
    start_flange: FloatArray
    end_flange: FloatArray
    speed_mm_s: float
    nominal_tcp_mm: FloatArray
    label: str = ""
    height_mm: float | None = None
    target_beam: str | None = None

    @property
    def length_mm(self) -> float:
        """Distance the commanded TCP travels."""
        a = self.start_flange[:3, :3] @ self.nominal_tcp_mm + self.start_flange[:3, 3]
        b = self.end_flange[:3, :3] @ self.nominal_tcp_mm + self.end_flange[:3, 3]
        return float(np.linalg.norm(b - a))

    @property
    def duration_s(self) -> float:
        return self.length_mm / self.speed_mm_s

    @property
    def tcp_velocity_mm_s(self) -> FloatArray:
        """The commanded TCP velocity (base, mm/s): constant along the straight move."""
        a = self.start_flange[:3, :3] @ self.nominal_tcp_mm + self.start_flange[:3, 3]
        b = self.end_flange[:3, :3] @ self.nominal_tcp_mm + self.end_flange[:3, 3]
        return (b - a) / self.duration_s

    def pose_at(self, s: float) -> FloatArray:
        """T_base_flange at path parameter ``s`` in [0, 1]: the commanded TCP moves on a
        straight line, the orientation is slerped (constant when start and end agree)."""
        R0, R1 = self.start_flange[:3, :3], self.end_flange[:3, :3]
        if np.array_equal(R0, R1):
            R = R0
        else:
            R = Slerp([0.0, 1.0], Rotation.from_matrix([R0, R1]))([s]).as_matrix()[0]
        tcp0 = R0 @ self.nominal_tcp_mm + self.start_flange[:3, 3]
        tcp1 = R1 @ self.nominal_tcp_mm + self.end_flange[:3, 3]
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = (1.0 - s) * tcp0 + s * tcp1 - R @ self.nominal_tcp_mm
        return T


class BeamTrigger(NamedTuple):
    """One switching of one beam: where on the path, which beam and edge, the flange pose
    there (T_base_flange) and the commanded TCP velocity (mm/s, base)."""

    s: float
    beam_id: str
    edge: Edge
    T_base_flange: FloatArray
    tcp_velocity_mm_s: FloatArray


def _unit(v: FloatArray) -> FloatArray:
    return v / np.linalg.norm(v)


def plan_cycle(beams: object, tool_diameter_mm: float, center_mm: object,
               heights_mm: Sequence[float], *,
               flange_rotation: object | None = None, nominal_tool: object | None = None,
               directions_deg: Sequence[float] = (0.0, 90.0), both_ways: bool = True,
               half_travel_mm: float | None = None, speed_mm_s: float = 20.0,
               tip_beam: str | None = None, tip_axis_flange: tuple[object, object] | None = None,
               tip_clearance_mm: float = 10.0) -> tuple[PlannedPass, ...]:
    """Plan the measuring cycle for a nominal tool: sweeps at each height, then a tip search.

    Sweeps: for each height ``h`` and direction ``phi`` (in the base XY plane, from base x),
    the commanded TCP moves straight and horizontally through ``center_mm + h * w0`` (``w0``
    the nominal tool axis in base), from ``-L`` to ``+L`` along ``(cos phi, sin phi, 0)``, so
    the nominal shaft crosses the beams' crossing point ``h`` mm above the tip; with
    ``both_ways`` the reverse pass follows. The flange orientation ``flange_rotation``
    (R_base_flange) is held constant throughout. A direction parallel to a beam does not
    cross it (that beam stays cut or clear the whole pass); 0 and 90 deg with beams along
    base x and y give the paper's cycle, 45 deg crosses both beams in one pass.

    Tip search: the flange moves along the estimated tool axis, which passes through
    ``center_mm``, from ``tip_clearance_mm`` above the beam to as far below; the expected
    TCP starts above the beam. The estimate is ``tip_axis_flange = (point_mm, direction)``
    (a point on the shaft axis and its direction, in flange; e.g. from
    :func:`solvers.light_barrier.shaft_axis_from_sweeps` after the sweeps) or else the
    nominal tool's axis. Aiming with the estimate keeps the tip on the beam despite offset and
    runout (a nominal aim can miss the beam sideways by the runout times the tool length).

    Parameters
    ----------
    beams : mapping id -> (point_mm (3,), direction (3,))
        The beams in base (mm).
    tool_diameter_mm : float
        Shaft diameter (sets the default travel).
    center_mm : array (3,)
        The beams' crossing point in base (mm).
    heights_mm : sequence of float
        Heights of the beam plane above the nominal TCP along the nominal axis (mm), 2 or 3
        values (at least 10 mm apart for a good runout).
    flange_rotation : array (3, 3), optional
        R_base_flange during the cycle; default flange z pointing down (Rx(180 deg)).
    nominal_tool : array (4, 4), optional
        Nominal T_flange_tcp (its z axis the nominal tool axis); default TCP at (0, 0, 100).
    directions_deg, both_ways, half_travel_mm, speed_mm_s :
        Sweep directions, reverse passes, half travel ``L`` (default ``d + 20`` mm) and speed.
    tip_beam : str, optional
        Beam of the tip search (default: the first). ``tip_clearance_mm`` its start height.

    Returns
    -------
    tuple of PlannedPass
        Sweeps (height by height, direction by direction, forward then reverse), then the tip.

    Examples
    --------
    >>> beams = {"bx": ([600, 0, 200], [1, 0, 0]), "by": ([600, 0, 200], [0, 1, 0])}
    >>> cycle = plan_cycle(beams, 6.0, [600, 0, 200], [10.0, 40.0])
    >>> [p.kind for p in cycle].count("sweep"), cycle[-1].kind
    (8, 'tip')
    """
    B = as_beams(beams)
    d = float(as_array(tool_diameter_mm, "tool_diameter_mm", ()))
    if d <= 0:
        raise CalibrationError(("tool_diameter_mm",), f"must be positive, got {d}")
    center = as_array(center_mm, "center_mm", (3,))
    heights = as_array(heights_mm, "heights_mm", (None,))
    R0 = (Rotation.from_euler("x", 180.0, degrees=True).as_matrix() if flange_rotation is None
          else as_array(flange_rotation, "flange_rotation", (3, 3)))
    tool = np.eye(4) if nominal_tool is None else as_array(nominal_tool, "nominal_tool", (4, 4))
    if nominal_tool is None:
        tool[2, 3] = 100.0
    t_nom, a_nom = tool[:3, 3], _unit(tool[:3, 2])
    w0 = R0 @ a_nom
    L = d + 20.0 if half_travel_mm is None else float(half_travel_mm)
    passes: list[PlannedPass] = []

    def flange_at(tcp: FloatArray) -> FloatArray:
        T = np.eye(4)
        T[:3, :3] = R0
        T[:3, 3] = tcp - R0 @ t_nom
        return T

    for h in heights:
        mid = center + h * w0
        for phi in directions_deg:
            v = np.array([np.cos(np.radians(phi)), np.sin(np.radians(phi)), 0.0])
            a, b = flange_at(mid - L * v), flange_at(mid + L * v)
            label = f"h={h:g} mm, {phi:g} deg"
            passes.append(PlannedPass("sweep", a, b, speed_mm_s, t_nom, label + " +", float(h)))
            if both_ways:
                passes.append(PlannedPass("sweep", b, a, speed_mm_s, t_nom, label + " -", float(h)))

    beam_id = next(iter(B)) if tip_beam is None else tip_beam
    if beam_id not in B:
        raise CalibrationError(("tip_beam",),
                               f"unknown beam '{beam_id}'; the sensor has {sorted(B)}")
    if tip_axis_flange is None:
        q_f, a_f = t_nom, a_nom
    else:
        q_f = as_array(tip_axis_flange[0], ("tip_axis_flange", 0), (3,))
        a_f = _unit(as_array(tip_axis_flange[1], ("tip_axis_flange", 1), (3,)))
    # expected TCP: the nominal TCP's foot on the estimated axis
    tcp_f = q_f + float((t_nom - q_f) @ a_f) * a_f
    w_e = R0 @ a_f
    start, end = np.eye(4), np.eye(4)
    start[:3, :3] = end[:3, :3] = R0
    start[:3, 3] = center - tip_clearance_mm * w_e - R0 @ tcp_f
    end[:3, 3] = center + tip_clearance_mm * w_e - R0 @ tcp_f
    # the commanded TCP stays the nominal one; PlannedPass interpolates it, which with a
    # constant orientation moves the flange exactly along the path set above
    passes.append(PlannedPass("tip", start, end, speed_mm_s, t_nom, f"tip search on {beam_id}",
                              None, beam_id))
    return tuple(passes)


def cross3(a: FloatArray, b: FloatArray) -> FloatArray:
    """a x b along the last axis (cheaper than np.cross for single vectors)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _sigma_many(c: FloatArray, w: FloatArray, beam: Beam) -> FloatArray:
    """(B1) for stacks of TCPs ``c`` and unit axes ``w`` (M, 3); NaN where axis // beam."""
    n = cross3(w, np.broadcast_to(beam.direction, w.shape))
    nn = np.linalg.norm(n, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        dist = np.einsum("ki,ki->k", c - beam.point_mm, n) / np.where(nn > 0, nn, 1.0)
        return np.where(nn > 1e-12, dist, np.nan)


def axis_beam_geometry(c: FloatArray, w: FloatArray, beam: Beam) -> tuple[float, float, FloatArray]:
    """Signed distance ``sigma`` (B1), the axis parameter ``lam`` of the point closest to the
    beam (from the TCP along ``w``) and ``n`` for an axis ``c + lam w`` (``w`` unit)."""
    n = cross3(w, beam.direction)
    nn = float(np.linalg.norm(n))
    if nn < 1e-12:
        return np.nan, np.nan, n
    n = n / nn
    dvec = c - beam.point_mm
    b = float(w @ beam.direction)
    lam = (b * float(beam.direction @ dvec) - float(w @ dvec)) / (1.0 - b * b)
    return float(dvec @ n), lam, n


def trigger_condition_mm(c: FloatArray, w: FloatArray, v: FloatArray, beam: Beam, edge: str,
                         radius_mm: float) -> float:
    """The format's trigger condition for one beam and edge, 0 at the trigger (mm).

    With the TCP ``c`` and the unit axis ``w`` (base) at the trigger, the commanded TCP
    velocity ``v`` and ``m = n sign(n . v)`` (``n`` of (B1), oriented along the motion)::

        enter: (c - p) . m + r        leave: (c - p) . m - r        tip: (c - p) . n_v

    with ``n_v = (v - (v.u) u) / |v - (v.u) u|``. NaN when the axis is parallel to the beam.

    Parameters
    ----------
    c, w : array (3,)
        The TCP (mm) and the unit tool axis (flange towards tip) in base, at the trigger.
    v : array (3,)
        The commanded TCP velocity (mm/s, base).
    beam : Beam
    edge : {'enter', 'leave', 'tip'}
    radius_mm : float
        Half the shaft diameter.

    Examples
    --------
    >>> b = as_beams({"by": ([600, 0, 200], [0, 1, 0])})["by"]
    >>> trigger_condition_mm(np.array([597.0, 0, 200]), np.array([0, 0, -1.0]),
    ...                      np.array([20.0, 0, 0]), b, "enter", 3.0)
    0.0
    """
    d = c - beam.point_mm
    if edge == "tip":
        nv = v - (v @ beam.direction) * beam.direction
        return float(d @ _unit(nv))
    sigma, _, n = axis_beam_geometry(c, w, beam)
    m_sign = 1.0 if float(n @ v) >= 0 else -1.0
    return float(m_sign * sigma + (radius_mm if edge == "enter" else -radius_mm))


def _shaft_mm(t: FloatArray, a: FloatArray, shaft_length_mm: float | None) -> float:
    """Length of the shaft behind the TCP: given, else from the TCP back to the flange plane
    (flange z = 0: ``t_z / a_z``); unbounded when the axis does not meet that plane."""
    if shaft_length_mm is not None:
        return float(shaft_length_mm)
    return float(t[2]) / float(a[2]) if a[2] > 1e-9 and t[2] > 0 else np.inf


def _lag_mm(path: PlannedPass, latency_ms: float) -> FloatArray:
    """``v L``: the tool at the trigger is where the recorded pose is, moved back by this."""
    if latency_ms < 0 or not np.isfinite(latency_ms):
        raise CalibrationError(("trigger_latency_ms",), f"must be >= 0, got {latency_ms}")
    return path.tcp_velocity_mm_s * float(latency_ms) / 1000.0


def trigger_events(flange_pose_at: Callable[[float], FloatArray] | None, path: PlannedPass,
                   true_tcp_mm: object, true_axis_flange: object, beams: object,
                   tool_diameter_mm: float, *, latency_ms: float = 0.0,
                   shaft_length_mm: float | None = None,
                   samples: int | None = None) -> list[BeamTrigger]:
    """Where each beam switches, and where the controller records it, while the controller
    commands ``path`` and the flange really is at ``flange_pose_at(s)``, s in [0, 1].

    This is the one beam-trigger simulator: the emulated controller's cycle
    (:func:`emulator.controller.run_beam_cycle`) and the recording simulator
    (:func:`solvers.simulate.simulate_recording`, kind ``beam``) both call it, each with its
    own flange motion (a rigid arm follows the commanded path; an imperfect one carries its
    hidden physics in ``flange_pose_at``). ``s`` is the time along the pass over its
    duration (the commanded speed is constant).

    The trigger latency ``L`` is the format's: the controller records the pose ``L`` after
    the trigger, so the tool at the trigger is the recorded one moved back by ``v L`` (``v``
    the commanded TCP velocity). The conditions (:func:`trigger_condition_mm`) hold for that
    tool, and ``s`` is the recorded position: ``L v`` further along the motion than without
    latency. Sweeps give ``enter``/``leave`` events (|sigma| of (B1) through ``d/2`` with the
    closest axis point on the shaft); tip searches give the first ``tip`` event on
    ``path.target_beam``. Roots are bracketed on a grid and refined with Brent's method.
    :func:`refine_trigger` moves one of them onto another (exact) flange motion.

    Parameters
    ----------
    flange_pose_at : callable s -> (4, 4), or None
        TRUE T_base_flange when the controller is at ``s`` of the move (None:
        ``path.pose_at``, the commanded move of a rigid arm).
    path : PlannedPass
        The commanded move (kind, duration, the commanded TCP and its velocity).
    true_tcp_mm : array (3,)
        The TRUE TCP in the flange frame (mm).
    true_axis_flange : array (3,)
        The TRUE tool axis in flange, pointing from the flange towards the tip.
    beams : mapping id -> (point_mm, direction)
    tool_diameter_mm : float
    latency_ms : float
        Trigger latency (ms, >= 0).
    shaft_length_mm : float, optional
        Length of the shaft behind the TCP (default: up to the flange plane).

    Returns
    -------
    list of BeamTrigger
        Sorted by ``s`` (the recorded position); ``T_base_flange`` is ``flange_pose_at(s)``,
        ``tcp_velocity_mm_s`` the commanded TCP velocity (base, mm/s).

    Raises
    ------
    CalibrationError
        A bad beam, tool axis or TCP (named), a negative latency, a tip search on an
        unknown beam.

    References
    ----------
    .. [1] S.-D. Lin et al., laser-sensor TCP calibration of runout and offset (Techman
       TM5-900), as in :mod:`solvers.light_barrier` (the cycle and its triggers).
    .. [2] R. P. Brent, "Algorithms for Minimization without Derivatives", Prentice-Hall,
       1973, ch. 4 (the bracketed root finding, ``scipy.optimize.brentq``).

    Examples
    --------
    >>> beams = {"bx": ([600, 0, 200], [1, 0, 0]), "by": ([600, 0, 200], [0, 1, 0])}
    >>> sweep = plan_cycle(beams, 6.0, [600, 0, 200], [10.0, 40.0])[0]  # along +x, crosses by
    >>> ev = trigger_events(None, sweep, [0, 0, 100], [0, 0, 1], beams, 6.0)
    >>> [(e.beam_id, e.edge, round(float(e.T_base_flange[0, 3]), 6)) for e in ev]
    [('by', 'enter', 597.0), ('by', 'leave', 603.0)]
    >>> late = trigger_events(None, sweep, [0, 0, 100], [0, 0, 1], beams, 6.0, latency_ms=50.0)
    >>> [round(float(e.T_base_flange[0, 3]), 6) for e in late]  # 20 mm/s x 50 ms = 1 mm later
    [598.0, 604.0]
    """
    pose_at = path.pose_at if flange_pose_at is None else flange_pose_at
    B = as_beams(beams)
    t = as_array(true_tcp_mm, "true_tcp_mm", (3,))
    a = _unit(as_array(true_axis_flange, "true_axis_flange", (3,)))
    r0 = 0.5 * float(tool_diameter_mm)
    shaft = _shaft_mm(t, a, shaft_length_mm)
    v = path.tcp_velocity_mm_s
    lag = _lag_mm(path, latency_ms)
    n_grid = samples or max(400, int(np.ceil(path.length_mm / max(r0 / 4.0, 1e-3))) + 1)
    grid = np.linspace(0.0, 1.0, n_grid)
    poses = np.array([pose_at(float(s)) for s in grid])
    c_grid = np.einsum("kij,j->ki", poses[:, :3, :3], t) + poses[:, :3, 3] - lag
    w_grid = np.einsum("kij,j->ki", poses[:, :3, :3], a)

    def tcp_axis(T: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The tool at the trigger (latency undone) when the flange is at T."""
        return T[:3, :3] @ t + T[:3, 3] - lag, T[:3, :3] @ a

    def roots(f: Callable[[float], float], values: FloatArray) -> list[tuple[float, float]]:
        """(s, slope sign) of every sign change of f on the grid, refined."""
        out = []
        for i in range(len(grid) - 1):
            f0, f1 = values[i], values[i + 1]
            if not (np.isfinite(f0) and np.isfinite(f1)):
                continue
            if f0 == 0.0 and i > 0:
                continue  # counted as the end of the previous interval
            if f0 * f1 < 0 or f1 == 0.0:
                s = (grid[i + 1] if f1 == 0.0
                     else brentq(f, grid[i], grid[i + 1], xtol=1e-14, rtol=1e-15))
                out.append((float(s), float(np.sign(f1 - f0))))
        return out

    events: list[BeamTrigger] = []
    if path.kind == "sweep":
        for beam in B.values():
            def sigma(s: float, beam: Beam = beam) -> float:
                return axis_beam_geometry(*tcp_axis(pose_at(s)), beam)[0]

            values = _sigma_many(c_grid, w_grid, beam)
            for target in (+r0, -r0):
                for s, slope in roots(lambda s, tg=target: sigma(s) - tg, values - target):
                    T = pose_at(s)
                    _, lam, _ = axis_beam_geometry(*tcp_axis(T), beam)
                    if not (-shaft - 1e-9 <= lam <= 1e-9):
                        continue  # the beam passes beyond the tip or above the shaft
                    falling = slope * np.sign(target) < 0  # |sigma| decreasing
                    edge: Edge = "enter" if falling else "leave"
                    events.append(BeamTrigger(s, beam.id, edge, T, v))
    else:
        beam = B[path.target_beam] if path.target_beam in B else None
        if beam is None:
            raise CalibrationError(("path", "target_beam"), f"unknown beam '{path.target_beam}'")

        def plane(s: float) -> float:
            return trigger_condition_mm(*tcp_axis(pose_at(s)), v, beam, "tip", r0)

        nv = _unit(v - (v @ beam.direction) * beam.direction)
        for s, slope in roots(plane, (c_grid - beam.point_mm) @ nv):
            if slope <= 0:
                continue
            T = pose_at(s)
            side = float((tcp_axis(T)[0] - beam.point_mm) @ cross3(beam.direction, nv))
            if abs(side) <= r0:
                events.append(BeamTrigger(s, beam.id, "tip", T, v))
                break
    return sorted(events, key=lambda e: e.s)


def refine_trigger(event: BeamTrigger, flange_pose_at: Callable[[float], FloatArray],
                   path: PlannedPass, true_tcp_mm: object, true_axis_flange: object,
                   beams: object, tool_diameter_mm: float, *, latency_ms: float = 0.0,
                   tol_mm: float = 1e-10, max_iter: int = 40, miss_mm: float = 0.05,
                   loc: tuple[str | int, ...] = ("beams",)) -> BeamTrigger:
    """The same switching (beam, edge) as ``event`` where the flange follows another motion.

    :func:`trigger_events` brackets every trigger on a motion that is cheap to evaluate (the
    commanded path, or the true one interpolated); this moves one of them onto the exact
    motion (e.g. the true arm at the joints the controller would record at ``s``, an IK and
    a physics model per call): secant steps on ``f(s) = trigger_condition_mm(...)`` from
    ``event.s`` and ``event.s + 0.2 mm / length`` until ``|f| < tol_mm``. The latency is
    undone as in :func:`trigger_events` (give the same ``latency_ms``).

    Returns
    -------
    BeamTrigger
        ``s`` the recorded position, ``T_base_flange = flange_pose_at(s)``.

    Raises
    ------
    KinematicsError
        ``loc``: still more than ``miss_mm`` off after ``max_iter`` steps (a joint that hardly
        moves can flip its backlash flank at the trigger, and the tool jumps across it).

    References
    ----------
    .. [1] W. H. Press et al., "Numerical Recipes", 3rd ed., Cambridge University Press,
       2007, sec. 9.2 (the secant method).

    Examples
    --------
    >>> beams = {"by": ([600, 0, 200], [0, 1, 0])}
    >>> sweep = plan_cycle(beams, 6.0, [600, 0, 200], [10.0])[0]
    >>> ev = trigger_events(None, sweep, [0, 0, 100], [0, 0, 1], beams, 6.0, latency_ms=50.0)
    >>> def ahead(s):  # the true flange stands 0.5 mm further along x than commanded
    ...     T = sweep.pose_at(s)
    ...     T[0, 3] += 0.5
    ...     return T
    >>> e = refine_trigger(ev[0], ahead, sweep, [0, 0, 100], [0, 0, 1], beams, 6.0, latency_ms=50.0)
    >>> e.edge, round(float(sweep.pose_at(e.s)[0, 3]), 6)  # commanded: 597 - 0.5 + 1 mm latency
    ('enter', 597.5)
    """
    beam = as_beams(beams)[event.beam_id]
    t = as_array(true_tcp_mm, "true_tcp_mm", (3,))
    a = _unit(as_array(true_axis_flange, "true_axis_flange", (3,)))
    r0, v, lag = 0.5 * float(tool_diameter_mm), path.tcp_velocity_mm_s, _lag_mm(path, latency_ms)
    cache: list = [None, None]  # the last (s, pose): the exact motion is costly

    def pose(s: float) -> FloatArray:
        if cache[0] != s:
            cache[:] = [s, flange_pose_at(s)]
        return cache[1]

    def f(s: float) -> float:
        T = pose(s)
        return trigger_condition_mm(T[:3, :3] @ t + T[:3, 3] - lag, T[:3, :3] @ a, v, beam,
                                    event.edge, r0)

    s_a, s_b = event.s, event.s + 0.2 / path.length_mm
    f_a, f_b = f(s_a), f(s_b)
    for _ in range(max_iter):
        if abs(f_b) < tol_mm or f_b == f_a:
            break
        s_a, s_b, f_a = s_b, s_b - f_b * (s_b - s_a) / (f_b - f_a), f_b
        f_b = f(s_b)
    if not abs(f_b) <= miss_mm:
        raise KinematicsError(loc, f"no {event.edge} trigger of beam {event.beam_id!r} found "
                              f"(misses by {abs(f_b):.3g} mm)")
    return BeamTrigger(float(s_b), event.beam_id, event.edge, pose(s_b), v)


def jittered_s(s: float, path: PlannedPass, noise_mm: float, rng: np.random.Generator) -> float:
    """Where the controller records a trigger at ``s`` whose position jitters along the
    motion by ``noise_mm`` (sigma, mm); ``s`` itself without noise (no draw from ``rng``)."""
    return s + rng.normal(0.0, noise_mm) / path.length_mm if noise_mm > 0 else s
