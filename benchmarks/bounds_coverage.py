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

from solvers.base import base_3point, base_indirect, pose_difference
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


#: (row name, scene) of the coverage table; every scene returns one Trial.
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


def light_barrier_coverage(tools: int, draws: int, seed: int) -> Coverage:
    """Coverage of ``tool.light_barrier`` over ``tools`` random tools x ``draws`` noise draws."""
    rng = np.random.default_rng(seed)
    runs = [t for _ in range(tools) for t in scene_light_barrier(rng, draws)]
    return summarise("tool.light_barrier", runs)
