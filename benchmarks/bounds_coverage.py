"""Coverage of the reported 95 % bounds: seeded Monte Carlo scenes, one per calibration method.

Each scene draws a true frame and the taught data a user would record for it, adds touch
noise (``SIGMA_MM`` per coordinate on every touched point / flange position; the light barrier
``LB_SIGMA_MM`` on every trigger's flange position), solves with the method's solver and
measures the errors against the truth, in the report's own parameters:

- position: ``|p̂ - p|`` (the TCP, the frame origin or the fixed TCP) against
  ``position_bound95_mm``;
- angle: the rotation angle of ``R̂ᵀ R`` (the tool axis' angle for the light barrier)
  against ``angle_bound95_deg``;
- Mahalanobis: ``sqrt(eᵀ C⁻¹ e)`` of the error ``e`` of all ``parameter_names`` against
  ``mahalanobis_bound95``.

The scenes are written from the documented conventions (docs/methods/*.md), not from the
solvers' internals. ``benchmarks/accuracy.py`` prints the table (>= 400 trials per row);
``tests/test_solver_coverage.py`` runs fewer trials of the same scenes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from solvers.base import base_3point, base_indirect, perturbed, pose_difference
from solvers.beam_cycle import plan_cycle, trigger_events
from solvers.fixed_tool import R_FLANGE_FIXEDTOOL, fixed_tool_5d, fixed_tool_6d
from solvers.light_barrier import tcp_light_barrier, tool_frame
from solvers.report import CalibrationResult, mahalanobis_distance
from solvers.tcp import tcp_xyz_4point, tcp_xyz_reference, tool_abc_2point
from solvers.workpiece import workpiece_direct, workpiece_indirect

SIGMA_MM = 0.05  # touch noise, 1 sigma per coordinate
LB_SIGMA_MM = 0.01  # light-barrier trigger noise on the flange position
DOWN = Rotation.from_euler("x", 180, degrees=True)
BASE_POINTS = np.array([[0, 0, 0], [300, 0, 0], [300, 200, 0], [0, 200, 0], [150, 100, 40],
                        [60, 160, 0], [240, 40, 0], [150, 0, 20.0]])
THREE_POINTS = np.array([[0, 0, 0], [180, 0, 0], [60, 140, 0.0]])
WORKPIECE_POINTS = np.array([[0, 0, 0], [200, 0, 0], [200, 150, 0], [0, 150, 60], [100, 75, 30],
                             [50, 120, 0], [160, 30, 0], [100, 0, 40.0]])


@dataclass(frozen=True)
class Trial:
    """One solve against the truth: errors and the report's bounds (None where not reported)."""

    position_mm: float | None
    position_bound_mm: float | None
    angle_deg: float | None
    angle_bound_deg: float | None
    mahalanobis: float | None
    mahalanobis_bound: float | None
    sigma_source: str  # the report's: "residual" or "assumed"


@dataclass(frozen=True)
class Coverage:
    """Fraction of trials whose error lies inside each 95 % bound (None: no such bound)."""

    name: str
    trials: int
    position: float | None
    angle: float | None
    mahalanobis: float | None
    sigma_source: str


def _rotation(rng: np.random.Generator, max_deg: float = 180.0) -> np.ndarray:
    v = rng.normal(size=3)
    return Rotation.from_rotvec(np.radians(rng.uniform(0, max_deg)) * v / np.linalg.norm(v)).as_matrix()


def _frame(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def _angle_deg(R_hat: np.ndarray, R: np.ndarray) -> float:
    return float(np.degrees(Rotation.from_matrix(R_hat.T @ R).magnitude()))


def _trial(result: CalibrationResult, error: np.ndarray, position_mm: float | None,
           angle_deg: float | None) -> Trial:
    rep = result.report
    m = mahalanobis_distance(error, rep.covariance) if rep.mahalanobis_bound95 is not None else None
    return Trial(position_mm, rep.position_bound95_mm, angle_deg, rep.angle_bound95_deg, m,
                 rep.mahalanobis_bound95, rep.sigma_source or "-")


def _pose_trial(result: CalibrationResult, T_true: np.ndarray) -> Trial:
    """Frames with POSE_PARAMETERS (R = R̂ Exp(dθ), dθ about the solved frame's axes)."""
    e = pose_difference(result.frame, T_true)
    return _trial(result, e, float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:])))


# ------------------------------------------------------------------------------- the scenes


def _cone_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """N flange rotations tilted 30-45 deg from straight down around a cone, random twist."""
    az = 2 * np.pi * (np.arange(n) + rng.uniform(-0.2, 0.2, n)) / n
    tilt = np.radians(rng.uniform(30, 45, n))
    tilts = Rotation.from_rotvec(tilt[:, None] * np.stack([np.cos(az), np.sin(az), 0 * az], 1))
    return (tilts * DOWN * Rotation.from_euler("z", rng.uniform(-45, 45, (n, 1)), degrees=True)).as_matrix()


