"""Simulated recordings: what a real robot with hidden imperfections would log.

:func:`simulate_recording` returns a ``robot-recording/1`` document (a dict) for any arm of
the library (or any :class:`~solvers.dh.RobotModel`), with the effects of
:class:`solvers.physics.Imperfections` built in. The controller moves on its nominal model;
the real robot is :func:`solvers.physics.true_tcp_poses`; the file records what the
controller shows. Coupled arms (FANUC J2/J3) are written decoupled, as the format requires.

- ``tracker``: random joint configurations spread over the joint limits, the TCP in a
  reachable box (radius 0.25..0.95 reach, above the robot's foot) and away from
  singularities (condition number of the reach-scaled Jacobian < 25);
  ``measured = T_instrument_base @ true TCP + noise`` (``noise_mm`` per axis).
- ``touch``: the operator brings the real TCP onto one point from orientations tilted
  20..50 deg about it: inverse kinematics on the nominal model, then Newton steps on the
  true pose error until the real TCP is on the aimed point within 1e-9 mm; the aimed point
  is the touch point plus the operator's error (``noise_mm`` per axis).
- ``beam``: the tool, pointing down, passes through crossed beams on straight lines at
  constant orientation (both directions unless ``both_directions=False``), the beams cutting
  the shaft at 2 or 3 heights above the TCP, at 4 turns about the tool axis, plus a tip
  descent onto the crossing. The controller moves the nominal TCP along the commanded line;
  the beams are switched by the one trigger simulator, :mod:`solvers.beam_cycle` (the
  emulated controller's cycle uses it too): :func:`~solvers.beam_cycle.trigger_events`
  finds each trigger on the commanded line, :func:`~solvers.beam_cycle.refine_trigger`
  moves it onto the real robot. The flange pose it is given is that of the real robot
  (:func:`solvers.physics.true_tcp_poses`) if the joints at ``s`` were the next recorded
  sample: the backlash flank from the recorded sequence, the thermal drift at the
  scheduled time, so the recording meets the trigger conditions exactly under the
  analysis's own model. With ``trigger_latency_ms`` the conditions hold for the recorded
  pose moved back by ``latency * v`` (the format's definition): the recorded pose lies
  ``latency * speed`` later along the motion. The trigger position then jitters along the
  motion by ``noise_mm``; ``tcp_velocity_mm_s`` is the commanded velocity. Trigger
  conditions (as the format defines them, :func:`solvers.beam_cycle.trigger_condition_mm`):
  ``enter`` / ``leave`` when the signed distance between the tool axis and the beam line
  along their common normal (pointed along the motion) is ``-r`` / ``+r`` (r = half the
  shaft diameter); ``tip`` when the TCP is on the plane through the beam line perpendicular
  to the motion (normal ``v - (v.u) u``).

Sample times: tracker 10 s apart, touch 20 s apart, beam the scheduled trigger times of
passes at ``speed_mm_s`` (nominal geometry, so the thermal drift's time base is known in
advance; the true trigger differs by well under 0.1 s).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.beam_cycle import (BeamTrigger, PlannedPass, jittered_s, refine_trigger,
                                trigger_events)
from solvers.dh import RobotModel, forward_kinematics, geometric_jacobian, link_matrices, pose_error
from solvers.errors import CalibrationError, KinematicsError
from solvers.frames import Pose, apply, invert
from solvers.physics import Imperfections, true_tcp_poses
from solvers.recording import RecordingData, motion_signs, recording_document
from solvers.robots import ROBOTS
from solvers.validate import FloatArray, as_array

DEFAULT_TOOL = Pose(z=150.0)
DEFAULT_INSTRUMENT = Pose(2500.0, 800.0, -400.0, 160.0, 3.0, -2.0)
DEFAULT_SAMPLES = {"touch": 12, "tracker": 60, "beam": 72}
TRACKER_DT_S, TOUCH_DT_S, PASS_GAP_S = 10.0, 20.0, 2.0
MAX_COND = 25.0
_W = np.array([1.0, 1.0, 1.0, 1000.0, 1000.0, 1000.0])  # 1 rad ~ 1000 mm in the IK


# ---------------------------------------------------------------- robot, IK, history


@dataclass
class _Arm:
    """The arm as written to the file (decoupled) and the controller's limits."""

    model: RobotModel           # coupling=None; q here is the decoupled q_dh
    C: FloatArray               # q_dh = C q_controller
    limits: FloatArray          # controller limits (n, 2)
    reach_mm: float
    tool: FloatArray            # T_flange_tcp

    def controller(self, q_dh: FloatArray) -> FloatArray:
        return np.linalg.solve(self.C, np.asarray(q_dh, dtype=float).T).T

    def within_limits(self, q_dh: FloatArray, margin_deg: float = 0.5) -> bool:
        q = self.controller(q_dh)
        lo, hi = self.limits[:, 0] + margin_deg, self.limits[:, 1] - margin_deg
        return bool(np.all(q >= lo) and np.all(q <= hi))

    def fk(self, q_dh: FloatArray) -> FloatArray:
        q = np.asarray(q_dh, dtype=float)
        if q.ndim > 1:
            return forward_kinematics(self.model, q, self.tool)
        return self._frames(q)[-1] @ self._flange_tool

    def jac(self, q_dh: FloatArray) -> FloatArray:
        q = np.asarray(q_dh, dtype=float)
        if q.ndim > 1:
            return geometric_jacobian(self.model, q, self.tool)
        F = self._frames(q)
        c = (F[-1] @ self._flange_tool)[:3, 3]
        sel = F[:-1] if self.model.dh_convention == "standard" else F[1:]
        z = sel[:, :3, 2] * self._p["direction"][:, None]
        return np.vstack([np.cross(z, c - sel[:, :3, 3]).T, z.T])

    def _frames(self, q: FloatArray) -> FloatArray:
        """Frames 0..n of one configuration (the same as ``solvers.dh.joint_frames``,
        with the mounting matrices cached: the simulator evaluates it thousands of times)."""
        p = self._p
        theta = np.radians(p["direction"] * q + p["offset_deg"])
        links = link_matrices(self.model.dh_convention, theta, p["d_mm"], p["a_mm"],
                              np.radians(p["alpha_deg"]))
        F = np.empty((len(q) + 1, 4, 4))
        F[0] = self._base
        for i in range(len(q)):
            F[i + 1] = F[i] @ links[i]
        return F

    @cached_property
    def _p(self) -> dict[str, FloatArray]:
        return self.model.params()

    @cached_property
    def _base(self) -> FloatArray:
        return self.model.base_pose.as_matrix()

    @cached_property
    def _flange_tool(self) -> FloatArray:
        return self.model.flange_pose.as_matrix() @ self.tool


