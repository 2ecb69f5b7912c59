"""The emulator's hidden physics: what a real robot does when its controller shows ``q``.

The controller's rigid model is :func:`solvers.dh.forward_kinematics`. A real arm differs by
the effects below; :func:`true_flange_poses` applies them, in this order, to recorded joint
values ``q`` (controller degrees) at times ``t_s``. Effect names, units and signs are those of
the discrepancy analysis report (``analysis-report/1``):

1. ``backlash_deg`` b (full lost-motion angle per joint): the link lags the motor by half
   the lost motion in the direction the joint last moved, ``q <- q - s * b / 2`` with
   ``s = motion_signs(q, start_joints_deg)`` (+1 after moving up, -1 after moving down, 0
   before any known motion). Approaching from + and from - therefore differs by b.
2. ``cyclic_error`` {joint: (amplitude_deg, periods_per_rev)}: a gear's periodic
   transmission error, ``q <- q + A sin(2 pi k q / 360)`` (k periods per joint turn), in the
   controller's sense of the joint. ``gear_transmission_error`` ((joint, amplitude_deg,
   periods_per_turn, phase_deg), ...) is the same in the report's terms, one entry per
   harmonic: the DH angle turns by ``A sin(k theta + phi)``, theta the joint's nominal DH
   angle at the recorded value (the analysis's ``gear_transmission_error``).
3. ``compliance_deg_per_Nm`` c: the joint yields under gravity and payload torque,
   ``q <- q + c * tau(q)``, tau from :func:`solvers.gravity.gravity_torques` at the recorded
   joints on the nominal model (signed in the joint's positive sense; evaluating it at the
   deflected pose differs by a second-order amount).
4. ``joint_offset_deg`` o (true minus recorded): the joint really stands at the recorded
   value plus o in the direction of its DH angle: ``theta = direction * q_dh + offset + o``
   (for ``direction = +1`` arms this is FK at ``q + o``).
5. ``dh_delta`` {("a_mm" | "d_mm" | "alpha_deg", joint 1-based): true minus nominal}: the
   true DH table.
6. ``thermal_drift_mm`` D: the robot's base shifts in time along ``thermal_direction``
   (unit, default +z: the pedestal and lower arm grow upwards as they warm),
   ``T_base <- Trans(D * w(t) * u) @ T_base``; D is the total shift between the first and
   the last sample. ``thermal_tau_s`` tau > 0 makes it a first-order warm-up (the ISO 230-3
   style of thermal response), ``w(t) = (1 - exp(-(t - t_0)/tau)) / (1 - exp(-(t_N - t_0)/tau))``;
   tau = 0 (the default) is the linear limit ``w(t) = (t - t_0) / (t_N - t_0)`` (tau >> span).
7. ``trigger_latency_ms`` L (beam recordings, when the TCP velocity v is given): the
   recorded joints are the pose L later along the motion, so the pose at the trigger is the
   recorded one moved back by ``v * L`` (a pure translation: the passes keep the tool's
   orientation).
8. ``tool_deflection_mm_per_N`` k (TCP only): the tool bends under the payload's weight
   ``F = m g`` (down, base frame); the TCP moves by ``k * F_perp`` where ``F_perp`` is the
   component of F across the tool axis; the tool axis keeps its direction.

``noise_mm`` (standard deviation per axis) is not applied here: the simulator adds it where
the measurement happens (instrument reading, operator's aim, trigger position).

All functions are pure and vectorised over samples.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace

import numpy as np

from solvers.dh import RobotModel, dh_angles_rad, joint_values, link_matrices
from solvers.errors import CalibrationError
from solvers.gravity import G_M_S2, gravity_torques
from solvers.recording import motion_signs
from solvers.validate import FloatArray, as_array

DH_LENGTHS = ("a_mm", "d_mm", "alpha_deg")


def _finite(value: object, loc: tuple) -> None:
    try:
        ok = bool(np.all(np.isfinite(np.asarray(value, dtype=float))))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise CalibrationError(loc, f"must be finite numbers, got {value!r}")


@dataclass(frozen=True)
class Imperfections:
    """How a real robot differs from its rigid model (all zero = the rigid model).

    Per-joint sequences have one value per joint (None = zeros). See the module docstring
    for each effect's equation and sign.

    Examples
    --------
    >>> imp = Imperfections(joint_offset_deg=(0, 0.05, 0, 0, 0, 0), noise_mm=0.01)
    >>> imp.per_joint("joint_offset_deg", 6).tolist()[1]
    0.05
    >>> Imperfections().is_rigid()
    True
    """

    joint_offset_deg: tuple[float, ...] | None = None
    dh_delta: Mapping[tuple[str, int], float] = field(default_factory=dict)
    compliance_deg_per_Nm: tuple[float, ...] | None = None
    backlash_deg: tuple[float, ...] | None = None
    thermal_drift_mm: float = 0.0
    thermal_direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    trigger_latency_ms: float = 0.0
    tool_deflection_mm_per_N: float = 0.0
    cyclic_error: Mapping[int, tuple[float, float]] = field(default_factory=dict)
    thermal_tau_s: float = 0.0
    gear_transmission_error: tuple[tuple[int, float, float, float], ...] = ()
    noise_mm: float = 0.0

    @classmethod
    def from_dict(cls, d: Mapping) -> "Imperfections":
        """From JSON-style values (for the CLI): ``dh_delta`` keys ``"a_mm:2"``,
        ``cyclic_error`` keys ``"3"`` with ``[amplitude_deg, periods_per_rev]``.

        Examples
        --------
        >>> imp = Imperfections.from_dict({"dh_delta": {"a_mm:2": 0.3}, "noise_mm": 0.01,
        ...                                "cyclic_error": {"3": [0.02, 4]}})
        >>> dict(imp.dh_delta), dict(imp.cyclic_error)
        ({('a_mm', 2): 0.3}, {3: (0.02, 4.0)})
        """
        known = {f.name for f in fields(cls)}
        for key in d:
            if key not in known:
                raise CalibrationError((str(key),), "unknown imperfection; known: "
                                       + ", ".join(sorted(known)))
        kw: dict = {}
        for key, value in d.items():
            if value is None:      # an omitted per-joint list (GET .../cell/physics shows null)
                continue
            try:
                kw[key] = cls._field_from(key, value)
            except CalibrationError:
                raise
            except (TypeError, ValueError, AttributeError):
                raise CalibrationError((str(key),), f"cannot read {value!r} as this effect's "
                                       "value(s)") from None
        return cls(**kw)

    @staticmethod
    def _field_from(key: str, value) -> object:  # noqa: ANN001
        """One field of :meth:`from_dict` (TypeError/ValueError on a wrong shape)."""
        if key == "dh_delta":
            delta = {}
            for k, v in value.items():
                param, _, joint = str(k).partition(":")
                if not joint.isdigit():
                    raise CalibrationError(("dh_delta", str(k)),
                                           "keys are 'a_mm:2' (parameter:joint)")
                delta[(param, int(joint))] = float(v)
            return delta
        if key == "cyclic_error":
            cyc = {}
            for k, v in value.items():
                if not str(k).isdigit() or len(v) != 2:
                    raise CalibrationError(("cyclic_error", str(k)),
                                           "is {joint: [amplitude_deg, periods_per_rev]}")
                cyc[int(k)] = (float(v[0]), float(v[1]))
            return cyc
        if key == "gear_transmission_error":
            gears = []
            for i, v in enumerate(value):
                if len(v) != 4 or not str(v[0]).isdigit():
                    raise CalibrationError((key, i), "is a list of [joint, amplitude_deg, "
                                           "periods_per_turn, phase_deg]")
                gears.append((int(v[0]), float(v[1]), float(v[2]), float(v[3])))
            return tuple(gears)
        if isinstance(value, (list, tuple)):
            return tuple(float(v) for v in value)
        return float(value)

    def per_joint(self, name: str, n: int) -> FloatArray:
        """The per-joint field ``name`` as an (n,) array (zeros when None)."""
        value = getattr(self, name)
        if value is None:
            return np.zeros(n)
        return as_array(value, name, (n,))

    def is_rigid(self) -> bool:
        """True when no effect is switched on (noise aside)."""
        per_joint = ("joint_offset_deg", "compliance_deg_per_Nm", "backlash_deg")
        return (all(getattr(self, f) is None or not np.any(getattr(self, f)) for f in per_joint)
                and not any(self.dh_delta.values()) and not self.cyclic_error
                and not self.gear_transmission_error
                and self.thermal_drift_mm == 0 and self.trigger_latency_ms == 0
                and self.tool_deflection_mm_per_N == 0)

    def check(self, n: int) -> "Imperfections":
        """Raise :class:`CalibrationError` naming the field if anything does not fit n joints."""
        for name in ("joint_offset_deg", "compliance_deg_per_Nm", "backlash_deg"):
            self.per_joint(name, n)
        if self.backlash_deg is not None and np.any(np.asarray(self.backlash_deg) < 0):
            raise CalibrationError(("backlash_deg",), "is a full lost-motion angle, must be >= 0")
        for (param, joint), _ in self.dh_delta.items():
            if param not in DH_LENGTHS or not 1 <= int(joint) <= n:
                raise CalibrationError(("dh_delta", f"{param}:{joint}"),
                                       f"must be one of {DH_LENGTHS} of a joint 1..{n}")
        for joint in self.cyclic_error:
            if not 1 <= int(joint) <= n:
                raise CalibrationError(("cyclic_error", joint), f"joint must be 1..{n}")
        for i, (joint, *values) in enumerate(self.gear_transmission_error):
            if not 1 <= int(joint) <= n:
                raise CalibrationError(("gear_transmission_error", i), f"joint must be 1..{n}")
            _finite(values, ("gear_transmission_error", i))
        for name in ("thermal_drift_mm", "thermal_tau_s", "trigger_latency_ms",
                     "tool_deflection_mm_per_N", "noise_mm"):
            _finite(getattr(self, name), (name,))
        if self.thermal_tau_s < 0:
            raise CalibrationError(("thermal_tau_s",), "is a time constant, must be >= 0 "
                                   "(0: a linear drift)")
        for (param, joint), value in self.dh_delta.items():
            _finite(value, ("dh_delta", f"{param}:{joint}"))
        for joint, value in self.cyclic_error.items():
            _finite(value, ("cyclic_error", joint))
        _finite(self.thermal_direction, ("thermal_direction",))
        if self.noise_mm < 0:
            raise CalibrationError(("noise_mm",), "is a standard deviation, must be >= 0")
        if np.linalg.norm(self.thermal_direction) < 1e-9:
            raise CalibrationError(("thermal_direction",), "must be a non-zero vector")
        return self


def true_robot(robot: RobotModel, imperfections: Imperfections) -> RobotModel:
    """The nominal model with the joint offsets and DH deltas applied (the true geometry)."""
    imp = imperfections.check(robot.dof)
    off = imp.per_joint("joint_offset_deg", robot.dof)
    joints = list(robot.joints)
    for i, j in enumerate(joints):
        joints[i] = replace(j, offset_deg=j.offset_deg + float(off[i]))
    for (param, joint), delta in imp.dh_delta.items():
        j = joints[int(joint) - 1]
        joints[int(joint) - 1] = replace(j, **{param: getattr(j, param) + float(delta)})
    return replace(robot, joints=tuple(joints))


def true_joint_values(robot: RobotModel, joints_deg: object, imperfections: Imperfections,
                      start_joints_deg: object = None, payload_mass_kg: float = 0.0,
                      payload_com_mm: object = (0.0, 0.0, 0.0)) -> FloatArray:
    """Where each joint really stands (controller sense, before the DH offset), (N, n).

    ``q_true = q - s b / 2 + A sin(2 pi k q / 360) + c tau(q)`` (backlash, cyclic error,
    compliance; see the module docstring).
    """
    q = np.atleast_2d(joint_values(robot, joints_deg))
    imp = imperfections.check(robot.dof)
    start = None if start_joints_deg is None else as_array(start_joints_deg, "start_joints_deg",
                                                             (robot.dof,))
    out = q - motion_signs(q, start) * imp.per_joint("backlash_deg", robot.dof) / 2.0
    for joint, (amp, periods) in imp.cyclic_error.items():
        i = int(joint) - 1
        out[:, i] += amp * np.sin(np.radians(periods * q[:, i]))
    c = imp.per_joint("compliance_deg_per_Nm", robot.dof)
    if np.any(c):
        out += c * gravity_torques(robot, q, payload_mass_kg, payload_com_mm)
    return out


def warmup_profile(t_s: FloatArray, t0: float, t1: float, tau_s: float | None) -> FloatArray:
    """Share ``w(t)`` of the total drift reached at each time (0 at t0, 1 at t1).

    First-order warm-up (ISO 230-3, thermal response of a machine to heat from its drives):
    ``w = (1 - exp(-(t - t0)/tau)) / (1 - exp(-(t1 - t0)/tau))``; ``tau`` None or 0 (or
    very large) is the linear limit ``(t - t0) / (t1 - t0)``. Computed with ``expm1`` so
    that neither a tiny nor a huge tau overflows.

    Examples
    --------
    >>> warmup_profile(np.array([0.0, 50.0, 100.0]), 0.0, 100.0, None).tolist()
    [0.0, 0.5, 1.0]
    >>> w = warmup_profile(np.array([0.0, 50.0, 100.0]), 0.0, 100.0, 20.0)
    >>> [round(float(v), 3) for v in w]
    [0.0, 0.924, 1.0]
    """
    t = np.asarray(t_s, dtype=float)
    span = float(t1 - t0)
    if span <= 0:
        return np.zeros_like(t)
    x = (t - t0) / span
    if not tau_s or tau_s > 1e4 * span:
        return x
    r = span / float(tau_s)
    if r > 700.0:   # a step at t0 (tau far below the sample spacing)
        return (x > 0).astype(float)
    return np.expm1(-r * x) / np.expm1(-r)


def gear_error_deg(robot: RobotModel, joints_deg: FloatArray,
                   imperfections: Imperfections) -> FloatArray:
    """DH angle change (N, n) of the ``gear_transmission_error`` harmonics, in degrees:
    ``sum A sin(k theta + phi)`` per joint, theta the nominal DH angle of the recorded joints
    (deg). One harmonic of a gear stage per entry."""
    q = np.atleast_2d(joints_deg)
    out = np.zeros(q.shape)
    if not imperfections.gear_transmission_error:
        return out
    theta = np.degrees(dh_angles_rad(robot, q))
    for joint, amp, k, phase in imperfections.gear_transmission_error:
        i = int(joint) - 1
        out[:, i] += amp * np.sin(np.radians(k * theta[:, i] + phase))
    return out


def thermal_shift_mm(t_s: object, imperfections: Imperfections,
                     time_span_s: tuple[float, float] | None = None) -> FloatArray:
    """Base translation (N, 3) at each time: ``D w(t) u`` (see :func:`warmup_profile`).

    ``time_span_s`` = (t_0, t_N) of the whole recording; default the span of ``t_s``.
    """
    t = np.atleast_1d(as_array(t_s, "t_s", (None,)))
    t0, t1 = (float(t.min()), float(t.max())) if time_span_s is None else map(float, time_span_s)
    if imperfections.thermal_drift_mm == 0 or t1 <= t0:
        return np.zeros((t.size, 3))
    u = np.asarray(imperfections.thermal_direction, dtype=float)
    u = u / np.linalg.norm(u)
    w = warmup_profile(t, t0, t1, imperfections.thermal_tau_s)
    return imperfections.thermal_drift_mm * w[:, None] * u


def true_flange_poses(robot: RobotModel, joints_deg: object, t_s: object,
                      imperfections: Imperfections, start_joints_deg: object = None,
                      payload_mass_kg: float = 0.0, payload_com_mm: object = (0.0, 0.0, 0.0),
                      tcp_velocity_mm_s: object = None,
                      time_span_s: tuple[float, float] | None = None) -> FloatArray:
    """``T_base_flange`` (N, 4, 4) the real robot takes when the controller shows ``joints_deg``.

    Parameters
    ----------
    robot : RobotModel
        The nominal (controller's) model.
    joints_deg : array_like, shape (N, n)
        Recorded joint values, in recording order.
    t_s : array_like, shape (N,)
        Sample times (for the thermal drift).
    imperfections : Imperfections
    start_joints_deg : array_like, shape (n,), optional
        Where the robot came from before the first sample (backlash).
    payload_mass_kg, payload_com_mm
        The payload (compliance).
    tcp_velocity_mm_s : array_like, shape (N, 3), optional
        Commanded TCP velocity at each sample (beam triggers): with it the trigger latency
        is undone, giving the pose at the trigger.
    time_span_s : (float, float), optional
        First and last time of the whole recording (thermal drift) when ``t_s`` is only part
        of it; default ``(min(t_s), max(t_s))``.

    Examples
    --------
    >>> from solvers.robots import ROBOTS
    >>> from solvers.dh import forward_kinematics
    >>> ur = ROBOTS["ur10"]
    >>> q = np.array([[10.0, -80, 70, -60, -90, 0]])
    >>> T = true_flange_poses(ur, q, [0.0], Imperfections(joint_offset_deg=(0, 0.1, 0, 0, 0, 0)))
    >>> bool(np.allclose(T, forward_kinematics(ur, q + [0, 0.1, 0, 0, 0, 0])))
    True
    """
    q = np.atleast_2d(joint_values(robot, joints_deg))
    t = as_array(np.atleast_1d(t_s), "t_s", (len(q),))
    imp = imperfections.check(robot.dof)
    true = true_robot(robot, imp)
    qt = true_joint_values(robot, q, imp, start_joints_deg, payload_mass_kg, payload_com_mm)
    p = true.params()
    theta = np.radians(p["direction"] * (qt @ true.coupling_matrix().T) + p["offset_deg"]
                       + gear_error_deg(robot, q, imp))
    links = link_matrices(true.dh_convention, theta, p["d_mm"], p["a_mm"],
                          np.radians(p["alpha_deg"]))
    T = np.broadcast_to(true.base_pose.as_matrix(), (len(q), 4, 4)).copy()
    T[:, :3, 3] += thermal_shift_mm(t, imp, time_span_s)
    for i in range(true.dof):
        T = T @ links[:, i]
    T = T @ true.flange_pose.as_matrix()
    if tcp_velocity_mm_s is not None and imp.trigger_latency_ms:
        v = as_array(tcp_velocity_mm_s, "tcp_velocity_mm_s", (len(q), 3))
        T[:, :3, 3] -= v * imp.trigger_latency_ms / 1000.0
    return T


def tool_deflection_mm(T_base_tcp: FloatArray, imperfections: Imperfections,
                       payload_mass_kg: float) -> FloatArray:
    """TCP displacement (N, 3) of a tool bending under the payload's weight across its axis."""
    k = imperfections.tool_deflection_mm_per_N
    if k == 0 or payload_mass_kg == 0:
        return np.zeros(T_base_tcp.shape[:-2] + (3,))
    F = np.array([0.0, 0.0, -G_M_S2 * payload_mass_kg])
    w = T_base_tcp[..., :3, 2]
    F_perp = F - (w @ F)[..., None] * w
    return k * F_perp


def true_tcp_poses(robot: RobotModel, joints_deg: object, t_s: object, imperfections: Imperfections,
                   tool: object, start_joints_deg: object = None, payload_mass_kg: float = 0.0,
                   payload_com_mm: object = (0.0, 0.0, 0.0),
                   tcp_velocity_mm_s: object = None,
                   time_span_s: tuple[float, float] | None = None) -> FloatArray:
    """``T_base_tcp`` (N, 4, 4) of the real robot: true flange poses, ``tool`` (T_flange_tcp),
    then the tool's deflection (a translation of the TCP)."""
    tool_T = as_array(tool, "tool", (4, 4))
    T = true_flange_poses(robot, joints_deg, t_s, imperfections, start_joints_deg,
                          payload_mass_kg, payload_com_mm, tcp_velocity_mm_s, time_span_s) @ tool_T
    T[:, :3, 3] += tool_deflection_mm(T, imperfections, payload_mass_kg)
    return T


def true_tcp_positions(robot: RobotModel, joints_deg: object, t_s: object,
                       imperfections: Imperfections, tool: object, start_joints_deg: object = None,
                       payload_mass_kg: float = 0.0, payload_com_mm: object = (0.0, 0.0, 0.0),
                       tcp_velocity_mm_s: object = None,
                       time_span_s: tuple[float, float] | None = None) -> FloatArray:
    """TCP positions (N, 3) in base of the real robot (see :func:`true_tcp_poses`)."""
    return true_tcp_poses(robot, joints_deg, t_s, imperfections, tool, start_joints_deg,
                          payload_mass_kg, payload_com_mm, tcp_velocity_mm_s, time_span_s)[:, :3, 3]


__all__ = ["Imperfections", "DH_LENGTHS", "true_robot", "true_joint_values", "thermal_shift_mm",
           "warmup_profile", "gear_error_deg",
           "true_flange_poses", "true_tcp_poses", "true_tcp_positions", "tool_deflection_mm"]