def _touch_poses(R: np.ndarray, point: np.ndarray, tcp: np.ndarray,
                 rng: np.random.Generator, sigma: float = SIGMA_MM) -> np.ndarray:
    """Flange poses with the TCP ``tcp`` on ``point`` (base), noisy flange positions."""
    T = np.tile(np.eye(4), (len(R), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = point + rng.normal(0.0, sigma, (len(R), 3)) - R @ tcp
    return T


def _random_tcp(rng: np.random.Generator) -> np.ndarray:
    return np.array([rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(100, 300)])


def scene_xyz_4point(n: int) -> Callable[[np.random.Generator], Trial]:
    def run(rng: np.random.Generator) -> Trial:
        t = _random_tcp(rng)
        res = tcp_xyz_4point(_touch_poses(_cone_rotations(rng, n), np.array([650.0, 120, 180]), t, rng))
        e = res.frame[:3, 3] - t
        return _trial(res, e, float(np.linalg.norm(e)), None)
    return run


def scene_xyz_reference(n: int) -> Callable[[np.random.Generator], Trial]:
    def run(rng: np.random.Generator) -> Trial:
        t, s = _random_tcp(rng), np.array([650.0, 120, 180])
        res = tcp_xyz_reference(s, _touch_poses(_cone_rotations(rng, n), s, t, rng))
        e = res.frame[:3, 3] - t
        return _trial(res, e, float(np.linalg.norm(e)), None)
    return run


def scene_abc_2point(rng: np.random.Generator) -> Trial:
    """The tool's TCP, a point 60-120 mm behind it on the axis and one 30-60 mm to its +X side
    brought to one reference point (its sigma is the solver's assumed 0.05 mm)."""
    R_ft = _rotation(rng, 20.0)
    t = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(120, 250)])
    z, x = R_ft[:, 2], R_ft[:, 0]
    marks = [t, t - rng.uniform(60, 120) * z, t + rng.uniform(30, 60) * x - rng.uniform(0, 30) * z]
    q = np.array([600.0, 0.0, 100.0])
    T = np.stack([_touch_poses(((DOWN * Rotation.from_matrix(_rotation(rng, 15.0))).as_matrix())[None],
                               q, m, rng)[0] for m in marks])
    res = tool_abc_2point(t, T)
    e = Rotation.from_matrix(res.frame[:3, :3].T @ R_ft).as_rotvec(degrees=True)
    return _trial(res, e, None, float(np.linalg.norm(e)))


def scene_base_3point(rng: np.random.Generator) -> Trial:
    T = _frame(_rotation(rng, 30.0), rng.uniform([500, -200, 0], [900, 200, 300]))
    P = THREE_POINTS @ T[:3, :3].T + T[:3, 3] + rng.normal(0, SIGMA_MM, (3, 3))
    return _pose_trial(base_3point(*P), T)


def scene_base_indirect(n: int) -> Callable[[np.random.Generator], Trial]:
    def run(rng: np.random.Generator) -> Trial:
        T = _frame(_rotation(rng), rng.uniform([500, -200, 0], [900, 200, 300]))
        K = BASE_POINTS[:n]
        M = K @ T[:3, :3].T + T[:3, 3] + rng.normal(0, SIGMA_MM, (n, 3))
        return _pose_trial(base_indirect(M, K), T)
    return run