def decoupled_arm(robot: RobotModel | str, tool: FloatArray) -> _Arm:
    """The arm as a recording holds it: J2/J3 coupling folded into the DH angles, so that
    ``q`` is the decoupled joint vector; ``fk``/``jac`` of the TCP with ``tool``."""
    if isinstance(robot, str):
        if robot not in ROBOTS:
            raise CalibrationError(("robot",), f"unknown robot {robot!r}; the library has "
                                   f"{', '.join(sorted(ROBOTS))}")
        robot = ROBOTS[robot]
    n = robot.dof
    C = robot.coupling_matrix()
    joints = list(robot.joints)
    for i in range(n):
        if not np.allclose(C[i], np.eye(n)[i]):
            joints[i] = replace(joints[i], q_min_deg=-360.0, q_max_deg=360.0)
    model = replace(robot, coupling=None, joints=tuple(joints))
    p = robot.params()
    reach = robot.reach_mm or float(np.abs(p["a_mm"]).sum() + np.abs(p["d_mm"][1:]).sum())
    return _Arm(model, C, robot.limits_deg(), reach, tool)


def solve_pose_newton(fk, jac, goal: FloatArray, q0: FloatArray, tol_mm: float = 1e-9,
            max_iter: int = 60) -> FloatArray:
    """Joint values with ``fk(q) == goal`` (pose), Gauss-Newton on the weighted pose error.

    ``fk`` may be the true (imperfect) robot while ``jac`` is the nominal one: that is how a
    touch-up is found on a robot whose model is off (used by the simulator and the emulator).
    """
    q = np.array(q0, dtype=float)
    for _ in range(max_iter):
        e = pose_error(fk(q), goal)
        if np.linalg.norm(e[:3]) < tol_mm and np.linalg.norm(e[3:]) < tol_mm * 1e-3:
            return q
        dq = np.degrees(np.linalg.lstsq(_W[:, None] * jac(q), _W * e, rcond=None)[0])
        big = np.abs(dq).max()
        q = q + (dq * 10.0 / big if big > 10.0 else dq)
    e = pose_error(fk(q), goal)
    raise KinematicsError(("target",), f"not reachable: Newton misses by "
                          f"{np.linalg.norm(e[:3]):.3g} mm")


