"""The candidate-effect library: each effect's regressor in the baseline's residual space.

An effect with parameter beta changes the true TCP pose at sample k by a twist
``G_k beta`` (displacement mm, rotation rad, base frame); through the kind's sensitivity
``S_k = dg_k / d twist`` it changes the constraint by ``X_k = S_k G_k``. ``X`` is the
Jacobian column of the residual with respect to the effect's parameter; the selection
(``selection.py``) fits ``-g ≈ B db + X beta``. Parameters are in report units, so beta is
``offset_deg``, ``delta_mm``, ``compliance_deg_per_Nm``, ... directly.

| effect | twist per unit parameter |
|---|---|
| joint_offset j | DH angle of joint j turns by 1 deg |
| link_length j (a/d) | DH length a_j or d_j grows by 1 mm |
| link_twist j | DH alpha_j turns by 1 deg (an axis misalignment) |
| joint_compliance j | DH angle of joint j turns by ``tau_j`` deg (gravity torque, Nm) |
| backlash j | DH angle turns by ``-s_j / 2`` deg (s_j = sign of the joint's last motion) |
| thermal_drift (tau) | the TCP moves by ``w(t)`` mm along base x, y, z; ``w`` the first-order warm-up profile of time constant tau (:func:`solvers.physics.warmup_profile`, ISO 230-3), linear for tau = None; one candidate per tau of a grid (``TAU_GRID``), refined by :func:`thermal_candidate` |
| gear_transmission_error j, k | DH angle of joint j turns by ``sin(k theta_j)`` and ``cos(k theta_j)`` deg (theta_j the recorded DH angle): one candidate per harmonic k = 1..``GEAR_HARMONICS``, so the selection scans each joint's periodogram |
| trigger_latency | the TCP stood ``v · 1 ms`` behind where it was recorded (beam) |
| tool_deflection | the TCP moves by ``F_perp`` mm (payload weight across the tool axis, N) |
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solvers.analysis.baseline import Baseline
from solvers.dh import dh_angles_rad
from solvers.gravity import G_M_S2
from solvers.physics import warmup_profile
from solvers.recording import last_motion_sign
from solvers.validate import FloatArray

DEG = np.pi / 180.0
GEAR_HARMONICS = 12          # periods per joint turn offered for a gear's transmission error
GEAR_MIN_PERIODS = 1.0       # a harmonic is a candidate only where the joint's travel covers
                             # at least this many of its periods (else it is a smooth trend
                             # any other effect of that joint fits as well, and it does not
                             # carry over to poses outside the travel)
TAU_GRID = (1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0, 2.0, None)   # warm-up tau / recording span


def effect_key(effect: str, joint: int | None, dh_parameter: str | None,
               periods: int | None, tau_s: float | None) -> str:
    """An effect's name in reports and saved models:
    ``<effect>[_j<joint>][_<DH parameter>][_k<periods>][_tau<s>s]``, e.g.
    ``gear_transmission_error_j2_k12`` (the thermal drift's tau only for that effect)."""
    j = "" if joint is None else f"_j{joint}"
    dp = "" if dh_parameter is None else f"_{dh_parameter}"
    k = "" if periods is None else f"_k{periods}"
    tau = "" if effect != "thermal_drift" or tau_s is None else f"_tau{tau_s:.0f}s"
    return f"{effect}{j}{dp}{k}{tau}"


@dataclass(eq=False)
class Candidate:
    """One effect on one joint (or none): its residual-space columns and report mapping."""

    effect: str
    joint: int | None                 # 1-based
    columns: FloatArray               # (rows, k)
    param: str                        # report parameter name
    dh_parameter: str | None = None   # 'a' / 'd' / 'alpha' for DH-row effects
    regressor: str = ""               # plain words for what the effect grows with
    feature: FloatArray | None = None  # per-sample scalar the effect scales with (locate)
    # how the effect changes the model (to apply it nonlinearly, ``apply``):
    theta_per_unit: FloatArray | None = None    # (N, n) DH angle change (rad) per unit beta
    dh_per_unit: tuple[str, int, float] | None = None  # ('a'|'d'|'alpha', row 0-based, scale)
    shift_per_unit: FloatArray | None = None    # (N, 3, k) TCP translation (mm) per unit beta
    periods: int | None = None        # gear_transmission_error: harmonic k (periods per turn)
    tau_s: float | None = None        # thermal_drift: warm-up time constant (None: linear)
    frame: FloatArray | None = None   # thermal_drift: R_instrument_base (direction's frame)

    def apply(self, state, beta: FloatArray) -> None:
        """Add this effect with parameter(s) ``beta`` to a :class:`State` (in place)."""
        if self.theta_per_unit is not None:
            if self.theta_per_unit.ndim == 3:
                state.dtheta_rad += self.theta_per_unit @ np.asarray(beta, float)
            else:
                state.dtheta_rad += self.theta_per_unit * float(beta[0])
        if self.dh_per_unit is not None:
            name, row, scale = self.dh_per_unit
            state.ddh[name][row] += scale * float(beta[0])
        if self.shift_per_unit is not None:
            state.shift_mm += np.einsum("nik,k->ni", self.shift_per_unit, np.asarray(beta, float))

    @property
    def key(self) -> str:
        return effect_key(self.effect, self.joint, self.dh_parameter, self.periods, self.tau_s)

    @property
    def family(self) -> str:
        """Candidates of one family are alternatives: at most one of them is chosen."""
        return "thermal_drift" if self.effect == "thermal_drift" else self.key

    @property
    def label(self) -> str:
        if self.effect == "link_length":
            return f"link length {self.dh_parameter}{self.joint}"
        if self.effect == "link_twist":
            return f"link twist alpha{self.joint}"
        if self.effect == "gear_transmission_error":
            return f"gear transmission error J{self.joint} ({self.periods} per turn)"
        j = "" if self.joint is None else f" J{self.joint}"
        return self.effect.replace("_", " ") + j

    def report_parameters(self, beta: FloatArray, std: FloatArray) -> dict[str, object]:
        """``parameters`` block of a finding (magnitudes where the spec says so)."""
        if self.effect == "thermal_drift":
            v = float(np.linalg.norm(beta))
            s = float(np.sqrt(np.sum((beta / max(v, 1e-12)) ** 2 * std ** 2)))
            u = beta / max(v, 1e-12)
            R = np.eye(3) if self.frame is None else self.frame
            return {"drift_mm": v, "drift_std_mm": s, "tau_s": self.tau_s,
                    "direction": [float(x) for x in R @ u],
                    "direction_base": [float(x) for x in u]}
        if self.effect == "gear_transmission_error":
            # A sin(k q + phi) = A cos(phi) sin(k q) + A sin(phi) cos(k q)
            amp = float(np.hypot(beta[0], beta[1]))
            g = np.array([beta[0], beta[1]]) / max(amp, 1e-300)
            s = float(np.sqrt(np.sum(g ** 2 * std[:2] ** 2)))
            return {"amplitude_deg": amp, "amplitude_std_deg": s,
                    "periods_per_turn": int(self.periods or 0),
                    "phase_deg": float(np.degrees(np.arctan2(beta[1], beta[0])))}
        b, s = float(beta[0]), float(std[0])
        if self.effect == "backlash":
            return {"backlash_deg": abs(b), "backlash_std_deg": s}
        out: dict[str, object] = {self.param: b, f"{self.param}_std": s}
        if self.dh_parameter is not None and self.effect == "link_length":
            out["dh_parameter"] = self.dh_parameter
        return out


def gravity_torques_nm(rec) -> FloatArray:
    """Gravity torque (N, n) in Nm on each joint, from ``solvers.gravity`` (the simulator's)."""
    from solvers.gravity import gravity_torques
    return np.asarray(gravity_torques(rec.robot, rec.joints_deg, rec.payload_mass_kg,
                                      rec.payload_com_mm, getattr(rec, "link_masses", None)),
                      dtype=float)


def _apply(base: Baseline, twist: FloatArray) -> FloatArray:
    """Residual column(s) of per-sample twists (N, 6) or (N, 6, k)."""
    if twist.ndim == 2:
        twist = twist[:, :, None]
    X = np.einsum("nmi,nik->nmk", base.S, twist)
    return X.reshape(-1, twist.shape[2])


@dataclass
class Library:
    candidates: list[Candidate] = field(default_factory=list)
    torques_nm: FloatArray | None = None
    signs: FloatArray | None = None
    skipped: list[dict] = field(default_factory=list)   # not offered, with the reason
    # the gear harmonics left out for too little travel (``skipped``), kept as yardsticks:
    # never named, but a named harmonic must fit better than they do (``forward.resolved``)
    longer: list[Candidate] = field(default_factory=list)


def build_library(rec, base: Baseline, torques_nm: FloatArray | None = None,
                  include_twist: bool = True) -> Library:
    """Every candidate effect of the spec's table (plus ``link_twist``) for this recording."""
    sens = base.sens
    n = rec.joints_deg.shape[1]
    cands: list[Candidate] = []
    tau = gravity_torques_nm(rec) if torques_nm is None else torques_nm
    sg = last_motion_sign(rec)
    # twist per controller joint (deg): theta = direction * (C q) + offset
    ctrl = np.einsum("nij,j,jk->nik", sens.theta, rec.robot.params()["direction"],
                     rec.robot.coupling_matrix())
    direction = rec.robot.params()["direction"]
    C = rec.robot.coupling_matrix()
    N = len(rec.joints_deg)
    for j in range(n):
        th = sens.theta[:, :, j] * DEG
        thq = ctrl[:, :, j] * DEG
        unit = np.zeros((N, n))
        unit[:, j] = DEG
        ctrl_unit = np.tile(direction * C[:, j] * DEG, (N, 1))   # DH angles per controller deg
        cands.append(Candidate("joint_offset", j + 1, _apply(base, th), "offset_deg",
                               regressor="a constant", feature=np.ones(N), theta_per_unit=unit))
        cands.append(Candidate("link_length", j + 1, _apply(base, sens.a[:, :, j]), "delta_mm", "a",
                               regressor="a constant", dh_per_unit=("a", j, 1.0)))
        cands.append(Candidate("link_length", j + 1, _apply(base, sens.d[:, :, j]), "delta_mm", "d",
                               regressor="a constant", dh_per_unit=("d", j, 1.0)))
        if include_twist:
            cands.append(Candidate("link_twist", j + 1, _apply(base, sens.alpha[:, :, j] * DEG),
                                   "delta_alpha_deg", "alpha", regressor="a constant",
                                   dh_per_unit=("alpha", j, DEG)))
        cands.append(Candidate("joint_compliance", j + 1, _apply(base, thq * tau[:, j:j + 1]),
                               "compliance_deg_per_Nm",
                               regressor=f"the gravity torque on joint {j + 1}", feature=tau[:, j],
                               theta_per_unit=ctrl_unit * tau[:, j:j + 1]))
        cands.append(Candidate("backlash", j + 1, _apply(base, thq * (-0.5 * sg[:, j:j + 1])),
                               "backlash_deg",
                               regressor=f"the direction joint {j + 1} last moved in",
                               feature=sg[:, j], theta_per_unit=ctrl_unit * (-0.5 * sg[:, j:j + 1])))
    theta_deg = np.degrees(dh_angles_rad(rec.robot, rec.joints_deg))
    skipped: list[dict] = []
    longer: list[Candidate] = []
    for j in range(n):
        travel = float(np.ptp(theta_deg[:, j]))
        if travel < 1e-6:
            continue
        short = [k for k in range(1, GEAR_HARMONICS + 1)
                 if travel * k / 360.0 < GEAR_MIN_PERIODS]
        cands += gear_candidates(base, theta_deg[:, j], j,
                                 [k for k in range(1, GEAR_HARMONICS + 1) if k not in short])
        longer += gear_candidates(base, theta_deg[:, j], j, short)
        if short:
            skipped.append({"effect": "gear_transmission_error", "joint": j + 1,
                            "periods_per_turn": short,
                            "reason": f"joint {j + 1} travels {travel:.3g} deg, less than one "
                                      f"period of these harmonics ({360.0 / short[-1]:.3g} deg "
                                      f"and longer): over part of a period a gear error looks "
                                      f"like a smooth trend and does not carry over to other "
                                      f"poses; spread joint {j + 1} over at least one full "
                                      f"period (better two) to test them"})
    t = np.asarray(rec.t_s, float)
    span = float(t.max() - t.min())
    if span > 0:
        for r in TAU_GRID:
            cands.append(thermal_candidate(rec, base, None if r is None else r * span))
    if rec.kind == "beam" and rec.tcp_velocity_mm_s is not None:
        w = np.asarray(rec.tcp_velocity_mm_s, float)
        tw = np.zeros((len(w), 6))
        tw[:, :3] = -w * 1e-3
        cands.append(Candidate("trigger_latency", None, _apply(base, tw), "latency_ms",
                               regressor="the TCP velocity",
                               feature=np.linalg.norm(w, axis=1), shift_per_unit=tw[:, :3, None]))
    if rec.payload_mass_kg > 0:
        u = sens.axis
        gdir = np.array([0.0, 0.0, -1.0])
        fperp = rec.payload_mass_kg * G_M_S2 * (gdir - np.outer(u @ gdir, np.ones(3)) * u)
        tw = np.zeros((len(u), 6))
        tw[:, :3] = fperp
        cands.append(Candidate("tool_deflection", None, _apply(base, tw), "deflection_mm_per_N",
                               regressor="the payload weight across the tool axis",
                               feature=np.linalg.norm(fperp, axis=1), shift_per_unit=tw[:, :3, None]))
    return Library(cands, tau, sg, skipped, longer)


def gear_candidates(base: Baseline, theta_deg: FloatArray, j: int, ks: list[int]
                    ) -> list[Candidate]:
    """:func:`gear_candidate` of every harmonic in ``ks`` (one residual product for all)."""
    if not ks:
        return []
    N = len(theta_deg)
    n = base.sens.theta.shape[2]
    arg = np.radians(np.outer(theta_deg, ks))                       # (N, K)
    waves = np.stack([np.sin(arg), np.cos(arg)], axis=2).reshape(N, -1)   # (N, 2K)
    th = base.sens.theta[:, :, j] * DEG
    X = _apply(base, th[:, :, None] * waves[:, None, :])
    out = []
    for i, k in enumerate(ks):
        unit = np.zeros((N, n, 2))
        unit[:, j, :] = waves[:, 2 * i:2 * i + 2] * DEG
        out.append(Candidate("gear_transmission_error", j + 1, X[:, 2 * i:2 * i + 2],
                             "amplitude_deg", regressor=f"sin/cos({k} q{j + 1})",
                             feature=waves[:, 2 * i], theta_per_unit=unit, periods=k))
    return out


def gear_candidate(base: Baseline, theta_deg: FloatArray, j: int, k: int) -> Candidate:
    """Joint j's (0-based) k-th harmonic of a gear's transmission error: its DH angle turns
    by ``b_s sin(k theta) + b_c cos(k theta)`` deg (theta: the recorded DH angle, deg)."""
    N = len(theta_deg)
    n = base.sens.theta.shape[2]
    arg = np.radians(k * theta_deg)
    waves = np.stack([np.sin(arg), np.cos(arg)], axis=1)            # (N, 2)
    th = base.sens.theta[:, :, j] * DEG
    unit = np.zeros((N, n, 2))
    unit[:, j, :] = waves * DEG
    return Candidate("gear_transmission_error", j + 1, _apply(base, th[:, :, None] * waves[:, None, :]),
                     "amplitude_deg", regressor=f"sin/cos({k} q{j + 1})",
                     feature=waves[:, 0], theta_per_unit=unit, periods=k)


def thermal_candidate(rec, base: Baseline, tau_s: float | None) -> Candidate:
    """A base (or instrument) shift ``w(t) beta`` mm along x, y, z: ``w`` the warm-up profile
    of time constant ``tau_s`` (None: linear), 0 at the first sample and 1 at the last."""
    t = np.asarray(rec.t_s, float)
    f = warmup_profile(t, float(t.min()), float(t.max()), tau_s)
    tw = np.zeros((len(t), 6, 3))
    tw[:, 0, 0] = tw[:, 1, 1] = tw[:, 2, 2] = f
    return Candidate("thermal_drift", None, _apply(base, tw), "drift_mm", regressor="time",
                     feature=f, shift_per_unit=tw[:, :3, :], tau_s=tau_s,
                     frame=base.R_instrument_base)