def _brush(rng: np.random.Generator, T_fw: np.ndarray, known: np.ndarray,
           r: np.ndarray) -> np.ndarray:
    """Flange poses bringing each known workpiece point onto the fixed TCP r (tilted up to 15
    deg between touches), the touch noise on the flange position."""
    c = known @ T_fw[:3, :3].T + T_fw[:3, 3]
    R = np.stack([(DOWN * Rotation.from_matrix(_rotation(rng, 15.0))).as_matrix() for _ in c])
    T = np.tile(np.eye(4), (len(c), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = r - np.einsum("kij,kj->ki", R, c) + rng.normal(0, SIGMA_MM, (len(c), 3))
    return T


def _random_workpiece(rng: np.random.Generator) -> np.ndarray:
    return _frame(_rotation(rng), np.array([rng.uniform(-50, 50), rng.uniform(-50, 50),
                                            rng.uniform(80, 150)]))


def scene_workpiece_direct(rng: np.random.Generator) -> Trial:
    T_fw, r = _random_workpiece(rng), np.array([700.0, 50.0, 250.0])
    return _pose_trial(workpiece_direct(r, _brush(rng, T_fw, THREE_POINTS, r)), T_fw)


def scene_workpiece_indirect(n: int) -> Callable[[np.random.Generator], Trial]:
    def run(rng: np.random.Generator) -> Trial:
        T_fw, r = _random_workpiece(rng), np.array([700.0, 50.0, 250.0])
        K = WORKPIECE_POINTS[:n]
        return _pose_trial(workpiece_indirect(r, _brush(rng, T_fw, K, r), K), T_fw)
    return run


def scene_fixed_tool(mode: str, touches: int) -> Callable[[np.random.Generator], Trial]:
    """A fixed tool (axis within 40 deg of up) touched ``touches`` times with a calibrated
    pointer from orientations 20-40 deg apart, then the flange aligned 150 mm above it."""
    solve = fixed_tool_5d if mode == "5d" else fixed_tool_6d

    def run(rng: np.random.Generator) -> Trial:
        R_E = _rotation(rng, 40.0)
        r = rng.uniform([500, -200, 100], [800, 200, 300])
        tcp = np.array([0.0, 0.0, 120.0])
        R = np.stack([(Rotation.from_matrix(R_E) * DOWN * Rotation.from_matrix(_rotation(rng, 40.0))
                       ).as_matrix() for _ in range(touches)])
        T = _touch_poses(R, r, tcp, rng)
        align = _frame(R_E @ R_FLANGE_FIXEDTOOL, r + 150.0 * R_E[:, 2])
        res = solve(T[0], tcp, align, extra_touch_poses=T[1:])
        e = res.frame[:3, 3] - r
        return _trial(res, e, float(np.linalg.norm(e)), None)
    return run


def scene_light_barrier(rng: np.random.Generator, noise_draws: int = 1) -> list[Trial]:
    """A random tool (offset <= 2 mm, runout <= 2 deg, 80-250 mm) measured by the paper's cycle
    (two level beams crossing at 90 deg, sweeps both ways at three heights in three directions,
    a tip search down and one back up), the flange tilted 0-20 deg; ``noise_draws`` noisy copies
    of its exact triggers, each solved."""
    a = Rotation.from_euler("xy", rng.uniform(-1.4, 1.4, 2), degrees=True).apply([0.0, 0.0, 1.0])
    tcp = np.r_[rng.uniform(-2.0, 2.0, 2), 0.0] + rng.uniform(80.0, 250.0) * a
    R0 = (Rotation.from_matrix(_rotation(rng, 20.0)) * DOWN).as_matrix()
    center = np.array([600.0, 0.0, 200.0])
    yaw = rng.uniform(0, 90)
    dirs = [Rotation.from_euler("z", yaw + k * 90, degrees=True).apply([1.0, 0, 0]) for k in (0, 1)]
    beams = {"bx": (center, dirs[0]), "by": (center, dirs[1])}
    nominal = np.eye(4)
    nominal[:3, 3] = np.round(tcp)
    plan = plan_cycle(beams, 6.0, center, [10.0, 25.0, 40.0], flange_rotation=R0,
                      nominal_tool=nominal, directions_deg=(0.0, 90.0, 45.0),
                      tip_axis_flange=(tcp, a))
    tip = plan[-1]
    back = type(tip)(tip.kind, tip.end_flange, tip.start_flange, tip.speed_mm_s,
                     tip.nominal_tcp_mm, "tip search back up", None, tip.target_beam)
    events = [e for p in (*plan, back) for e in trigger_events(None, p, tcp, a, beams, 6.0)]
    T = np.array([e.T_base_flange for e in events])
    ids, edges = [e.beam_id for e in events], [e.edge for e in events]
    vel = np.array([e.tcp_velocity_mm_s for e in events])
    out = []
    for _ in range(noise_draws):
        noisy = T.copy()
        noisy[:, :3, 3] += rng.normal(0.0, LB_SIGMA_MM, (len(T), 3))
        res = tcp_light_barrier(noisy, ids, edges, beams, 6.0, vel, find_bad_point=False)
        a_hat = res.frame[:3, 2]
        x, y = tool_frame(res.frame[:3, 3], a_hat)[:3, 0:2].T
        tilt = np.degrees([a @ x, a @ y])  # the true axis' tilts about the fitted one (small)
        e = np.r_[res.frame[:3, 3] - tcp, -tilt]  # estimate minus truth, as the position
        angle = float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a_hat, a)), a_hat @ a)))
        out.append(_trial(res, e, float(np.linalg.norm(e[:3])), angle))
    return out