class _History:
    """The real robot along a recording, sample by sample (backlash needs the previous one)."""

    def __init__(self, arm: _Arm, imp: Imperfections, start: FloatArray,
                 payload: tuple[float, FloatArray], span: tuple[float, float]):
        self.arm, self.imp, self.payload, self.span = arm, imp, payload, span
        self.q_prev = np.array(start, dtype=float)
        self.sign_prev, self.t_prev = np.zeros(len(start)), span[0]
        self.first = True
        self.start = np.array(start, dtype=float)
        self.recorded: list[FloatArray] = []

    def _args(self, q: FloatArray, t: float):
        if self.first:
            return q[None, :], np.array([t]), self.start
        # start = q_prev - sign_prev: motion_signs then gives q_prev its known sign
        return (np.stack([self.q_prev, q]), np.array([self.t_prev, t]),
                self.q_prev - self.sign_prev)

    def true_T(self, q: FloatArray, t: float) -> FloatArray:
        """True T_base_tcp (4, 4) if the next recorded sample is ``q`` at ``t``."""
        joints, times, start = self._args(q, t)
        return true_tcp_poses(self.arm.model, joints, times, self.imp, self.arm.tool, start,
                              self.payload[0], self.payload[1], time_span_s=self.span)[-1]

    def commit(self, q: FloatArray, t: float) -> None:
        joints, _, start = self._args(q, t)
        self.sign_prev = motion_signs(joints, start)[-1]
        self.q_prev, self.t_prev, self.first = np.array(q, dtype=float), t, False
        self.recorded.append(self.q_prev)


def _ready(arm: _Arm, rng: np.random.Generator, point_mm: FloatArray | None = None) -> FloatArray:
    """A well-conditioned configuration with the tool pointing straight down (-z of base),
    at radius 0.35..0.65 reach (or with the TCP on ``point_mm``)."""
    R = arm.reach_mm
    lo = np.maximum(arm.limits[:, 0], -180.0) * 0.9
    hi = np.minimum(arm.limits[:, 1], 180.0) * 0.9
    foot_z = arm.model.base_pose.z
    for _ in range(20):
        Q = rng.uniform(lo, hi, (3000, arm.model.dof))
        Qd = Q @ arm.C.T
        T = arm.fk(Qd)
        p = T[:, :3, 3]
        r = np.hypot(p[:, 0], p[:, 1])
        down = -T[:, 2, 2]
        ok = (down > 0.8) & (r > 0.35 * R) & (r < 0.65 * R) & (p[:, 2] - foot_z > 0.05 * R) \
            & (p[:, 2] - foot_z < 0.7 * R)
        for k in np.flatnonzero(ok)[np.argsort(-down[ok])][:20]:
            Rn = Rotation.align_vectors([[0, 0, -1]], [T[k, :3, 2]])[0]
            goal = np.eye(4)
            goal[:3, :3] = (Rn * Rotation.from_matrix(T[k, :3, :3])).as_matrix()
            goal[:3, 3] = np.round(p[k], 0) if point_mm is None else point_mm
            try:
                q = solve_pose_newton(arm.fk, arm.jac, goal, Qd[k])
            except KinematicsError:
                continue
            if arm.within_limits(q, 5.0) and _cond(arm, q[None])[0] < MAX_COND:
                return q
    raise KinematicsError(("robot",), f"found no well-conditioned pose of {arm.model.name} with "
                          "the tool pointing down" + ("" if point_mm is None else
                                                      f" at {np.round(point_mm, 1).tolist()} mm"))


def _cond(arm: _Arm, Qd: FloatArray) -> FloatArray:
    J = arm.jac(Qd).copy()
    J[..., :3, :] /= arm.reach_mm
    s = np.linalg.svd(J, compute_uv=False)
    return s[..., 0] / np.maximum(s[..., -1], 1e-12)


# ---------------------------------------------------------------- the three kinds


