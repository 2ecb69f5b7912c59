"""The rigid baseline of each recording kind, fitted by nonlinear least squares.

Every kind is written as a constraint ``g_k(b) = 0`` that a rigid robot would meet exactly at
each sample k, where b holds the kind's free parameters:

- ``tracker``: ``g_k = T_instrument_base · T_base_flange(q_k) · p_tcp - measured_k`` (3 rows);
  b = rotation vector and translation of ``T_instrument_base`` (6) and ``p_tcp`` (3).
- ``touch``: ``g_k = T_base_flange(q_k) · p_tcp - s`` (3 rows); b = ``p_tcp`` (3), fixed point s (3).
- ``beam``: one row per trigger: for ``enter``/``leave`` the signed distance between the tool
  axis and the beam line along their common normal (pointed along the motion) plus / minus
  the shaft radius; for ``tip`` the TCP's distance from the plane through the beam line
  perpendicular to the motion; b = TCP position (3) and the tool axis's tilt (2) in the flange.

Besides the fit this module gives the per-sample sensitivity ``S_k = dg_k / d(TCP twist)``
(rows x 6: TCP displacement mm, tool rotation rad, base frame), through which every physical
effect enters the residual (``effects.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from solvers.analysis.identify import Identifiability, analyse
from solvers.analysis.kinematics import (Sensitivities, State, flange_of, state_frames,
                                         state_sensitivities)
from solvers.errors import CalibrationError
from solvers.validate import FloatArray

MAX_GN = 12     # Gauss-Newton steps of the tracker's setup


@dataclass
class Baseline:
    """A fitted rigid model: residual ``g`` (rows), its Jacobian ``B`` w.r.t. the baseline
    parameters, the per-sample sensitivity ``S`` (N, m, 6) and the kinematics ``sens``."""

    kind: str
    g: FloatArray                 # (N*m,) residual, model minus measurement
    B: FloatArray                 # (N*m, p)
    S: FloatArray                 # (N, m, 6)
    m: int                        # rows per sample
    sens: Sensitivities
    tool: FloatArray              # fitted T_flange_tcp (4x4)
    parameters: dict[str, float] = field(default_factory=dict)
    R_instrument_base: FloatArray = field(default_factory=lambda: np.eye(3))
    blocks: dict[str, slice] = field(default_factory=dict)  # columns of B by what they fit
    w: FloatArray | None = None   # row weights already applied to g, B and S (beam), else None
    ident: Identifiability | None = None   # which parameters the poses determine
    setup: dict = field(default_factory=dict)   # raw fitted setup (``model.py`` predicts with it)
    B_full: FloatArray | None = None   # B before the undetermined directions were dropped

    @property
    def row_scale(self) -> FloatArray:
        """Multiply a (weighted) residual row by this to get mm again."""
        return np.ones(self.g.size) if self.w is None else 1.0 / self.w

    @property
    def g_mm(self) -> FloatArray:
        """The residual in mm (unweighted)."""
        return self.g * self.row_scale

    @property
    def n_samples(self) -> int:
        return self.S.shape[0]

    def rows(self, samples: FloatArray) -> FloatArray:
        """Residual row indices of the given samples."""
        s = np.asarray(samples, dtype=int)
        return (s[:, None] * self.m + np.arange(self.m)[None, :]).ravel()


def skew_cols(v: FloatArray) -> FloatArray:
    """(N, 3, 3) matrices whose columns are e_i x v (d(w x v)/dw)."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out[..., 0, 1], out[..., 0, 2] = z, -y
    out[..., 1, 0], out[..., 1, 2] = -z, x
    out[..., 2, 0], out[..., 2, 1] = y, -x
    return out


def per_sample_rms(g: FloatArray, m: int) -> FloatArray:
    """|r_k| per sample (length of the 3-vector, or |scalar| for beam)."""
    return np.sqrt(np.sum(np.reshape(g, (-1, m)) ** 2, axis=1))


def rms_mm(g: FloatArray, m: int) -> float:
    """sqrt(mean_k |r_k|^2) of a stacked residual with m rows per sample.

    Examples
    --------
    >>> rms_mm(np.array([3.0, 4.0, 0.0, 0.0, 0.0, 0.0]), 3)  # |r_0| = 5, |r_1| = 0
    3.5355339059327378
    """
    return float(np.sqrt(np.sum(g ** 2) / (g.size / m)))