# ------------------------------------------------------------------ chained scenes
# What the server does (server.service.external.solve_in_chain) with the same solvers.external.chain
# functions: the touching tool is itself calibrated (XYZ 4-point, its covariance stored), the
# rail too (Linear unit); both are carried into the result's bound. Touch noise: the cell's
# aim AIM_SIGMA_MM, which the menus without redundancy assume.

AIM_SIGMA_MM = 0.1  # server.api.schemas.AIM_NOISE_MM: the pendant's aim, the assumed sigma


def _calibrated_tool(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, int | None]:
    """(true TCP, XYZ 4-point TCP, its covariance as stored, the dof of its sigma)."""
    t = _random_tcp(rng)
    res = tcp_xyz_4point(_touch_poses(_cone_rotations(rng, 4), np.array([650.0, 120, 180]), t,
                                      rng, AIM_SIGMA_MM))
    return t, res.frame[:3, 3], res.report.covariance[:3, :3], res.report.dof


def _tilted_down(rng: np.random.Generator, n: int) -> np.ndarray:
    """N flange rotations within 10 deg of straight down, random twist (a base touch-up)."""
    return np.stack([(Rotation.from_matrix(_rotation(rng, 10.0)) * DOWN
                      * Rotation.from_euler("z", rng.uniform(-180, 180), degrees=True)).as_matrix()
                     for _ in range(n)])


def _chained_trial(result: CalibrationResult, T_true: np.ndarray,
                   terms: dict[str, np.ndarray], term_dofs: dict[str, int | None],
                   position_only: bool = False) -> Trial:
    from solvers.external.chain import combined_bounds, own_covariance, report_dof

    rep = result.report
    b = combined_bounds(rep.position_bound95_mm, rep.angle_bound95_deg, terms, report_dof(rep),
                        own_covariance(rep), term_dofs)
    e = pose_difference(result.frame, T_true)
    return Trial(float(np.linalg.norm(e[:3])), b["position_bound95_mm"],
                 None if position_only else float(np.linalg.norm(e[3:])),
                 None if position_only else b["angle_bound95_deg"], None, None,
                 rep.sigma_source or ("residual" if report_dof(rep) else "assumed"))


def scene_base_3point_with_tool(rng: np.random.Generator) -> Trial:
    """Base > 3-point touched with tool 1 as XYZ 4-point calibrated it (both at the aim sigma)."""
    from solvers.dh import tcp_of
    from solvers.external.chain import propagate

    t, t_hat, C_t, nu_t = _calibrated_tool(rng)
    T = _frame(_rotation(rng, 30.0), rng.uniform([500, -200, 0], [900, 200, 300]))
    targets = THREE_POINTS @ T[:3, :3].T + T[:3, 3]
    F = np.stack([_touch_poses(R[None], p, t, rng, AIM_SIGMA_MM)[0]
                  for R, p in zip(_tilted_down(rng, 3), targets)])

    def solve(x: np.ndarray) -> CalibrationResult:
        return base_3point(*tcp_of(F, x), touch_sigma_mm=AIM_SIGMA_MM)
    res = solve(t_hat)
    return _chained_trial(res, T, {"tool": propagate(lambda x: solve(x).frame, t_hat, C_t)},
                          {"tool": nu_t})


def scene_root_point_on_rail(rng: np.random.Generator) -> Trial:
    """ext.root_point on a turntable with the robot on its rail: the rail calibrated (Linear
    unit, 4 positions over 500 mm), the mark then touched at 4 table positions with the rail at
    100-300 mm, with tool 1 as calibrated; the root in the world (base at rail 0)."""
    from solvers.dh import tcp_of
    from solvers.external import linear_unit, root_point
    from solvers.external.chain import propagate, to_world
    from solvers.external_sim import make_linear_unit, make_turntable

    t, t_hat, C_t, nu_t = _calibrated_tool(rng)
    rail = make_linear_unit(direction_tilt_deg=rng.uniform(-0.6, 0.6),
                            scale=1.0 + rng.uniform(-0.003, 0.003))
    e_cal = np.array([-250.0, -80.0, 80.0, 250.0])
    mark_world = np.array([560.0, 100.0, 250.0])
    cal_targets = rail.mark_in_base(mark_world, e_cal)
    F_cal = np.stack([_touch_poses(R[None], p, t, rng, AIM_SIGMA_MM)[0]
                      for R, p in zip(_tilted_down(rng, 4), cal_targets)])
    lu = linear_unit(tcp_of(F_cal, t_hat), e_cal, touch_sigma_mm=AIM_SIGMA_MM)
    d_hat, k_hat = lu.report.extras["travel_direction"], lu.report.extras["scale"]
    C_b, nu_b = lu.report.covariance[3:, 3:], lu.report.extras["dof"] or None
    table = make_turntable(tilt_deg=rng.uniform(0, 0.8), root_offset_mm=rng.uniform(0, 3),
                           nominal_root=_frame(np.eye(3), np.array([520.0, 380.0, 80.0])))
    mark = np.array([150.0, 0.0, 0.0])
    theta = np.array([-135.0, -45.0, 45.0, 135.0]) + rng.uniform(-10, 10, 4)
    e = rng.uniform(100.0, 300.0) * np.ones(4)
    world = table.mark(mark, theta)
    B = rail.base_pose(e)
    in_base = np.einsum("nji,nj->ni", B[:, :3, :3], world - B[:, :3, 3])
    F = np.stack([_touch_poses(R[None], p, t, rng, AIM_SIGMA_MM)[0]
                  for R, p in zip(_tilted_down(rng, 4), in_base)])

    def solve(x: np.ndarray, b: np.ndarray) -> CalibrationResult:
        k = float(np.linalg.norm(b))
        return root_point(tcp_of(to_world(F, e, -b / k, k), x), theta,
                          nominal_axis=table.nominal_root[:3, 2], touch_sigma_mm=AIM_SIGMA_MM)
    b0 = -k_hat * d_hat
    res = solve(t_hat, b0)
    terms = {"tool": propagate(lambda x: solve(x, b0).frame, t_hat, C_t),
             "rail": propagate(lambda b: solve(t_hat, b).frame, b0, C_b)}
    truth = table.true_root_frame(mark)
    return _chained_trial(res, truth, terms, {"tool": nu_t, "rail": nu_b}, position_only=True)