def _tracker(arm: _Arm, imp: Imperfections, n: int, rng: np.random.Generator,
             payload: tuple[float, FloatArray], instrument: FloatArray, dt_s: float = TRACKER_DT_S):
    R = arm.reach_mm
    lo = np.maximum(arm.limits[:, 0], -180.0) * 0.95
    hi = np.minimum(arm.limits[:, 1], 180.0) * 0.95
    foot_z = arm.model.base_pose.z
    chosen: list[FloatArray] = []
    for _ in range(200):
        Qd = rng.uniform(lo, hi, (500, arm.model.dof)) @ arm.C.T
        p = arm.fk(Qd)[:, :3, 3]
        r = np.hypot(p[:, 0], p[:, 1])
        dist = np.linalg.norm(p - arm.model.base_pose.as_array()[:3], axis=1)
        ok = (r > 0.25 * R) & (dist < 0.95 * R) & (p[:, 2] - foot_z > 0.0)
        ok[ok] = _cond(arm, Qd[ok]) < MAX_COND
        chosen.extend(Qd[ok])
        if len(chosen) >= n + 1:
            break
    if len(chosen) < n + 1:
        raise KinematicsError(("robot",), f"found only {len(chosen)} well-conditioned poses of "
                              f"{arm.model.name}")
    start, q = chosen[0], np.array(chosen[1:n + 1])
    t = dt_s * np.arange(n)
    tcp = true_tcp_poses(arm.model, q, t, imp, arm.tool, start, payload[0], payload[1])[:, :3, 3]
    measured = apply(instrument, tcp) + rng.normal(0.0, imp.noise_mm, (n, 3)) * (imp.noise_mm > 0)
    return dict(t_s=t, joints_deg=q, start_joints_deg=start, measured_mm=measured)


def _touch(arm: _Arm, imp: Imperfections, n: int, rng: np.random.Generator,
           payload: tuple[float, FloatArray], point_mm: FloatArray | None):
    q0 = _ready(arm, rng, point_mm)
    T0 = arm.fk(q0)
    point = T0[:3, 3].copy()
    t = TOUCH_DT_S * np.arange(n)
    hist = _History(arm, imp, q0, payload, (float(t[0]), float(t[-1])))
    golden = np.pi * (3.0 - np.sqrt(5.0))
    k = tries = 0
    while k < n:
        tries += 1
        if tries > 40 * n:
            raise KinematicsError(("touch_point_mm",), f"could not touch "
                                  f"{np.round(point, 1).tolist()} from {n} orientations "
                                  "tilted 20..50 deg")
        tilt = np.radians(rng.uniform(20.0, 50.0))
        az = golden * tries + rng.uniform(-0.3, 0.3)
        axis = np.array([-np.sin(az), np.cos(az), 0.0])
        rot = Rotation.from_rotvec(axis * tilt) * Rotation.from_matrix(T0[:3, :3]) \
            * Rotation.from_euler("z", rng.uniform(-60.0, 60.0), degrees=True)
        goal = np.eye(4)
        goal[:3, :3] = rot.as_matrix()
        goal[:3, 3] = point + (rng.normal(0.0, imp.noise_mm, 3) if imp.noise_mm > 0 else 0.0)
        try:
            q = solve_pose_newton(arm.fk, arm.jac, goal, q0)
            q = solve_pose_newton(lambda x: hist.true_T(x, float(t[k])), arm.jac, goal, q, tol_mm=1e-9)
        except KinematicsError:
            continue
        if not arm.within_limits(q) or _cond(arm, q[None])[0] > MAX_COND:
            continue
        hist.commit(q, float(t[k]))
        k += 1
    return dict(t_s=t, joints_deg=np.array(hist.recorded), start_joints_deg=q0)


@dataclass(frozen=True)
class _Event:
    """One scheduled trigger: its pass, where the commanded path of the (true) tool switches
    the beam, latency included (:func:`solvers.beam_cycle.trigger_events`), and when."""

    pass_no: int              # the pass (a descent triggers every beam at its point at once)
    path: PlannedPass         # commanded: the nominal TCP on a straight line, orientation held
    trigger: BeamTrigger      # on the commanded path; refined later on the true robot
    t_s: float                # scheduled time of the nominal trigger


def _tcp_pass(kind: str, rot: FloatArray, start_mm: FloatArray, end_mm: FloatArray,
              tool: FloatArray, speed: float, target: str | None = None) -> PlannedPass:
    """The move of the commanded TCP from ``start_mm`` to ``end_mm`` with the tool
    orientation ``rot`` (R_base_tcp) held, as the flange path of the tool ``tool``."""
    R = rot @ tool[:3, :3].T
    ends = []
    for p in (start_mm, end_mm):
        F = np.eye(4)
        F[:3, :3], F[:3, 3] = R, p - R @ tool[:3, 3]
        ends.append(F)
    return PlannedPass(kind, ends[0], ends[1], speed, tool[:3, 3],  # type: ignore[arg-type]
                       target_beam=target)