def _kabsch(A: FloatArray, B: FloatArray) -> tuple[FloatArray, FloatArray]:
    """R, t minimising |R A + t - B|."""
    a0, b0 = A.mean(0), B.mean(0)
    U, _, Vt = np.linalg.svd((A - a0).T @ (B - b0))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, b0 - R @ a0


def fit_tracker(rec, state: State | None = None, ident: Identifiability | None = None,
                start: dict | None = None) -> Baseline:
    robot, q, meas = rec.robot, rec.joints_deg, np.asarray(rec.measured_mm, float)
    tool0 = np.asarray(rec.tool, float)
    F = state_frames(robot, q, state)
    Rf, pf = flange_of(robot, F, state)                # flange pose in base
    if start is not None and ident is not None:
        # warm start at a fitted setup (found along the same determined directions)
        R0, t0 = np.asarray(start["R_instrument_base"], float), \
            np.asarray(start["t_instrument_base"], float)
        tcp0 = np.asarray(start["tcp_mm"], float)
    else:
        R0, t0 = _kabsch(pf + Rf @ tool0[:3, 3], meas)
        tcp0 = tool0[:3, 3]

    def model(x):
        R = Rotation.from_rotvec(x[:3]).as_matrix() @ R0
        c = pf + Rf @ x[6:9]
        return R, c, c @ R.T + x[3:6]

    def fun(x):
        return (model(x)[2] - meas).ravel()

    def jac(x):
        R, c, pred = model(x)
        N = len(q)
        J = np.zeros((N, 3, 9))
        J[:, :, 0:3] = skew_cols(pred - x[3:6])     # left perturbation of the rotation
        J[:, :, 3:6] = np.eye(3)
        J[:, :, 6:9] = R @ Rf
        return J.reshape(3 * N, 9)

    x0 = np.concatenate([np.zeros(3), t0, tcp0])
    names = ["instrument_rx", "instrument_ry", "instrument_rz", "instrument_x_mm",
             "instrument_y_mm", "instrument_z_mm", "tcp_x_mm", "tcp_y_mm", "tcp_z_mm"]
    if ident is None:
        ident = analyse(jac(x0), names, {"the instrument frame": slice(0, 6),
                                         "the TCP": slice(6, 9)})
    P = ident.basis          # the fit moves only along the determined directions
    # Gauss-Newton along the determined directions; the rotation is re-centred after each
    # step, so the left-perturbation Jacobian is exact (quadratic convergence)
    for _ in range(MAX_GN):
        R, c, pred = model(x0)
        r = (pred - meas).ravel()
        J = np.zeros((len(q), 3, 9))
        J[:, :, 0:3] = skew_cols(pred - x0[3:6])
        J[:, :, 3:6] = np.eye(3)
        J[:, :, 6:9] = R @ Rf
        J = J.reshape(-1, 9) @ P
        G = J.T @ J
        d = np.sqrt(np.maximum(np.diag(G), 1e-300))
        dz = -np.linalg.lstsq((G / np.outer(d, d)), (J.T @ r) / d, rcond=1e-12)[0] / d
        xs = x0 + P @ dz
        R0 = Rotation.from_rotvec(xs[:3]).as_matrix() @ R0
        x0 = np.concatenate([np.zeros(3), xs[3:]])
        # the step's size in the residual (mm, root-sum-square over all rows)
        if np.linalg.norm(J @ dz) < 1e-9 * max(np.sqrt(len(q)), 1.0):
            break
    x = x0
    R, c, pred = model(x)
    tool = tool0.copy()
    tool[:3, 3] = x[6:9]
    sens = state_sensitivities(robot, q, tool, state, frames=F)
    N = len(q)
    S = np.zeros((N, 3, 6))
    S[:, :, :3] = R
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, x[3:6]
    from solvers.frames import kuka_from_matrix
    v = kuka_from_matrix(T)
    params = {f"instrument_{k}": float(val) for k, val in zip(
        ("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg"), v)}
    params.update({"tcp_x_mm": x[6], "tcp_y_mm": x[7], "tcp_z_mm": x[8]})
    Jx = jac(x)
    return Baseline("tracker", (pred - meas).ravel(), Jx if ident.full else Jx @ P, S, 3, sens, tool,
                    {k: float(v) for k, v in params.items()}, R,
                    {"the instrument frame": slice(0, 6), "the TCP": slice(6, 9)},
                    ident=ident, setup={"R_instrument_base": R, "t_instrument_base": x[3:6].copy(),
                                        "tcp_mm": x[6:9].copy()}, B_full=Jx)