def _base_on_table(rng: np.random.Generator, table: object, mark: np.ndarray, half_mm: float,
                   sigma_mm: float) -> tuple[np.ndarray, float, np.ndarray]:
    """(true base in the table's flange frame, the axis value, the three touched points): the
    origin within ``half_mm`` of the axis, any yaw, tilted up to 10 deg; touched by its origin,
    a point 200 mm along +X and one 150 mm along +Y with ``sigma_mm`` of noise."""
    from solvers.external.common import rz

    truth = _frame((Rotation.from_matrix(_rotation(rng, 10.0))
                    * Rotation.from_euler("z", rng.uniform(-180, 180), degrees=True)).as_matrix(),
                   np.r_[rng.uniform(-half_mm, half_mm, 2), rng.uniform(0, 50)])
    theta = rng.uniform(-180, 180)
    W = table.true_root_frame(mark) @ rz([theta])[0] @ truth  # type: ignore[attr-defined]
    P = np.array([W[:3, 3], W[:3, 3] + 200 * W[:3, 0], W[:3, 3] + 150 * W[:3, 1]])
    return truth, theta, P + rng.normal(0.0, sigma_mm, (3, 3))


def scene_offset_on_root_by_tool(rng: np.random.Generator) -> Trial:
    """ext.offset on a root point touched with tool 1 as XYZ 4-point calibrated it (4 table
    positions, the tool's term stored with the root), the base then touched with an exact
    tool: the Offset's own bound (touch and the root's own share) plus the root's tool term
    carried through the Offset by moving the root frame, as the server does
    (``server.service.external._root_terms``); per-block dof as ``report_dofs`` reads them."""
    from solvers.dh import tcp_of
    from solvers.external import offset, root_point
    from solvers.external.chain import combined_bounds, own_covariance, propagate, report_dofs
    from solvers.external_sim import make_turntable

    t, t_hat, C_t, nu_t = _calibrated_tool(rng)
    table = make_turntable(tilt_deg=rng.uniform(0, 0.8), root_offset_mm=rng.uniform(0, 3),
                           nominal_root=_frame(np.eye(3), np.array([620.0, 300.0, 80.0])))
    mark = np.array([150.0, 0.0, 0.0])
    theta = np.array([-135.0, -45.0, 45.0, 135.0]) + rng.uniform(-10, 10, 4)
    F = np.stack([_touch_poses(R[None], p, t, rng, AIM_SIGMA_MM)[0]
                  for R, p in zip(_tilted_down(rng, 4), table.mark(mark, theta))])

    def solve_root(x: np.ndarray) -> CalibrationResult:
        return root_point(tcp_of(F, x), theta, nominal_axis=table.nominal_root[:3, 2],
                          touch_sigma_mm=AIM_SIGMA_MM)
    rp = solve_root(t_hat)
    C_root_tool = propagate(lambda x: solve_root(x).frame, t_hat, C_t)
    truth, th, P = _base_on_table(rng, table, mark, 100.0, AIM_SIGMA_MM)

    def solve(root: np.ndarray) -> CalibrationResult:
        return offset(*P, th, root, root_covariance=rp.report.covariance,
                      root_dof=rp.report.extras["dof"], root_sigma_mm=rp.report.sigma_mm,
                      touch_sigma_mm=AIM_SIGMA_MM)
    res = solve(rp.frame)
    term = propagate(lambda d: solve(perturbed(rp.frame, d)).frame, np.zeros(6), C_root_tool)
    rep = res.report
    b = combined_bounds(rep.position_bound95_mm, rep.angle_bound95_deg, {"root tool": term},
                        report_dofs(rep), own_covariance(rep), {"root tool": nu_t})
    e = pose_difference(res.frame, truth)
    return Trial(float(np.linalg.norm(e[:3])), b["position_bound95_mm"],
                 float(np.linalg.norm(e[3:])), b["angle_bound95_deg"], None, None,
                 "assumed+residual")