def _beam_schedule(beams: dict[str, tuple[FloatArray, FloatArray]], r: float, R0: FloatArray,
                   heights: Sequence[float], both: bool, speed: float, n: int,
                   tool: FloatArray, latency_ms: float) -> list[_Event]:
    """The passes (4 turns about the tool axis; at each height both ways; a descent onto each
    beam point) and their nominal triggers, cut at ``n``."""
    events: list[_Event] = []
    t = 0.0
    ids = list(beams)
    centre = np.mean([beams[b][0] for b in ids], axis=0)
    spins = (0.0, 90.0, 180.0, 270.0)
    cycle = passes = 0

    def schedule(pass_no: int, path: PlannedPass, t0: float, crossed: dict) -> None:
        """Append the triggers of ``path`` (started at ``t0``, crossing ``crossed``), stamped
        at the nominal trigger (the recorded pose comes the latency later)."""
        for e in trigger_events(None, path, tool[:3, 3], tool[:3, 2], crossed, 2.0 * r,
                                latency_ms=latency_ms):
            t_s = t0 + e.s * path.duration_s - latency_ms / 1000.0
            events.append(_Event(pass_no, path, e, t_s))

    while len(events) < n:
        spin = Rotation.from_euler("z", spins[cycle % 4], degrees=True)
        rot = (Rotation.from_matrix(R0) * spin).as_matrix()
        w = rot[:, 2]
        u1 = beams[ids[0]][1]
        # not the bisector: crossed beams must not trigger at the same instant (the recorded
        # joints would not move between the two samples, and backlash needs a motion sign)
        v = (u1 - 0.6 * beams[ids[1]][1]) if len(ids) > 1 else np.cross(w, u1)
        v = v - (v @ w) * w
        v = v / np.linalg.norm(v)
        crossed = {}  # beams a pass cuts cleanly: not along the tool, crossed at >= 11.5 deg
        for b in ids:
            nrm = np.cross(w, beams[b][1])
            if np.linalg.norm(nrm) >= 0.3 and abs(nrm @ v) / np.linalg.norm(nrm) >= 0.2:
                crossed[b] = beams[b]
        half = r + 25.0
        for h in heights:
            for vd in ((v, -v) if both else (v,)):
                path = _tcp_pass("sweep", rot, centre + h * w - half * vd,
                                 centre + h * w + half * vd, tool, speed)
                if crossed:
                    schedule(passes, path, t, crossed)
                t += path.duration_s + PASS_GAP_S
                passes += 1
        # tip descent along the tool axis onto each distinct beam point
        for point in np.unique(np.array([beams[b][0] for b in ids]), axis=0):
            path = _tcp_pass("tip", rot, point - 20.0 * w, point + 10.0 * w, tool, speed)
            for b in ids:
                if np.allclose(beams[b][0], point) and abs(beams[b][1] @ w) < 0.2:
                    schedule(passes, replace(path, target_beam=b), t, beams)
            t += path.duration_s + PASS_GAP_S
            passes += 1
        cycle += 1
        if cycle > 4 * n:
            raise CalibrationError(("sensor",), "no pass of the tool triggers these beams")
    return events[:n]


def _seed_turn(arm: _Arm, goal: FloatArray, q_ready: FloatArray) -> FloatArray:
    """IK of a tool pose turned about the tool axis from the ready pose: try the last joint
    turned both ways and keep the solution inside the limits nearest to the ready pose."""
    angle = np.degrees(Rotation.from_matrix(arm.fk(q_ready)[:3, :3].T @ goal[:3, :3]).magnitude())
    best = None
    for turn in (0.0, angle, -angle, 360.0 - angle, angle - 360.0):
        seed = q_ready.copy()
        seed[-1] += turn
        try:
            q = solve_pose_newton(arm.fk, arm.jac, goal, seed)
        except KinematicsError:
            continue
        if not arm.within_limits(q, 2.0):
            continue
        if best is None or np.abs(q - q_ready).sum() < np.abs(best - q_ready).sum():
            best = q
    if best is None:
        raise KinematicsError(("sensor",), "the tool cannot turn about its axis at the beams "
                              "inside the joint limits")
    return best