def fit_touch(rec, state: State | None = None, ident: Identifiability | None = None,
              start: dict | None = None) -> Baseline:
    robot, q = rec.robot, rec.joints_deg
    tool0 = np.asarray(rec.tool, float)
    F = state_frames(robot, q, state)
    Rf, pf = flange_of(robot, F, state)
    N = len(q)

    def fun(x):
        return (pf + Rf @ x[:3] - x[3:6]).ravel()

    def jac(x):
        J = np.zeros((N, 3, 6))
        J[:, :, :3] = Rf
        J[:, :, 3:] = -np.eye(3)
        return J.reshape(3 * N, 6)

    x0 = np.concatenate([tool0[:3, 3], np.mean(pf + Rf @ tool0[:3, 3], axis=0)])
    if ident is None:
        ident = analyse(jac(x0), ["tcp_x_mm", "tcp_y_mm", "tcp_z_mm", "point_x_mm",
                                  "point_y_mm", "point_z_mm"],
                        {"the TCP": slice(0, 3), "the fixed point": slice(3, 6)})
    P = ident.basis
    J = jac(x0) @ P                  # the touch constraint is linear in its parameters
    x = x0 - P @ np.linalg.lstsq(J, fun(x0), rcond=1e-12)[0]
    tool = tool0.copy()
    tool[:3, 3] = x[:3]
    sens = state_sensitivities(robot, q, tool, state, frames=F)
    S = np.zeros((N, 3, 6))
    S[:, :, :3] = np.eye(3)
    params = {"tcp_x_mm": x[0], "tcp_y_mm": x[1], "tcp_z_mm": x[2],
              "point_x_mm": x[3], "point_y_mm": x[4], "point_z_mm": x[5]}
    Jx = jac(x)
    return Baseline("touch", fun(x), Jx if ident.full else Jx @ P, S, 3, sens, tool,
                    {k: float(v) for k, v in params.items()},
                    blocks={"the TCP": slice(0, 3), "the fixed point": slice(3, 6)},
                    ident=ident, setup={"tcp_mm": x[:3].copy(), "point_mm": x[3:6].copy()},
                    B_full=Jx)


def _beam_constraint(c, u, b, v, w, edge, radius):
    """g per trigger (N,) from TCP c, tool axis u, beam point b / direction v, velocity w."""
    n = np.cross(u, v)
    nn = np.linalg.norm(n, axis=1, keepdims=True)
    n = n / np.maximum(nn, 1e-12)
    s = np.sign(np.sum(n * w, axis=1))
    s[s == 0] = 1.0
    dist = s * np.sum((c - b) * n, axis=1)
    # tip: the TCP on the plane through the beam LINE perpendicular to the motion; its normal
    # is the motion without its component along the beam (as solvers/light_barrier.py, eq. 3)
    wp = w - np.sum(w * v, axis=1, keepdims=True) * v
    wn = wp / np.maximum(np.linalg.norm(wp, axis=1, keepdims=True), 1e-12)
    tip = np.sum((c - b) * wn, axis=1)
    return np.where(edge == 0, dist + radius, np.where(edge == 1, dist - radius, tip))


def _beam_inputs(rec):
    ids = list(rec.beam_ids)
    beams = rec.beams
    b = np.array([np.asarray(beams[i][0], float) for i in ids])
    v = np.array([np.asarray(beams[i][1], float) for i in ids])
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    edge = np.array([{"enter": 0, "leave": 1, "tip": 2}[e] for e in rec.edges])
    w = np.asarray(rec.tcp_velocity_mm_s, float)
    return b, v, w, edge, 0.5 * float(rec.tool_diameter_mm)


def beam_sensitivity(c, u, b, v, w, edge, radius) -> FloatArray:
    """dg/d(TCP twist) (N, 1, 6) by central differences (the constraint is cheap)."""
    N = len(c)
    S = np.zeros((N, 1, 6))
    h = 1e-4
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        S[:, 0, i] = (_beam_constraint(c + e, u, b, v, w, edge, radius)
                      - _beam_constraint(c - e, u, b, v, w, edge, radius)) / (2 * h)
        up, um = u + np.cross(e, u), u - np.cross(e, u)
        S[:, 0, 3 + i] = (_beam_constraint(c, up, b, v, w, edge, radius)
                          - _beam_constraint(c, um, b, v, w, edge, radius)) / (2 * h)
    return S