# ------------------------------------------------------------------ external kinematics
# solvers.external_sim's machines (docs/methods/external.md) with random hidden errors, the
# marks touched with SIGMA_MM per coordinate on the touched point (solvers.external_sim.touch:
# the emulator's aim, emulator.controller's noise_mm, is the same isotropic Gaussian). The
# truth is the frame as the method defines it (``Turntable.true_root_frame``: origin the centre
# of the mark's circle, z the axis positive values turn about, x towards the mark at 0).


def _random_turntable(rng: np.random.Generator) -> tuple[object, np.ndarray]:
    """A turntable whose nominal axis is within 30 deg of vertical, hidden tilt 0-1 deg, root
    offset 0-3 mm and a random sign; a mark 150-400 mm off the axis, -50..100 mm up it."""
    from solvers.external_sim import make_turntable

    nominal = _frame(_rotation(rng, 30.0), rng.uniform([1000, -400, 0], [1600, 400, 600]))
    table = make_turntable(tilt_deg=rng.uniform(0, 1), root_offset_mm=rng.uniform(0, 3),
                           sign=int(rng.choice([-1, 1])), nominal_root=nominal)
    a = rng.uniform(0, 2 * np.pi)
    mark = np.r_[rng.uniform(150, 400) * np.array([np.cos(a), np.sin(a)]), rng.uniform(-50, 100)]
    return table, mark


def _rotary_values(rng: np.random.Generator, n: int) -> np.ndarray:
    """N axis values over 270 deg (-135..135), each jittered +-10 deg (the ends fixed for N > 8)."""
    return np.linspace(-135.0, 135.0, n) + rng.uniform(-10, 10, n) * (n <= 8)


def _axis_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def _ext_trial(result: CalibrationResult, position_mm: float | None,
               angle_deg: float | None, source: str | None = None) -> Trial:
    """The external kinematics report no Mahalanobis bound; sigma from ``extras["dof"]``."""
    rep = result.report
    if source is None:
        source = "residual" if (rep.extras or {}).get("dof") else "assumed"
    return Trial(position_mm, rep.position_bound95_mm, angle_deg, rep.angle_bound95_deg,
                 None, None, source)


def scene_root_point(n: int) -> Callable[[np.random.Generator], Trial]:
    """ext.root_point: the mark touched at N axis values; the centre (position) and the axis
    direction (angle: ``angle_bound95_deg`` is the axis direction's, 2 dof)."""
    from solvers.external import root_point

    def run(rng: np.random.Generator) -> Trial:
        table, mark = _random_turntable(rng)
        values = _rotary_values(rng, n)
        tu = table.touch_mark(mark, values, SIGMA_MM, rng)
        res = root_point(tu.points_mm, tu.axis_values, nominal_axis=table.nominal_root[:3, 2])
        truth = table.true_root_frame(mark)
        return _ext_trial(res, float(np.linalg.norm(res.frame[:3, 3] - truth[:3, 3])),
                          _axis_angle_deg(res.frame[:3, 2], truth[:3, 2]))
    return run


def scene_offset(rng: np.random.Generator) -> Trial:
    """ext.offset: the root point from 4 touch-ups (its covariance and dof carried), then a base
    on the table (origin within 150 mm of the axis, any yaw, tilted up to 10 deg) touched at
    one axis value by its origin, a point 200 mm along +X and one 150 mm along +Y."""
    from solvers.external import offset, root_point

    table, mark = _random_turntable(rng)
    tu = table.touch_mark(mark, _rotary_values(rng, 4), SIGMA_MM, rng)
    rp = root_point(tu.points_mm, tu.axis_values, nominal_axis=table.nominal_root[:3, 2])
    truth, theta, P = _base_on_table(rng, table, mark, 150.0, SIGMA_MM)
    res = offset(*P, theta, rp.frame, root_covariance=rp.report.covariance,
                 root_dof=rp.report.extras["dof"], root_sigma_mm=rp.report.sigma_mm,
                 touch_sigma_mm=SIGMA_MM)
    e = pose_difference(res.frame, truth)
    return _ext_trial(res, float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:])),
                      "assumed+residual")