def _beam(arm: _Arm, imp: Imperfections, n: int, rng: np.random.Generator,
          payload: tuple[float, FloatArray], sensor: Mapping | None, heights, both: bool,
          speed: float):
    q_ready = _ready(arm, rng)
    T0 = arm.fk(q_ready)
    if sensor is None:
        centre = T0[:3, 3] + [0.0, 0.0, 15.0]
        sensor = {"beams": [
            {"id": "bx", "point_mm": centre.tolist(), "direction": [1.0, 0.0, 0.0]},
            {"id": "by", "point_mm": centre.tolist(), "direction": [0.0, 1.0, 0.0]}],
            "tool_diameter_mm": 6.0}
    beams = {}
    for i, b in enumerate(sensor["beams"]):
        d = as_array(b["direction"], ("sensor", "beams", i, "direction"), (3,))
        beams[str(b["id"])] = (as_array(b["point_mm"], ("sensor", "beams", i, "point_mm"), (3,)),
                               d / np.linalg.norm(d))
    diameter = float(sensor["tool_diameter_mm"])
    r = diameter / 2.0
    if isinstance(heights, (int, np.integer)):
        if heights not in (2, 3):
            raise CalibrationError(("heights",), f"must be 2 or 3 heights (or a list in mm), "
                                   f"got {heights}")
        heights = (5.0, 15.0, 25.0)[:heights]
    latency_ms = imp.trigger_latency_ms
    events = _beam_schedule(beams, r, T0[:3, :3], [float(h) for h in heights], both, speed, n,
                            arm.tool, latency_ms)
    hist = _History(arm, imp, q_ready, payload, (events[0].t_s, events[-1].t_s))
    t_tool, a_tool, tool_flange = arm.tool[:3, 3], arm.tool[:3, 2], invert(arm.tool)
    cache: dict = {}

    def q_cmd(path: PlannedPass, s: float) -> FloatArray:
        goal = path.pose_at(s) @ arm.tool
        if cache.get("rotation") is None or not np.array_equal(cache["rotation"], goal[:3, :3]):
            cache["rotation"] = goal[:3, :3]  # a new turn about the tool axis: reseed
            cache["q"] = _seed_turn(arm, goal, q_ready)
        q = solve_pose_newton(arm.fk, arm.jac, goal, cache["q"])
        cache["q"] = q
        return q

    rows: list[BeamTrigger] = []
    previous: _Event | None = None
    for e in events:
        if (previous is not None and imp.noise_mm == 0 and e.trigger.edge == previous.trigger.edge
                == "tip" and previous.pass_no == e.pass_no):
            # the same descent triggers a second beam at the same instant: the same joints
            hist.commit(hist.q_prev, e.t_s)
            rows.append(e.trigger)
            continue
        previous = e

        def true_flange(s: float, e: _Event = e) -> FloatArray:
            """The true flange if the joints at s were recorded next (backlash flank from
            the recorded sequence, thermal drift at the scheduled time)."""
            return hist.true_T(q_cmd(e.path, s), e.t_s) @ tool_flange

        # the one trigger simulator: the nominal trigger moved onto the true robot, where
        # the conditions hold with the latency undone along the commanded velocity; a joint
        # that hardly moves along the pass can flip its backlash flank at the trigger, and the
        # real tool then jumps across the condition by a fraction of the lost motion
        trig = refine_trigger(e.trigger, true_flange, e.path, t_tool, a_tool, beams, diameter,
                              latency_ms=latency_ms, loc=("sensor", "beams"))
        q = q_cmd(e.path, jittered_s(trig.s, e.path, imp.noise_mm, rng))
        if not arm.within_limits(q, 0.0):
            raise KinematicsError(("sensor",), f"a pass through beam {e.trigger.beam_id!r} "
                                  "leaves the joint limits")
        hist.commit(q, e.t_s)
        rows.append(trig)
    return dict(t_s=np.array([e.t_s for e in events]), joints_deg=np.array(hist.recorded),
                start_joints_deg=q_ready, beams=beams, tool_diameter_mm=diameter,
                beam_ids=np.array([e.beam_id for e in rows], dtype=str),
                edges=np.array([e.edge for e in rows], dtype=str),
                tcp_velocity_mm_s=np.array([e.tcp_velocity_mm_s for e in rows]))


# ---------------------------------------------------------------- public