def fit_beam(rec, state: State | None = None, ident: Identifiability | None = None,
             start: dict | None = None) -> Baseline:
    robot, q = rec.robot, rec.joints_deg
    tool0 = np.asarray(rec.tool, float)
    b, v, w, edge, radius = _beam_inputs(rec)
    sens0 = state_sensitivities(robot, q, np.eye(4), state)
    Rf, pf = sens0.R_base_flange, sens0.tcp_mm
    a0 = tool0[:3, 2]
    e1 = np.cross(a0, [1.0, 0, 0]) if abs(a0[0]) < 0.9 else np.cross(a0, [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a0, e1)

    def axis_of(x):
        a = a0 + x[3] * e1 + x[4] * e2
        return a / np.linalg.norm(a)

    def fun(x):
        c = pf + Rf @ x[:3]
        u = Rf @ axis_of(x)
        return _beam_constraint(c, u, b, v, w, edge, radius)

    x0 = np.concatenate([tool0[:3, 3], [0.0, 0.0]])
    sol = least_squares(fun, x0, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12,
                        x_scale=np.array([1, 1, 1, 1e-2, 1e-2]))
    x = sol.x
    a = axis_of(x)
    tool = tool0.copy()
    tool[:3, 3] = x[:3]
    # rotate the nominal tool so its z axis is the fitted axis (smallest rotation)
    rv = np.cross(a0, a)
    sn = np.linalg.norm(rv)
    if sn > 1e-15:
        ang = np.arctan2(sn, float(a0 @ a))
        tool[:3, :3] = Rotation.from_rotvec(rv / sn * ang).as_matrix() @ tool0[:3, :3]
    sens = state_sensitivities(robot, q, tool, state)
    c, u = sens.tcp_mm, sens.axis
    S = beam_sensitivity(c, u, b, v, w, edge, radius)
    # Jacobian of g w.r.t. the 5 baseline parameters through the sensitivity
    N = len(q)
    B = np.zeros((N, 5))
    B[:, :3] = np.einsum("nk,nkj->nj", S[:, 0, :3], Rf)
    for k, e in enumerate((e1, e2)):
        du_flange = e - a * (a @ e)
        # rotation of the axis in base that moves u by Rf du: w = u x (Rf du)
        wv = np.cross(u, Rf @ du_flange)
        B[:, 3 + k] = np.einsum("nk,nk->n", S[:, 0, 3:], wv)
    runout = float(np.degrees(np.arccos(np.clip(a @ a0, -1, 1))))
    params = {"tcp_x_mm": x[0], "tcp_y_mm": x[1], "tcp_z_mm": x[2],
              "axis_x": a[0], "axis_y": a[1], "axis_z": a[2], "runout_deg": runout}
    # A trigger's error is a position error along the motion (timing jitter): weight each row
    # by 1 / |dg/d(shift along the motion)| so that every row's noise is in mm along the
    # motion (homoscedastic); reported RMS values are unweighted again (``row_scale``).
    wn = w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-12)
    wt = 1.0 / np.maximum(np.abs(np.einsum("ni,ni->n", S[:, 0, :3], wn)), 0.05)
    S = S * wt[:, None, None]
    B = B * wt[:, None]
    return Baseline("beam", fun(x) * wt, B, S, 1, sens, tool,
                    {k: float(val) for k, val in params.items()},
                    blocks={"the TCP position": slice(0, 3), "the tool axis": slice(3, 5)},
                    w=wt, ident=analyse(B, ["tcp_x_mm", "tcp_y_mm", "tcp_z_mm", "axis_tilt_1",
                                            "axis_tilt_2"],
                                        {"the TCP position": slice(0, 3),
                                         "the tool axis": slice(3, 5)}),
                    setup={"tool": tool.copy()})


def fit_baseline(rec, state: State | None = None, ident: Identifiability | None = None,
                 start: dict | None = None) -> Baseline:
    """The kind's rigid fit (dispatch on ``rec.kind``), optionally with effects applied;
    ``ident``: the determined directions to fit along (default: found on this recording);
    ``start``: a fitted ``setup`` to start the iteration at (tracker; with ``ident``)."""
    fits = {"tracker": fit_tracker, "touch": fit_touch, "beam": fit_beam}
    if rec.kind not in fits:
        raise CalibrationError(("kind",), f"must be touch, tracker or beam, got {rec.kind!r}")
    return fits[rec.kind](rec, state, ident, start)