def scene_linear_unit(n: int) -> Callable[[np.random.Generator], Trial]:
    """ext.linear_unit: a rail with its travel tilted up to 1 deg, a random sign, an encoder
    scale within 0.5 % and the robot yawed on the carriage; one fixed mark touched at N rail
    positions spread over -400..400 mm. Position: the mark at encoder 0 (the report's position
    block, ``mark_at_zero_mm``); angle: the travel direction."""
    from solvers.external import linear_unit
    from solvers.external_sim import make_linear_unit

    def run(rng: np.random.Generator) -> Trial:
        rail = make_linear_unit(direction_tilt_deg=rng.uniform(-1, 1),
                                sign=int(rng.choice([-1, 1])), scale=1 + rng.uniform(-0.005, 0.005),
                                base_yaw_deg=rng.uniform(-180, 180))
        mark = rng.uniform([400, -300, -100], [900, 300, 400])
        values = np.linspace(-400.0, 400.0, n) + rng.uniform(-20, 20, n)
        tu = rail.touch_mark(mark, values, SIGMA_MM, rng)
        res = linear_unit(tu.points_mm, tu.axis_values, nominal_direction=rail.nominal_in_base)
        a_true = rail.mark_in_base(mark, [0.0])[0]
        return _ext_trial(res, float(np.linalg.norm(res.report.extras["mark_at_zero_mm"] - a_true)),
                          _axis_angle_deg(res.report.extras["travel_direction"], rail.travel_in_base))
    return run


def _positioner_solve(rng: np.random.Generator) -> tuple[CalibrationResult, np.ndarray]:
    """A positioner with hidden errors (tilt axis tilted 0-1 deg and 0-3 mm off its root, a
    random tilt sign, the turn axis tilted 0-1 deg and missing the tilt axis by 1-3 mm), a mark
    100-200 mm off the turn axis; the tilt taught at 4 values over +-75 deg (turn at 0), the
    turn at 4 values over 270 deg with the tilt at -30..30 deg. Returns (result, the true
    T_tiltflange_turnroot)."""
    from solvers.external import positioner_2axis
    from solvers.external.common import rz
    from solvers.external_sim import Turntable, make_positioner, touch

    pos = make_positioner(tilt_deg=rng.uniform(0, 1), root_offset_mm=rng.uniform(0, 3),
                          sign=int(rng.choice([-1, 1])), turn_tilt_deg=rng.uniform(0, 1),
                          axis_offset_mm=rng.uniform(1, 3))
    a = rng.uniform(0, 2 * np.pi)
    mark = np.r_[rng.uniform(100, 200) * np.array([np.cos(a), np.sin(a)]), 0.0]
    tilt_values = np.linspace(-75.0, 75.0, 4) + rng.uniform(-5, 5, 4)
    turn_values = _rotary_values(rng, 4)
    tau = rng.uniform(-30, 30)
    tilt = touch(pos.mark(mark, tilt_values, np.zeros(4)), tilt_values, SIGMA_MM, rng)
    turn = touch(pos.mark(mark, np.full(4, tau), turn_values), turn_values, SIGMA_MM, rng)
    res = positioner_2axis(tilt.points_mm, tilt_values, turn.points_mm, turn_values, tau,
                           nominal_root_mm=pos.tilt.nominal_root[:3, 3], touch_sigma_mm=SIGMA_MM)
    # the truth as root_point defines both roots: the tilt's for the mark at turn 0, the turn's
    # at tilt tau, the turn root carried into the tilt flange frame at tau
    mark_in_tilt = pos.turn_in_tilt[:3, :3] @ mark + pos.turn_in_tilt[:3, 3]
    T_tilt = pos.tilt.true_root_frame(mark_in_tilt)
    T_turn = Turntable(pos.turn_root_in_base(tau), pos.turn_root_in_base(tau),
                       pos.turn_sign).true_root_frame(mark)
    return res, np.linalg.inv(T_tilt @ rz([tau])[0]) @ T_turn


def _positioner_frame_trial(res: CalibrationResult, X: np.ndarray) -> Trial:
    e = pose_difference(res.frame, X)
    return _ext_trial(res, float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:])), "residual")


def scene_positioner_2axis(rng: np.random.Generator) -> Trial:
    """ext.positioner_2axis: the turn root in the tilt flange frame (the result's frame)."""
    return _positioner_frame_trial(*_positioner_solve(rng))


