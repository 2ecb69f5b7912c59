"""Which poses to measure: a D-optimal set of joint configurations for chosen effects.

For a tracker (or touch) recording the analysis fits, to first order,
``y = B b + E e + noise`` (``baseline.py``, ``effects.py``): ``b`` the nuisance parameters
(tracker: the instrument frame and the TCP; touch: the TCP and the touched point), ``e`` the
chosen effects' parameters. The covariance of the estimate of ``e`` with ``b`` profiled out is
``sigma^2 (E^T (I - P_B) E)^-1``, and its determinant is the generalised variance. A
*D-optimal* design maximises

    log det(X^T X) - log det(B^T B),   X = [B E]

(the log-determinant of the Schur complement ``E^T (I - P_B) E``; Atkinson, Donev & Tobias,
*Optimum Experimental Designs, with SAS*, Oxford 2007, ch. 10-11, where this is the
D_s-optimal design for a parameter subset; applied to robot calibration by Borm & Menq,
"Determination of optimal measurement configurations for robot calibration based on
observability measure", IJRR 10(1):51-63, 1991). Columns may be scaled freely (the criterion
changes by a constant), so mm, degrees and deg/Nm mix without care.

The pool: random joint configurations within the joint limits (a margin inside), with the TCP
inside the workspace box and above the floor (``z > floor``, base frame), and a well
conditioned Jacobian; for ``touch`` the TCP on one point (the box's centre) with the tool
tilted up to 50 deg from straight down. The design: greedy selection (each step the pose
that raises the criterion most, by the matrix determinant lemma over the whole pool), then
Fedorov exchange passes (swap a design pose for a pool pose while the criterion rises;
Fedorov, *Theory of Optimal Experiments*, 1972). Effects not identifiable from any pose
(absorbed by the nuisance parameters) are left out and listed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy.spatial.transform import Rotation

from solvers.analysis.baseline import fit_baseline
from solvers.analysis.effects import build_library
from solvers.analysis.screen import IDENT_TOL, screen
from solvers.analysis.selection import normalise, orth, project_out
from solvers.dh import RobotModel, forward_kinematics, geometric_jacobian
from solvers.errors import CalibrationError
from solvers.recording import RecordingData
from solvers.validate import FloatArray

PLANNABLE = ("joint_offset", "link_length", "link_twist", "joint_compliance", "tool_deflection")
INSTRUMENTS = ("tracker", "touch")
MAX_COND = 200.0   # Jacobian condition number (positions scaled by the reach) of a pool pose
RIDGE = 1e-9       # relative regularisation while the design is still too small to be regular


@dataclass(frozen=True)
class Workspace:
    """An axis-aligned box in the robot base frame (mm) and the floor height."""

    lo: FloatArray
    hi: FloatArray
    floor_mm: float

    @classmethod
    def default(cls, robot: RobotModel) -> "Workspace":
        """A box in front of the robot: x 0.3..0.8 reach, y +-0.5 reach, z floor..0.7 reach."""
        R = robot.reach_mm or 1000.0
        z0 = float(robot.base_pose.z)
        return cls(np.array([0.3 * R, -0.5 * R, z0]), np.array([0.8 * R, 0.5 * R, z0 + 0.7 * R]),
                   z0)

    @classmethod
    def parse(cls, text: str, robot: RobotModel) -> "Workspace":
        """``"xmin,ymin,zmin,xmax,ymax,zmax"`` in mm, base frame (the floor: the base's z)."""
        try:
            v = np.array([float(x) for x in str(text).split(",")])
        except ValueError:
            v = np.zeros(0)
        if v.size != 6 or not np.all(np.isfinite(v)) or np.any(v[3:] <= v[:3]):
            raise CalibrationError(("workspace",), "must be 'xmin,ymin,zmin,xmax,ymax,zmax' in mm "
                                   f"with each max above its min, got {text!r}")
        return cls(v[:3], v[3:], float(robot.base_pose.z))


def parse_effects(specs: list[str], n_joints: int) -> list[tuple[str, int | None]]:
    """``["joint_compliance:2", "link_length", ...]`` -> (effect, joint or None for all)."""
    out = []
    for spec in specs:
        for item in str(spec).replace(" ", ",").split(","):
            if not item:
                continue
            name, _, joint = item.partition(":")
            if name not in PLANNABLE:
                raise CalibrationError(("effects", item), "plannable effects are "
                                       + ", ".join(PLANNABLE) + " (optionally ':joint'); "
                                       "backlash and thermal drift depend on the order and "
                                       "time of the motion, not on the poses")
            if joint and (not joint.isdigit() or not 1 <= int(joint) <= n_joints):
                raise CalibrationError(("effects", item), f"joint must be 1..{n_joints}")
            out.append((name, int(joint) if joint else None))
    if not out:
        raise CalibrationError(("effects",), "name at least one effect, e.g. joint_compliance:2")
    return out


def _well_conditioned(robot: RobotModel, q: FloatArray, tool: FloatArray) -> FloatArray:
    J = geometric_jacobian(robot, q, tool).copy()
    J[..., :3, :] /= robot.reach_mm or 1000.0
    s = np.linalg.svd(J, compute_uv=False)
    return s[..., 0] / np.maximum(s[..., -1], 1e-12) < MAX_COND


def tracker_pool(robot: RobotModel, tool: FloatArray, ws: Workspace, n_pool: int,
                 rng: np.random.Generator, margin_deg: float = 5.0) -> FloatArray:
    """Random reachable joint configurations with the TCP in the box, above the floor."""
    lim = robot.limits_deg()
    lo = np.maximum(lim[:, 0], -360.0) + margin_deg
    hi = np.minimum(lim[:, 1], 360.0) - margin_deg
    found: list[FloatArray] = []
    for _ in range(400):
        Q = rng.uniform(lo, hi, (2000, robot.dof))
        p = forward_kinematics(robot, Q, tool)[:, :3, 3]
        ok = np.all((p >= ws.lo) & (p <= ws.hi), axis=1) & (p[:, 2] > ws.floor_mm)
        if np.any(ok):
            ok[ok] = _well_conditioned(robot, Q[ok], tool)
        found.extend(Q[ok])
        if len(found) >= n_pool:
            break
    if len(found) < 10:
        raise CalibrationError(("workspace",), f"found only {len(found)} reachable, well "
                               "conditioned poses with the TCP inside the box: widen it")
    return np.array(found[:n_pool])


def solve_ik(robot: RobotModel, tool: FloatArray, goals: FloatArray, seeds: FloatArray,
             iterations: int = 40) -> FloatArray:
    """Joint values (N, n) reaching the TCP poses ``goals`` (N, 4, 4) from ``seeds`` (N, n):
    damped least-squares Newton steps, all at once (Wampler, "Manipulator inverse kinematic
    solutions based on vector formulations and damped least-squares methods", IEEE SMC
    16(1):93-101, 1986). Check the result: a seed may converge elsewhere or not at all."""
    R = robot.reach_mm or 1000.0
    q = np.array(seeds, dtype=float)
    for _ in range(iterations):
        T = forward_kinematics(robot, q, tool)
        e = np.concatenate([goals[:, :3, 3] - T[:, :3, 3], Rotation.from_matrix(
            goals[:, :3, :3] @ np.swapaxes(T[:, :3, :3], 1, 2)).as_rotvec() * R], axis=1)
        J = geometric_jacobian(robot, q, tool).copy()
        J[:, 3:, :] *= R
        JJt = J @ np.swapaxes(J, 1, 2) + (1e-3 * R) ** 2 * np.eye(6)
        dq = np.swapaxes(J, 1, 2) @ np.linalg.solve(JJt, e[:, :, None])
        q = q + np.degrees(dq[:, :, 0])
    return q


def reached(robot: RobotModel, tool: FloatArray, q: FloatArray, goals: FloatArray,
            margin_deg: float = 5.0, tol_mm: float = 1e-6) -> FloatArray:
    """Which solutions reach their goal position, stay inside the limits and are well
    conditioned (boolean (N,))."""
    lim = robot.limits_deg()
    T = forward_kinematics(robot, q, tool)
    ok = (np.linalg.norm(T[:, :3, 3] - goals[:, :3, 3], axis=1) < tol_mm) \
        & np.all((q >= lim[:, 0] + margin_deg) & (q <= lim[:, 1] - margin_deg), axis=1)
    if np.any(ok):
        ok[ok] = _well_conditioned(robot, q[ok], tool)
    return ok


def tool_down(n: int, rng: np.random.Generator, max_tilt_deg: float = 50.0) -> FloatArray:
    """(n, 3, 3) tool orientations: straight down, tilted 0..max about a random horizontal
    axis, turned about the tool axis at random."""
    az = rng.uniform(0, 2 * np.pi, n)
    tilt = np.radians(rng.uniform(0, max_tilt_deg, n))
    axes = np.stack([np.cos(az), np.sin(az), np.zeros(n)], 1) * tilt[:, None]
    return (Rotation.from_rotvec(axes) * Rotation.from_euler("x", 180.0, degrees=True)
            * Rotation.from_euler("z", rng.uniform(-180, 180, (n, 1)), degrees=True)).as_matrix()


def touch_pool(robot: RobotModel, tool: FloatArray, ws: Workspace, n_pool: int,
               rng: np.random.Generator, margin_deg: float = 5.0) -> FloatArray:
    """Joint configurations that put the TCP on the box's centre with the tool tilted 0..50
    deg from straight down (:func:`tool_down`), solved from random reachable configurations
    near the point (:func:`solve_ik`)."""
    point = 0.5 * (ws.lo + ws.hi)
    R = robot.reach_mm or 1000.0
    near = Workspace(point - 0.25 * R, point + 0.25 * R, ws.floor_mm)
    out: list[FloatArray] = []
    for _ in range(10):
        seeds = tracker_pool(robot, tool, near, 4 * n_pool, rng, margin_deg)
        goals = np.tile(np.eye(4), (len(seeds), 1, 1))
        goals[:, :3, :3] = tool_down(len(seeds), rng)
        goals[:, :3, 3] = point
        q = solve_ik(robot, tool, goals, seeds)
        out.extend(q[reached(robot, tool, q, goals, margin_deg)])
        if len(out) >= n_pool:
            break
    if len(out) < 10:
        raise CalibrationError(("workspace",), "found fewer than 10 ways to touch the box's "
                               f"centre {np.round(point, 1).tolist()} mm: move the box")
    return np.array(out[:n_pool])


def _recording(robot, joints, tool, instrument, payload) -> RecordingData:
    """A noise-free recording of the nominal robot at ``joints`` (the design's linearisation)."""
    p = forward_kinematics(robot, joints, tool)[:, :3, 3]
    N = len(joints)
    return RecordingData(kind=instrument, robot=robot, tool=tool, payload_mass_kg=float(payload[0]),
                         payload_com_mm=np.asarray(payload[1], float), start_joints_deg=None,
                         t_s=np.arange(N, dtype=float), joints_deg=np.asarray(joints, float),
                         measured_mm=p if instrument == "tracker" else None)


def design_matrices(robot, joints, tool, instrument, payload, effects
                    ) -> tuple[FloatArray, FloatArray, list[str], int, list[str]]:
    """(B, E, effect parameter keys, rows per pose, keys not identifiable on any pose) of
    the candidate poses; an effect is screened as the analysis screens it (``screen.py``)."""
    rec = _recording(robot, joints, tool, instrument, payload)
    base = fit_baseline(rec)
    lib = build_library(rec, base, include_twist=True)
    wanted = [c for c in lib.candidates if c.effect in PLANNABLE
              and any(c.effect == e and (j is None or c.joint == j) for e, j in effects)]
    if not wanted:
        raise CalibrationError(("effects",), "none of these effects acts on this robot's "
                               "poses (tool_deflection needs a payload)")
    ok = screen(rec, base, orth(base.B), wanted).candidates
    dropped = [c.key for c in wanted if c not in ok]
    if not ok:
        raise CalibrationError(("effects",), "none of these effects is identifiable with a "
                               f"{instrument}: " + ", ".join(dropped))
    return base.B, np.hstack([c.columns for c in ok]), [c.key for c in ok], base.m, dropped


def _criterion(A_full: FloatArray, A_nuis: FloatArray) -> float:
    s1, l1 = np.linalg.slogdet(A_full)
    s2, l2 = np.linalg.slogdet(A_nuis)
    return float(l1 - l2) if s1 > 0 and s2 > 0 else -np.inf


def _gains(Ainv: FloatArray, U: FloatArray) -> FloatArray:
    """log det(I + U_i A^-1 U_i^T) for every pool pose i (matrix determinant lemma)."""
    S = (U @ Ainv) @ np.swapaxes(U, 1, 2) + np.eye(U.shape[1])
    return np.linalg.slogdet(S)[1]


def d_optimal(X: FloatArray, nb: int, m: int, n: int, rng: np.random.Generator,
              passes: int = 3) -> list[int]:
    """Indices of ``n`` poses (rows ``m`` each of ``X = [B E]``, B the first ``nb`` columns)
    maximising log det(X_S^T X_S) - log det(B_S^T B_S): greedy, then Fedorov exchange."""
    P = X.shape[0] // m
    U = X.reshape(P, m, -1)
    Ub = U[:, :, :nb]
    scale = np.sum(X ** 2, axis=0) / P
    ridge_f, ridge_b = np.diag(RIDGE * scale), np.diag(RIDGE * scale[:nb])

    def info(sel):
        Us = U[sel].reshape(-1, U.shape[2])
        return Us.T @ Us + ridge_f, Us[:, :nb].T @ Us[:, :nb] + ridge_b

    chosen = [int(rng.integers(P))]
    while len(chosen) < n:
        Af, Ab = info(chosen)
        g = _gains(np.linalg.inv(Af), U) - _gains(np.linalg.inv(Ab), Ub)
        g[chosen] = -np.inf
        chosen.append(int(np.argmax(g)))
    best = _criterion(*info(chosen))
    for _ in range(passes):
        improved = False
        for pos in range(n):
            rest = chosen[:pos] + chosen[pos + 1:]
            Af, Ab = info(rest)
            g = _gains(np.linalg.inv(Af), U) - _gains(np.linalg.inv(Ab), Ub)
            g[rest] = -np.inf
            cand = int(np.argmax(g))
            trial = rest[:pos] + [cand] + rest[pos:]
            value = _criterion(*info(trial))
            if cand != chosen[pos] and value > best + 1e-9:
                chosen, best, improved = trial, value, True
        if not improved:
            break
    return chosen


def identifiable_columns(B: FloatArray, E: FloatArray, tol: float = IDENT_TOL) -> FloatArray:
    """Column indices of E identifiable next to B on these rows: pivoted QR of the unit
    columns projected out of span(B); a column whose new direction is shorter than ``tol``
    (the analysis's identifiability tolerance) is absorbed or a combination of the others."""
    Ep = project_out(orth(B), normalise(E))
    _, R, piv = sla.qr(Ep, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    return np.sort(piv[:len(d)][d > tol])


def parameter_std(B: FloatArray, E: FloatArray, noise_mm: float) -> FloatArray:
    """Standard deviation of each effect parameter (B profiled out) at noise ``noise_mm``."""
    Ep = project_out(orth(B), E)
    cov = np.linalg.pinv(Ep.T @ Ep)
    return noise_mm * np.sqrt(np.maximum(np.diag(cov), 0.0))


def plan_poses(robot: RobotModel, effects: list[tuple[str, int | None]], n: int = 30, *,
               workspace: Workspace | None = None, instrument: str = "tracker",
               tool: FloatArray | None = None, payload: tuple = (0.0, (0.0, 0.0, 0.0)),
               noise_mm: float = 0.02, seed: int = 0, n_pool: int = 1500) -> dict:
    """A D-optimal set of ``n`` poses for the ``effects`` (see the module docstring).

    Returns
    -------
    dict
        ``joints_deg`` (n lists, in measuring order), ``tcp_mm`` (nominal TCP, base frame),
        ``parameters`` (the identifiable effect parameters' keys), ``predicted_std``
        (their standard deviations at ``noise_mm``), ``not_identifiable`` (keys absorbed by
        the nuisance parameters on every pose), ``criterion`` (the D_s value).
    """
    if instrument not in INSTRUMENTS:
        raise CalibrationError(("instrument",), f"must be tracker or touch, got {instrument!r}")
    if not 6 <= int(n) <= 500:
        raise CalibrationError(("n",), f"must be 6..500 poses, got {n}")
    tool = np.eye(4) if tool is None else np.asarray(tool, float)
    ws = workspace or Workspace.default(robot)
    rng = np.random.default_rng(seed)
    pool_fn = tracker_pool if instrument == "tracker" else touch_pool
    pool = pool_fn(robot, tool, ws, n_pool if instrument == "tracker" else max(n_pool // 5, 4 * n),
                   rng)
    B, E, keys, m, dropped = design_matrices(robot, pool, tool, instrument, payload, effects)
    keep = identifiable_columns(B, E)
    dropped += [k for i, k in enumerate(keys) if i not in set(keep)]
    E, keys = E[:, keep], [keys[i] for i in keep]
    X = np.hstack([B, E])
    idx = d_optimal(X, B.shape[1], m, int(n), rng)
    rows = (np.asarray(idx)[:, None] * m + np.arange(m)).ravel()
    q = pool[idx]
    std = parameter_std(B[rows], E[rows], noise_mm)
    Us = X[rows]
    return {"format": "pose-plan/1", "robot": robot.name, "instrument": instrument,
            "n_poses": int(n), "effects": [e if j is None else f"{e}:{j}" for e, j in effects],
            "workspace": {"min_mm": ws.lo.tolist(), "max_mm": ws.hi.tolist(),
                          "floor_mm": ws.floor_mm},
            "joints_deg": np.round(q, 6).tolist(),
            "tcp_mm": np.round(forward_kinematics(robot, q, tool)[:, :3, 3], 3).tolist(),
            "parameters": keys,
            "predicted_std": {k: float(s) for k, s in zip(keys, std)},
            "noise_mm": noise_mm,
            "not_identifiable": dropped,
            "criterion": _criterion(Us.T @ Us, Us[:, :B.shape[1]].T @ Us[:, :B.shape[1]])}


def record_plan(robot: RobotModel, joints_deg: object, imperfections, *, seed: int = 0,
                tool: FloatArray | None = None, payload: tuple = (0.0, (0.0, 0.0, 0.0)),
                instrument_pose: FloatArray | None = None, dt_s: float = 10.0) -> dict:
    """A ``robot-recording/1`` tracker document measured at a plan's joints on a simulated
    real robot: the true TCP from :func:`solvers.physics.true_tcp_positions` (the hidden
    ``imperfections``), seen from the instrument (``instrument_pose`` = T_instrument_base,
    default that of the simulator), plus Gaussian noise of ``imperfections.noise_mm`` per
    axis; samples ``dt_s`` apart, in the plan's order."""
    from solvers.frames import Pose, apply
    from solvers.physics import true_tcp_positions
    from solvers.recording import recording_document

    q = np.atleast_2d(np.asarray(joints_deg, dtype=float))
    if q.ndim != 2 or q.shape[1] != robot.dof or len(q) < 1:
        raise CalibrationError(("joints_deg",), f"must be a list of poses of {robot.dof} joint "
                               "values")
    tool = np.eye(4) if tool is None else np.asarray(tool, float)
    T_inst = (Pose(2500.0, 800.0, -400.0, 160.0, 3.0, -2.0).as_matrix() if instrument_pose is None
              else np.asarray(instrument_pose, float))
    rng = np.random.default_rng(seed)
    imperfections.check(robot.dof)
    t = dt_s * np.arange(len(q))
    mass, com = float(payload[0]), np.asarray(payload[1], float)
    tcp = true_tcp_positions(robot, q, t, imperfections, tool, None, mass, com)
    noise = rng.normal(0.0, imperfections.noise_mm, tcp.shape) if imperfections.noise_mm > 0 else 0.0
    rec = RecordingData(kind="tracker", robot=robot, tool=tool, payload_mass_kg=mass,
                        payload_com_mm=com, start_joints_deg=None, t_s=t, joints_deg=q,
                        measured_mm=apply(T_inst, tcp) + noise)
    return recording_document(rec)
