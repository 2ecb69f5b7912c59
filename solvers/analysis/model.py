"""The fitted robot model itself: effects applied to the kinematics, fitted nonlinearly,
held-out by refitting on each fold, saved (``robot-model/1``) and used to predict.

The selection (``forward.py``) works on the residual linearised at the rigid fit; every
figure the report gives comes from here instead:

- :func:`fit` fits the rigid setup (``baseline.fit_baseline``: the instrument frame and the
  TCP, ...) and the named effects' parameters together, by variable projection: for given
  effect parameters the setup is fitted exactly (nonlinear least squares), then a
  Gauss-Newton step on the effect parameters with the setup's Jacobian alongside (Golub &
  Pereyra, "Separable nonlinear least squares", Inverse Problems 19:R1-R26, 2003; Kaufman's
  step). The effects enter the kinematics themselves (``kinematics.State``: joint angles, DH
  rows, TCP shifts), not a linear approximation of them.
- :func:`heldout` refits that model on each fold's training samples (started from the fit on
  all samples) and predicts the left-out samples with the training setup.
- :func:`model_document` / :func:`predict`: the ``robot-model/1`` document and the
  ``prediction/1`` of a recording (``../shared/spec/robot-model.md``, docs/analysis.md).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from solvers.analysis.baseline import (
    Baseline,
    _beam_constraint,
    _beam_inputs,
    fit_baseline,
    per_sample_rms,
)
from solvers.analysis.effects import effect_key
from solvers.analysis.kinematics import State, flange_of, state_frames, state_sensitivities
from solvers.analysis.selection import CV, fit_linear
from solvers.dh import dh_angles_rad
from solvers.errors import CalibrationError
from solvers.gravity import G_M_S2
from solvers.physics import warmup_profile
from solvers.recording import last_motion_sign
from solvers.validate import FloatArray

DEG = np.pi / 180.0
MODEL_FORMAT = "robot-model/1"
PREDICTION_FORMAT = "prediction/1"
MAX_ITER = 12
STEP_TOL = 1e-7      # relative change of the RSS that ends the iteration
SESSION_EFFECTS = ("thermal_drift",)   # refitted with the setup on another session


@dataclass(frozen=True)
class Effect:
    """One named effect of the model (what ``effects.Candidate`` describes, without columns)."""

    effect: str
    joint: int | None = None
    dh_parameter: str | None = None
    periods: int | None = None
    tau_s: float | None = None

    @classmethod
    def of(cls, c) -> Effect:
        return cls(c.effect, c.joint, c.dh_parameter, c.periods, c.tau_s)

    @property
    def size(self) -> int:
        return {"gear_transmission_error": 2, "thermal_drift": 3}.get(self.effect, 1)

    @property
    def key(self) -> str:
        return effect_key(self.effect, self.joint, self.dh_parameter, self.periods, self.tau_s)

    def document(self) -> dict:
        return {"effect": self.effect, "joint": self.joint, "dh_parameter": self.dh_parameter,
                "periods_per_turn": self.periods, "tau_s": self.tau_s}


@dataclass
class Units:
    """How one effect changes the kinematics per unit parameter, at each sample."""

    theta: FloatArray | None = None       # (N, n, k) DH angle change, rad
    dh: tuple[str, int, float] | None = None
    shift: FloatArray | None = None       # (N, 3, k) TCP translation in base, mm

    def take(self, idx) -> Units:
        return Units(None if self.theta is None else self.theta[idx], self.dh,
                     None if self.shift is None else self.shift[idx])


def units_of(rec, eff: Effect, torques: FloatArray, signs: FloatArray,
             time_span: tuple[float, float]) -> Units:
    """The per-unit change of ``eff`` at every sample of ``rec`` (as ``effects.py`` defines
    each effect's regressor; tested to agree with it)."""
    robot = rec.robot
    q = rec.joints_deg
    N, n = q.shape
    p = robot.params()
    j = None if eff.joint is None else eff.joint - 1
    ctrl = np.asarray(p["direction"], float) * robot.coupling_matrix()[:, j] * DEG \
        if j is not None else None
    e = eff.effect
    if e == "joint_offset":
        th = np.zeros((N, n, 1))
        th[:, j, 0] = DEG
        return Units(theta=th)
    if e == "link_length":
        return Units(dh=(eff.dh_parameter, j, 1.0))
    if e == "link_twist":
        return Units(dh=("alpha", j, DEG))
    if e in ("joint_compliance", "backlash"):
        f = torques[:, j] if e == "joint_compliance" else -0.5 * signs[:, j]
        return Units(theta=(np.tile(ctrl, (N, 1)) * f[:, None])[:, :, None])
    if e == "gear_transmission_error":
        theta = np.degrees(dh_angles_rad(robot, q))[:, j]
        arg = np.radians(eff.periods * theta)
        th = np.zeros((N, n, 2))
        th[:, j, 0], th[:, j, 1] = np.sin(arg) * DEG, np.cos(arg) * DEG
        return Units(theta=th)
    if e == "thermal_drift":
        f = warmup_profile(np.asarray(rec.t_s, float), time_span[0], time_span[1], eff.tau_s)
        sh = np.zeros((N, 3, 3))
        sh[:, 0, 0] = sh[:, 1, 1] = sh[:, 2, 2] = f
        return Units(shift=sh)
    if e == "trigger_latency":
        w = np.asarray(rec.tcp_velocity_mm_s, float)
        return Units(shift=(-w * 1e-3)[:, :, None])
    if e == "tool_deflection":
        axis = state_sensitivities(robot, q, np.asarray(rec.tool, float)).axis
        gdir = np.array([0.0, 0.0, -1.0])
        fperp = rec.payload_mass_kg * G_M_S2 * (gdir - np.outer(axis @ gdir, np.ones(3)) * axis)
        return Units(shift=fperp[:, :, None])
    raise CalibrationError(("effect",), f"unknown effect {e!r}")


def time_span_of(rec) -> tuple[float, float]:
    t = np.asarray(rec.t_s, float)
    return float(t.min()), float(t.max())


def gravity_of(rec) -> FloatArray:
    from solvers.analysis.effects import gravity_torques_nm
    return gravity_torques_nm(rec)


@dataclass
class Prepared:
    """A recording with the per-unit arrays of a list of effects (all samples)."""

    rec: object
    effects: list[Effect]
    units: list[Units]

    @classmethod
    def make(cls, rec, effects: list[Effect], torques: FloatArray | None = None,
             time_span: tuple[float, float] | None = None,
             signs: FloatArray | None = None) -> Prepared:
        needs_tau = any(e.effect == "joint_compliance" for e in effects)
        tau = (gravity_of(rec) if torques is None else torques) if needs_tau \
            else np.zeros(rec.joints_deg.shape)
        needs_sign = any(e.effect == "backlash" for e in effects)
        sg = (last_motion_sign(rec) if signs is None else signs) if needs_sign else None
        span = time_span_of(rec) if time_span is None else time_span
        return cls(rec, list(effects), [units_of(rec, e, tau, sg, span) for e in effects])

    @property
    def n_params(self) -> int:
        return int(sum(e.size for e in self.effects))

    def state(self, beta: FloatArray, idx=None) -> State:
        rec = self.rec
        N = rec.n_samples if idx is None else len(idx)
        st = State.zero(N, rec.joints_deg.shape[1])
        col = 0
        for e, u in zip(self.effects, self.units):
            b = np.asarray(beta[col:col + e.size], float)
            col += e.size
            u = u if idx is None else u.take(idx)
            if u.theta is not None:
                st.dtheta_rad += u.theta @ b
            if u.dh is not None:
                name, row, scale = u.dh
                st.ddh[name][row] += scale * float(b[0])
            if u.shift is not None:
                st.shift_mm += np.einsum("nik,k->ni", u.shift, b)
        return st

    def columns(self, base: Baseline, idx=None, which: list[int] | None = None) -> FloatArray:
        """Residual-space Jacobian columns (rows, k) of the effects at ``base``."""
        sens = base.sens
        cols = []
        for i, (e, u) in enumerate(zip(self.effects, self.units)):
            if which is not None and i not in which:
                continue
            u = u if idx is None else u.take(idx)
            tw = np.zeros((sens.theta.shape[0], 6, e.size))
            if u.theta is not None:
                tw += np.einsum("nij,njk->nik", sens.theta, u.theta)
            if u.dh is not None:
                name, row, scale = u.dh
                tw[:, :, 0] += getattr(sens, name)[:, :, row] * scale
            if u.shift is not None:
                tw[:, :3, :] += u.shift
            cols.append(np.einsum("nmi,nik->nmk", base.S, tw).reshape(-1, e.size))
        return np.hstack(cols) if cols else np.zeros((base.g.size, 0))


def subset(rec, idx):
    """The recording restricted to the samples ``idx`` (per-sample fields sliced)."""
    idx = np.asarray(idx, int)
    kw = {"t_s": np.asarray(rec.t_s)[idx], "joints_deg": np.asarray(rec.joints_deg)[idx]}
    for name in ("measured_mm", "beam_ids", "edges", "tcp_velocity_mm_s"):
        v = getattr(rec, name)
        if v is not None:
            kw[name] = np.asarray(v)[idx]
    return replace(rec, **kw)


@dataclass
class Fit:
    """A nonlinear fit: effect parameters ``beta``, the fitted rigid setup ``base``."""

    beta: FloatArray
    base: Baseline
    rss_mm2: float
    n_samples: int
    iterations: int

    @property
    def rms_mm(self) -> float:
        return float(np.sqrt(self.rss_mm2 / max(self.n_samples, 1)))


def fit(prep: Prepared, idx=None, beta0: FloatArray | None = None,
        free: list[int] | None = None, ident=None, max_iter: int = MAX_ITER,
        start: dict | None = None, base0: Baseline | None = None) -> Fit:
    """Fit the setup and the effects' parameters (``free``: indices of the effects whose
    parameters move; default all) to the samples ``idx`` (default all); ``ident``: the
    setup's determined directions (default: found on these samples); ``start``: a fitted
    setup to start at (with ``ident``); ``base0``: the rigid fit at ``beta0`` if already
    known (e.g. the previous model's fit, when the new effect starts at zero).

    The iteration ends when the Gauss-Newton step's predicted decrease of the RSS (the
    linear model's, ``|M step|^2``) or its achieved one is below ``STEP_TOL`` of the RSS:
    the parameters are then within a few thousandths of a standard deviation of the
    minimum, so the step that would confirm it is not taken."""
    rec = prep.rec if idx is None else subset(prep.rec, idx)
    beta = np.zeros(prep.n_params) if beta0 is None else np.array(beta0, float)
    free = list(range(len(prep.effects))) if free is None else list(free)
    offs = np.cumsum([0] + [e.size for e in prep.effects])
    fcols = np.concatenate([np.arange(offs[i], offs[i + 1]) for i in free]) if free else \
        np.zeros(0, int)
    base = fit_baseline(rec, prep.state(beta, idx), ident, start=start) if base0 is None \
        else base0
    ident = base.ident
    rss = float(np.sum(base.g ** 2))     # weighted rows (beam): what the step minimises
    it = 0
    for it in range(1, max_iter + 1):
        if not len(fcols):
            break
        X = prep.columns(base, idx, free)
        M = np.hstack([base.B, X])
        full_step = fit_linear(-base.g, M)[0]
        if float(np.sum((M @ full_step) ** 2)) <= STEP_TOL * max(rss, 1e-30):
            break
        step = full_step[base.B.shape[1]:]
        # halve the step while it does not lower the RSS (the effects enter nonlinearly)
        for _ in range(6):
            trial = beta.copy()
            trial[fcols] += step
            b2 = fit_baseline(rec, prep.state(trial, idx), ident, start=base.setup)
            rss2 = float(np.sum(b2.g ** 2))
            if rss2 <= rss * (1 + 1e-12):
                break
            step = step * 0.5
        else:
            break
        done = rss - rss2 <= STEP_TOL * max(rss, 1e-30)
        beta, base, rss = trial, b2, rss2
        if done:
            break
    return Fit(beta, base, float(np.sum(base.g_mm ** 2)), rec.n_samples, it)


def residual_at(prep: Prepared, beta: FloatArray, setup_base: Baseline, idx) -> FloatArray:
    """Residual rows (mm) of the samples ``idx`` predicted with a fitted setup and ``beta``."""
    rec = subset(prep.rec, idx)
    pred = predict_values(rec, prep.state(beta, idx), setup_base.kind, setup_base.setup)
    if rec.kind == "tracker":
        return (pred - np.asarray(rec.measured_mm, float)).ravel()
    if rec.kind == "touch":
        return (pred - setup_base.setup["point_mm"]).ravel()
    return pred


def predict_values(rec, state: State, kind: str, setup: dict, light: bool = False
                   ) -> FloatArray:
    """tracker: positions (N, 3) in the instrument frame; touch: TCP positions (N, 3) in base;
    beam: the signed distance of each trigger (N,). ``light``: the forward kinematics alone
    (the same numbers, without the DH sensitivities)."""
    robot, q = rec.robot, rec.joints_deg
    if kind == "beam":
        tool = np.asarray(setup["tool"], float)
        sens = state_sensitivities(robot, q, tool, state)
        b, v, w, edge, radius = _beam_inputs(rec)
        return _beam_constraint(sens.tcp_mm, sens.axis, b, v, w, edge, radius)
    if light:
        Rf, pf = flange_of(robot, state_frames(robot, q, state), state)
    else:
        sens = state_sensitivities(robot, q, np.eye(4), state)
        Rf, pf = sens.R_base_flange, sens.tcp_mm
    c = pf + np.einsum("nij,j->ni", Rf, np.asarray(setup["tcp_mm"], float))
    if kind == "tracker":
        R = np.asarray(setup["R_instrument_base"], float)
        return c @ R.T + np.asarray(setup["t_instrument_base"], float)
    return c


FOLD_ITER = 3   # Gauss-Newton iterations of a fold's refit (it starts at the fit on all)
FOLD_LINEAR_TOL = 1e-3   # a fold's one-step refit is kept when its nonlinear training RSS is
                         # this close (relative) to the RSS the step's linear model predicted


def heldout(prep: Prepared, cv: CV, full: Fit) -> float:
    """sqrt(mean over samples of |held-out residual|^2): the model refitted on each fold's
    training samples (from the fit on all; the setup directions the training samples determine
    checked on them, as for any fit), the left-out samples predicted with the nonlinear model
    at the fold's fit.

    A fold's refit starts at the fit on all samples, where the residual and its Jacobian
    (setup and effects) are already known: the training rows of both give a Gauss-Newton step
    (the training Gram matrix is the full one minus the left-out rows', one small solve per
    fold). The model itself is then evaluated at the stepped parameters on every sample (one
    forward kinematics): the left-out samples give the held-out residual, the training
    samples check the step. The step is the nonlinear fit's when the training RSS it reaches
    agrees with the RSS its linear model predicted to ``FOLD_LINEAR_TOL`` (the nonlinearity
    over the step is then below a thousandth of the residual, far below the 0.2 % held-out
    gain any decision uses, and a further Gauss-Newton step would change the RSS by less
    still); otherwise, and where the fold's poses do not determine every setup direction, the
    fold is refitted by :func:`fit` (Gauss-Newton from the same start). The fold's setup moves
    along the directions the fit on all samples moves along (``identify.py``), checked to be
    determined by the training poses as well.
    """
    m = full.base.m
    fast = _FoldSteps.make(prep, cv, full)
    sse = 0.0
    for te_rows, tr_rows in zip(cv.test_rows, cv.train_rows):
        r = fast.test_residual(te_rows, tr_rows) if fast is not None else None
        if r is None:
            te = np.unique(te_rows // m)
            tr = np.unique(tr_rows // m)
            f = fit(prep, tr, full.beta, max_iter=FOLD_ITER)
            r = residual_at(prep, f.beta, f.base, te)
        sse += float(r @ r)
    return float(np.sqrt(sse / prep.rec.n_samples))


@dataclass
class _FoldSteps:
    """The fit on all samples, ready for one Gauss-Newton step per fold (:func:`heldout`)."""

    prep: Prepared
    full: Fit
    J: FloatArray          # (rows, p) [setup | effects] Jacobian at the full fit
    G: FloatArray          # J^T J
    Jg: FloatArray         # J^T g
    nb: int                # setup columns (the determined directions of the fit on all)

    @classmethod
    def make(cls, prep: Prepared, cv: CV, full: Fit) -> _FoldSteps | None:
        base = full.base
        if base.kind not in ("tracker", "touch") or base.ident is None:
            return None
        J = np.hstack([base.B, prep.columns(base)]) if prep.effects else base.B
        return cls(prep, full, J, J.T @ J, J.T @ base.g, base.B.shape[1])

    def test_residual(self, te_rows, tr_rows) -> FloatArray | None:
        from solvers.analysis.identify import IDENT_TOL
        base = self.full.base
        Jt, gt = self.J[te_rows], base.g[te_rows]
        G = self.G - Jt.T @ Jt
        # do the training poses determine every setup direction the fit on all moves along
        # (identify.analyse's test on the training rows of those directions)?
        nb = self.nb
        Gb = G[:nb, :nb]
        d = np.sqrt(np.maximum(np.diag(Gb), 1e-300))
        w = np.linalg.eigvalsh(Gb / np.outer(d, d))
        if w[0] < (IDENT_TOL ** 2) * w[-1]:
            return None
        rhs = -(self.Jg - Jt.T @ gt)
        s = np.sqrt(np.maximum(np.diag(G), 1e-300))
        try:
            step = np.linalg.solve(G / np.outer(s, s), rhs / s) / s
        except np.linalg.LinAlgError:
            return None
        g_tr = base.g[tr_rows]
        J_tr = self.J[tr_rows]
        rss_lin = float(np.sum((g_tr + J_tr @ step) ** 2))
        dx = step[:nb] if base.ident.full else base.ident.basis @ step[:nb]
        setup = _stepped_setup(base, dx)
        beta = self.full.beta + step[nb:]
        rec = self.prep.rec
        pred = predict_values(rec, self.prep.state(beta), base.kind, setup, light=True)
        target = np.asarray(rec.measured_mm, float) if base.kind == "tracker" else \
            setup["point_mm"]
        r = (pred - target).ravel()
        rss_nl = float(r[tr_rows] @ r[tr_rows])
        if abs(rss_nl - rss_lin) > FOLD_LINEAR_TOL * max(rss_lin, 1e-30):
            return None
        return r[te_rows]


def _stepped_setup(base: Baseline, dx: FloatArray) -> dict:
    """The rigid setup moved by ``dx`` in the baseline's parameters (``baseline.py``: the
    tracker's rotation as a left perturbation, its translation, the TCP; the touch's TCP and
    fixed point)."""
    s = base.setup
    if base.kind == "tracker":
        from scipy.spatial.transform import Rotation
        return {"R_instrument_base": Rotation.from_rotvec(dx[:3]).as_matrix()
                @ s["R_instrument_base"],
                "t_instrument_base": s["t_instrument_base"] + dx[3:6],
                "tcp_mm": s["tcp_mm"] + dx[6:9]}
    return {"tcp_mm": s["tcp_mm"] + dx[:3], "point_mm": s["point_mm"] + dx[3:6]}


# --------------------------------------------------------------- robot-model/1 and predict


def _robot_doc(rec) -> dict:
    from solvers.recording import recording_document
    doc = recording_document(replace(rec, t_s=np.zeros(0), joints_deg=np.zeros((0, rec.robot.dof)),
                                     measured_mm=None, beam_ids=None, edges=None,
                                     tcp_velocity_mm_s=None))
    return doc


def model_document(prep: Prepared, f: Fit, report_parameters: list[dict] | None = None,
                   masses: str | None = None) -> dict:
    """The ``robot-model/1`` document of a fit (docs/analysis.md, "The model")."""
    rec = prep.rec
    doc = _robot_doc(rec)
    setup = {}
    for k, v in f.base.setup.items():
        setup[k] = np.asarray(v, float).tolist()
    if rec.kind == "beam":
        setup["sensor"] = doc.get("sensor")
    effects = []
    col = 0
    for i, e in enumerate(prep.effects):
        b = f.beta[col:col + e.size]
        col += e.size
        entry = {**e.document(), "beta": [float(x) for x in b],
                 "per_session": e.effect in SESSION_EFFECTS}
        if report_parameters is not None and i < len(report_parameters):
            entry["parameters"] = report_parameters[i]
        effects.append(entry)
    t0, t1 = time_span_of(rec)
    return {"format": MODEL_FORMAT, "kind": rec.kind, "robot": doc["robot"], "tool": doc["tool"],
            **({"payload": doc["payload"]} if "payload" in doc else {}),
            "effects": effects,
            "setup": {**setup, "time_span_s": [t0, t1]},
            "gravity_masses": masses,
            "fitted_on": {"n_samples": int(rec.n_samples), "rms_mm": round(f.rms_mm, 6),
                          **({"recorded_at": rec.recorded_at} if rec.recorded_at else {})}}


KNOWN = ("joint_offset", "link_length", "link_twist", "joint_compliance", "backlash",
         "gear_transmission_error", "thermal_drift", "trigger_latency", "tool_deflection")
SETUP_KEYS = {"tracker": {"R_instrument_base": (3, 3), "t_instrument_base": (3,), "tcp_mm": (3,)},
              "touch": {"tcp_mm": (3,), "point_mm": (3,)}, "beam": {"tool": (4, 4)}}


def _numbers(v, shape, loc) -> None:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationError(loc, "must hold numbers") from None
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise CalibrationError(loc, f"must be finite numbers of shape {list(shape)}")


def _check_model(model: dict) -> None:
    """A clear error naming the field for anything :func:`predict` cannot use."""
    if not isinstance(model, dict) or model.get("format") != MODEL_FORMAT:
        raise CalibrationError(("format",), f"must be {MODEL_FORMAT!r} (a model written by "
                               "pendant analyze --save-model)")
    for key in ("kind", "robot", "effects", "setup"):
        if key not in model:
            raise CalibrationError((key,), "missing from the model")
    if model["kind"] not in SETUP_KEYS:
        raise CalibrationError(("kind",), "must be touch, tracker or beam")
    if not isinstance(model["robot"], dict) or not isinstance(model["robot"].get("joints"), list):
        raise CalibrationError(("robot", "joints"), "must be the DH table of the robot")
    if not isinstance(model["effects"], list):
        raise CalibrationError(("effects",), "must be a list")
    n = len(model["robot"]["joints"])
    for i, e in enumerate(model["effects"]):
        if not isinstance(e, dict) or e.get("effect") not in KNOWN:
            raise CalibrationError(("effects", i, "effect"), "must be one of " + ", ".join(KNOWN))
        j = e.get("joint")
        if j is not None and (not isinstance(j, int) or not 1 <= j <= n):
            raise CalibrationError(("effects", i, "joint"), f"must be 1..{n} or null")
        needs_joint = e["effect"] not in ("thermal_drift", "trigger_latency", "tool_deflection")
        if needs_joint and j is None:
            raise CalibrationError(("effects", i, "joint"), f"{e['effect']} needs a joint")
        if e["effect"] == "link_length" and e.get("dh_parameter") not in ("a", "d"):
            raise CalibrationError(("effects", i, "dh_parameter"), "must be 'a' or 'd'")
        if e["effect"] == "gear_transmission_error" and (
                not isinstance(e.get("periods_per_turn"), int) or e["periods_per_turn"] < 1):
            raise CalibrationError(("effects", i, "periods_per_turn"), "must be an integer >= 1")
        tau = e.get("tau_s")
        if tau is not None and (not isinstance(tau, (int, float)) or not tau > 0):
            raise CalibrationError(("effects", i, "tau_s"), "must be a positive number or null")
        size = Effect(e["effect"]).size
        _numbers(e.get("beta"), (size,), ("effects", i, "beta"))
    setup = model["setup"]
    if not isinstance(setup, dict):
        raise CalibrationError(("setup",), "must be an object")
    for key, shape in SETUP_KEYS[model["kind"]].items():
        if key not in setup:
            raise CalibrationError(("setup", key), "missing from the model")
        _numbers(setup[key], shape, ("setup", key))
    if "time_span_s" in setup:
        _numbers(setup["time_span_s"], (2,), ("setup", "time_span_s"))


def _same_robot(model: dict, rec) -> None:
    joints = model["robot"].get("joints", [])
    if len(joints) != rec.robot.dof:
        raise CalibrationError(("robot", "joints"), f"the model's robot has {len(joints)} "
                               f"joints, the recording's {rec.robot.dof}: not the same robot")
    mine = _robot_doc(rec)["robot"]["joints"]
    for i, (a, b) in enumerate(zip(joints, mine)):
        for k in ("a_mm", "alpha_deg", "d_mm", "offset_deg"):
            if not isinstance(a, dict) or abs(float(a.get(k, 0.0)) - float(b.get(k, 0.0))) > 1e-6:
                raise CalibrationError(("robot", "joints", i, k), "differs between the model and "
                                       "the recording: not the same robot's nominal model")
    if model["kind"] != rec.kind:
        raise CalibrationError(("kind",), f"the model was fitted on a {model['kind']} recording; "
                               f"this one is {rec.kind}: the setup does not carry over")


def prepared_from_model(model: dict, rec, time_span=None) -> tuple[Prepared, FloatArray]:
    lm = model["robot"].get("link_masses")
    if isinstance(lm, dict) and getattr(rec, "link_masses", None) is None:
        from solvers.gravity import LinkMasses  # the masses the model was fitted with
        rec = replace(rec, link_masses=LinkMasses(
            tuple(float(x) for x in lm["mass_kg"]),
            None if lm.get("com_mm") is None else tuple(tuple(map(float, c)) for c in lm["com_mm"]),
            "the model's link masses"))
    effects, beta = [], []
    for e in model["effects"]:
        effects.append(Effect(e["effect"], e.get("joint"), e.get("dh_parameter"),
                              e.get("periods_per_turn"), e.get("tau_s")))
        beta.extend(float(x) for x in e["beta"])
    span = tuple(model["setup"].get("time_span_s", time_span_of(rec))) if time_span is None \
        else time_span
    return Prepared.make(rec, effects, time_span=span), np.asarray(beta, float)


def _setup_of(model: dict) -> dict:
    s = model["setup"]
    out = {k: np.asarray(v, float) for k, v in s.items() if k not in ("sensor", "time_span_s")}
    return out


def predict(model: dict, rec, refit_setup: bool = False) -> dict:
    """The ``prediction/1`` document of a recording with a saved model (module docstring)."""
    _check_model(model)
    _same_robot(model, rec)
    kind = rec.kind
    has_meas = kind != "tracker" or rec.measured_mm is not None
    out: dict = {"format": PREDICTION_FORMAT, "n_samples": int(rec.n_samples),
                 "refit_setup": bool(refit_setup)}
    if refit_setup:
        if kind == "tracker" and rec.measured_mm is None:
            raise CalibrationError(("samples", 0, "measured_mm"), "--refit-setup needs the "
                                   "recording's measurements to fit the setup to")
        # a new session: the per-session terms start again at this recording's own span
        prep, beta = prepared_from_model(model, rec, time_span_of(rec))
        free = [i for i, e in enumerate(prep.effects) if e.effect in SESSION_EFFECTS]
        b0 = beta.copy()
        offs = np.cumsum([0] + [e.size for e in prep.effects])
        for i in free:
            b0[offs[i]:offs[i + 1]] = 0.0
        f = fit(prep, None, b0, free)
        setup, beta = f.base.setup, f.beta
        out["setup"] = {k: np.asarray(v, float).tolist() for k, v in setup.items()}
        session = {prep.effects[i].key: [float(x) for x in beta[offs[i]:offs[i + 1]]]
                   for i in free}
        if session:
            out["setup"]["per_session_beta"] = session
    else:
        prep, beta = prepared_from_model(model, rec)
        setup = _setup_of(model)
    pred = predict_values(rec, prep.state(beta), kind, setup)
    out["predicted"] = np.round(pred, 6).tolist()
    if kind == "tracker" and has_meas:
        r = pred - np.asarray(rec.measured_mm, float)
        out["rms_mm"] = round(float(np.sqrt(np.mean(np.sum(r ** 2, axis=1)))), 6)
    elif kind == "touch":
        r = pred - np.asarray(setup["point_mm"], float)
        out["rms_mm"] = round(float(np.sqrt(np.mean(np.sum(r ** 2, axis=1)))), 6)
    elif kind == "beam":
        out["rms_mm"] = round(float(np.sqrt(np.mean(pred ** 2))), 6)
    return out


__all__ = [
    "Effect",
    "Fit",
    "Prepared",
    "fit",
    "heldout",
    "model_document",
    "per_sample_rms",
    "predict",
]