def scene_positioner_axes(rng: np.random.Generator) -> Trial:
    """ext.positioner_2axis' 1-D bounds: the common normal's length (mm, in the position
    column) against ``common_normal_bound95_mm``, the angle between the axes (deg, in the angle
    column) against ``axes_angle_bound95_deg``."""
    return _positioner_axes_trial(*_positioner_solve(rng))


def _positioner_axes_trial(res: CalibrationResult, X: np.ndarray) -> Trial:
    from solvers.external.common import line_distance

    ex = res.report.extras
    # of the true frame: with the tilt sign reversed the tilt root's z (the axis positive
    # values turn about) is the machine's -z, and the angle between the axes 180 deg minus it
    L, _, _ = line_distance(np.zeros(3), np.array([0.0, 0.0, 1.0]), X[:3, 3], X[:3, 2])
    angle = float(np.degrees(np.arccos(np.clip(X[2, 2], -1.0, 1.0))))
    return Trial(abs(ex["common_normal_mm"] - L), ex["common_normal_bound95_mm"],
                 abs(ex["axes_angle_deg"] - angle), ex["axes_angle_bound95_deg"], None, None,
                 "residual")


#: (row name, scene) of the coverage table; every scene returns one Trial.
SCENES: list[tuple[str, Callable[[np.random.Generator], Trial]]] = [
    ("tool.xyz_4point N=4", scene_xyz_4point(4)),
    ("tool.xyz_4point N=8", scene_xyz_4point(8)),
    ("tool.xyz_reference N=3", scene_xyz_reference(3)),
    ("tool.abc_2point", scene_abc_2point),
    ("base.3point", scene_base_3point),
    ("base.indirect N=4", scene_base_indirect(4)),
    ("base.indirect N=8", scene_base_indirect(8)),
    ("workpiece.direct", scene_workpiece_direct),
    ("workpiece.indirect N=4", scene_workpiece_indirect(4)),
    ("workpiece.indirect N=8", scene_workpiece_indirect(8)),
    ("fixed_tool.5d 3 touches", scene_fixed_tool("5d", 3)),
    ("fixed_tool.6d 2 touches", scene_fixed_tool("6d", 2)),
    ("chain: base.3point+tool", scene_base_3point_with_tool),
    ("chain: root_point on rail", scene_root_point_on_rail),
    ("chain: offset, root by tool", scene_offset_on_root_by_tool),
    ("ext.root_point N=4", scene_root_point(4)),
    ("ext.root_point N=12", scene_root_point(12)),
    ("ext.offset (root N=4)", scene_offset),
    ("ext.linear_unit N=5", scene_linear_unit(5)),
    ("ext.positioner_2axis 4+4", scene_positioner_2axis),
    ("ext.positioner_2axis axes", scene_positioner_axes),
]


def _fraction(trials: list[Trial], err: str, bound: str) -> float | None:
    pairs = [(getattr(t, err), getattr(t, bound)) for t in trials]
    if any(b is None or e is None for e, b in pairs):
        return None
    return float(np.mean([e <= b for e, b in pairs]))


def summarise(name: str, trials: list[Trial]) -> Coverage:
    sources = sorted({t.sigma_source for t in trials})
    return Coverage(name, len(trials), _fraction(trials, "position_mm", "position_bound_mm"),
                    _fraction(trials, "angle_deg", "angle_bound_deg"),
                    _fraction(trials, "mahalanobis", "mahalanobis_bound"), "/".join(sources))


def coverage(name: str, trials: int, seed: int) -> Coverage:
    """Coverage of one row of :data:`SCENES` over ``trials`` seeded trials."""
    scene = dict(SCENES)[name]
    rng = np.random.default_rng(seed)
    runs = [scene(rng) for _ in range(trials)]
    return summarise(name, runs)


def positioner_coverage(trials: int, seed: int) -> tuple[Coverage, Coverage]:
    """The rows ``ext.positioner_2axis 4+4`` and ``ext.positioner_2axis axes`` from one run
    of ``trials`` seeded solves (the two scenes draw the same trials from the same seed)."""
    rng = np.random.default_rng(seed)
    runs = [_positioner_solve(rng) for _ in range(trials)]
    return (summarise("ext.positioner_2axis 4+4", [_positioner_frame_trial(*r) for r in runs]),
            summarise("ext.positioner_2axis axes", [_positioner_axes_trial(*r) for r in runs]))


def light_barrier_coverage(tools: int, draws: int, seed: int) -> Coverage:
    """Coverage of ``tool.light_barrier`` over ``tools`` random tools x ``draws`` noise draws."""
    rng = np.random.default_rng(seed)
    runs = [t for _ in range(tools) for t in scene_light_barrier(rng, draws)]
    return summarise("tool.light_barrier", runs)