def _tool_matrix(tool_mm: object) -> FloatArray:
    if isinstance(tool_mm, Pose):
        return tool_mm.as_matrix()
    v = np.asarray(tool_mm, dtype=float)
    if v.shape == (4, 4):
        return as_array(v, "tool_mm", (4, 4))
    if v.shape == (3,):
        return Pose(*as_array(v, "tool_mm", (3,))).as_matrix()
    return Pose.from_array(as_array(v, "tool_mm", (6,))).as_matrix()


def _payload(payload: object) -> tuple[float, FloatArray]:
    if payload is None:
        return 0.0, np.zeros(3)
    if isinstance(payload, Mapping):
        mass, com = payload["mass_kg"], payload.get("com_mm", (0.0, 0.0, 0.0))
    else:
        mass, com = payload  # type: ignore[misc]
    mass = float(as_array(mass, ("payload", "mass_kg"), ()))
    if mass < 0:
        raise CalibrationError(("payload", "mass_kg"), "must be >= 0")
    return mass, as_array(com, ("payload", "com_mm"), (3,))


def simulate_recording(kind: str, robot: RobotModel | str,
                       imperfections: Imperfections | None = None,
                       n_samples: int | None = None, seed: int = 0, *,
                       tool_mm: object = DEFAULT_TOOL, payload: object = None,
                       instrument_pose: Pose | FloatArray = DEFAULT_INSTRUMENT,
                       touch_point_mm: object = None, sensor: Mapping | None = None,
                       heights: int | Sequence[float] = 2, both_directions: bool = True,
                       speed_mm_s: float = 10.0, recorded_at: str | None = None,
                       sample_interval_s: float | None = None) -> dict:
    """A ``robot-recording/1`` document of a simulated real robot (see the module docstring).

    Parameters
    ----------
    kind : {'touch', 'tracker', 'beam'}
    robot : RobotModel or str
        The nominal model (what the controller knows), or a key of ``solvers.robots.ROBOTS``.
    imperfections : Imperfections, optional
        The hidden physics; default none (a rigid robot, no noise).
    n_samples : int, optional
        Default touch 12, tracker 60, beam 72 (4 turns x 2 heights x 2 directions x 4
        triggers + 2 tips per turn); beam schedules are cut at ``n_samples``.
    seed : int
        Everything random (poses, orientations, noise) comes from this seed.
    tool_mm : Pose, (3,), (6,) or (4, 4)
        The nominal tool T_flange_tcp (written to the file, and the real tool).
    payload : (mass_kg, com_mm) or {"mass_kg", "com_mm"}, optional
    instrument_pose : Pose or (4, 4)
        tracker: T_instrument_base.
    touch_point_mm : (3,), optional
        touch: the fixed point in base (default: below a comfortable tool-down pose).
    sensor : dict, optional
        beam: the format's sensor block (``beams`` with ``id``, ``point_mm``, ``direction``,
        and ``tool_diameter_mm``); default two crossed beams along x and y of base, 6 mm tool.
    heights : 2, 3 or a list of mm
        beam: heights above the TCP at which the beams cut the shaft (5, 15 (, 25) mm).
    both_directions : bool
        beam: pass through the beams both ways.
    speed_mm_s : float
        beam: commanded TCP speed of the passes.
    sample_interval_s : float, optional
        tracker: seconds between samples (default 10 s; long warm-up recordings).

    Returns
    -------
    dict
        The document; ``server.formats.recording.parse_recording`` accepts it.

    Raises
    ------
    CalibrationError, KinematicsError
        Bad arguments, or no reachable poses for the requested setup.

    Examples
    --------
    >>> doc = simulate_recording("tracker", "ur10", Imperfections(noise_mm=0.01), 8, seed=1)
    >>> doc["format"], len(doc["samples"]), len(doc["samples"][0]["measured_mm"])
    ('robot-recording/1', 8, 3)
    """
    if kind not in DEFAULT_SAMPLES:
        raise CalibrationError(("kind",), f"must be 'touch', 'tracker' or 'beam', got {kind!r}")
    imp = imperfections or Imperfections()
    n = DEFAULT_SAMPLES[kind] if n_samples is None else int(n_samples)
    if n < 1:
        raise CalibrationError(("n_samples",), f"must be >= 1, got {n}")
    tool = _tool_matrix(tool_mm)
    arm = decoupled_arm(robot, tool)
    imp.check(arm.model.dof)
    pay = _payload(payload)
    rng = np.random.default_rng(seed)
    if kind == "tracker":
        T_inst = instrument_pose.as_matrix() if isinstance(instrument_pose, Pose) \
            else as_array(instrument_pose, "instrument_pose", (4, 4))
        data = _tracker(arm, imp, n, rng, pay, T_inst, float(sample_interval_s or TRACKER_DT_S))
    elif kind == "touch":
        point = None if touch_point_mm is None else as_array(touch_point_mm, "touch_point_mm", (3,))
        data = _touch(arm, imp, n, rng, pay, point)
    else:
        data = _beam(arm, imp, n, rng, pay, sensor, heights, both_directions, float(speed_mm_s))
    rec = RecordingData(kind=kind, robot=arm.model, tool=tool,  # type: ignore[arg-type]
                        payload_mass_kg=pay[0], payload_com_mm=pay[1], recorded_at=recorded_at,
                        **data)
    return recording_document(rec)


def constant_orientation_path(robot: RobotModel | str, n: int, *, tool_mm: object = DEFAULT_TOOL,
                              seed: int = 0, size_mm: Sequence[float] = (300.0, 200.0, 100.0),
                              repeats: int = 1, tilt_deg: float = 0.0) -> FloatArray:
    """Joint values (n, dof) of a machining-like path with the tool orientation constant.

    The TCP sweeps a serpentine raster through a box (``size_mm``) in front of the robot with
    the tool pointing straight down (tilted by ``tilt_deg`` about base x); each point is
    solved from its neighbour (damped least squares, ``plan.solve_ik``). ``repeats`` > 1
    visits each raster point that many times in a row (repeated neighbours). What a laser
    tracker sees on such a path cannot tell the tool point on the flange from the
    instrument's position (``analysis.identify``).
    """
    from solvers.analysis.plan import reached, solve_ik

    model = ROBOTS[robot] if isinstance(robot, str) else robot
    tool = _tool_matrix(tool_mm)
    R = model.reach_mm or 1000.0
    rng = np.random.default_rng(seed)
    n_points = -(-int(n) // max(int(repeats), 1))
    nx = max(int(np.ceil(np.sqrt(n_points * size_mm[0] / max(size_mm[1], 1e-9)))), 1)
    ny = -(-n_points // nx)
    xs, ys = np.linspace(-0.5, 0.5, nx), np.linspace(-0.5, 0.5, ny)
    pts = []
    for i, yv in enumerate(ys):
        row = xs if i % 2 == 0 else xs[::-1]
        for xv in row:
            pts.append([xv * size_mm[0], yv * size_mm[1], 0.5 * size_mm[2] * np.sin(
                np.pi * (xv + yv))])
    pts = np.array(pts[:n_points])
    centre = np.array([0.55 * R, 0.1 * R * rng.uniform(-1, 1), float(model.base_pose.z) + 0.35 * R])
    rot = (Rotation.from_euler("x", 180.0 + tilt_deg, degrees=True)).as_matrix()
    goals = np.tile(np.eye(4), (n_points, 1, 1))
    goals[:, :3, :3] = rot
    goals[:, :3, 3] = centre + pts
    # a start configuration reaching the first point: elbow up, wrist down
    lim = model.limits_deg()
    for _ in range(50):
        seeds = rng.uniform(np.maximum(lim[:, 0], -180) + 5, np.minimum(lim[:, 1], 180) - 5,
                            (200, model.dof))
        q0 = solve_ik(model, tool, np.repeat(goals[:1], len(seeds), 0), seeds, 60)
        ok = reached(model, tool, q0, np.repeat(goals[:1], len(seeds), 0))
        if np.any(ok):
            break
    else:
        raise KinematicsError(("robot",), f"no pose of {model.name} reaches the path's start")
    q = [q0[np.flatnonzero(ok)[0]]]
    for k in range(1, n_points):
        qk = solve_ik(model, tool, goals[k:k + 1], q[-1][None, :], 30)
        if not reached(model, tool, qk, goals[k:k + 1])[0]:
            raise KinematicsError(("robot",), f"the path leaves {model.name}'s reach at point {k}")
        q.append(qk[0])
    out = np.repeat(np.array(q), max(int(repeats), 1), axis=0)[:int(n)]
    return out


__all__ = ["simulate_recording", "constant_orientation_path", "DEFAULT_TOOL", "DEFAULT_INSTRUMENT", "DEFAULT_SAMPLES"]
