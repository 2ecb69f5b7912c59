"""Tool > Light barrier: measuring-cycle geometry, the paper's closed form and the full fit.

Cycles are planned with ``solvers.beam_cycle`` for a nominal tool, triggered with a random
TRUE tool (offset up to 3 mm, runout up to 2 deg, length 80-250 mm) on flange orientations
reached by two (four) library robots, and solved back.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solvers.beam_cycle import axis_beam_geometry, as_beams, plan_cycle, trigger_events
from solvers.dh import forward_kinematics
from solvers.errors import CalibrationError
from solvers.frames import axis_angle_deg
from solvers.light_barrier import (light_barrier_two_heights, runout_angles_deg,
                                   shaft_axis_from_sweeps, tcp_light_barrier, tool_frame)
from solvers.robots import ROBOTS

D_MM = 6.0
# (robot, joints): flange poses the arm reaches; the second of each pair tilts the flange
CONFIGS = [("kuka_kr6_r900_sixx", [10, -80, 100, 0, 70, 20]),
           ("kuka_kr6_r900_sixx", [10, -80, 100, 20, 60, 20]),
           ("ur5e", [10, -100, -100, -70, 90, 30]),
           ("ur5e", [10, -100, -100, -60, 80, 30])]


def random_tool(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """TRUE tool: TCP (mm) and unit axis in flange; |offset| <= 3 mm, runout <= 2 deg."""
    runout = Rotation.from_euler("xy", rng.uniform(-1.4, 1.4, 2), degrees=True)
    a = runout.apply([0.0, 0.0, 1.0])
    base = np.r_[rng.uniform(-2.0, 2.0, 2), 0.0]
    tcp = base + rng.uniform(80.0, 250.0) * a
    return tcp, a


def sensor(center: np.ndarray, yaw_deg: float = 0.0, angle_deg: float = 90.0) -> dict:
    """Two level beams crossing at ``center``, at ``yaw_deg`` and ``yaw_deg + angle_deg``."""
    dirs = [Rotation.from_euler("z", yaw_deg + k * angle_deg, degrees=True).apply([1.0, 0, 0])
            for k in (0, 1)]
    return {"bx": (center, dirs[0]), "by": (center, dirs[1])}


def run(passes, tcp, a, beams):
    events = [e for p in passes for e in trigger_events(None, p, tcp, a, beams, D_MM)]
    return (np.array([e.T_base_flange for e in events]), [e.beam_id for e in events],
            [e.edge for e in events], np.array([e.tcp_velocity_mm_s for e in events]))


def measure(config, tcp, a, *, heights=(10.0, 40.0), yaw_deg=0.0, directions=(0.0, 90.0),
            both_ways=True):
    """The two-stage cycle of the paper: sweeps, the axis from them, then an aimed tip search."""
    robot, q = config
    T = forward_kinematics(ROBOTS[robot], q)
    length = round(float(np.linalg.norm(tcp)) / 10.0) * 10.0  # nominal tool: within 5 mm
    nominal = np.eye(4)
    nominal[2, 3] = length
    center = T[:3, :3] @ nominal[:3, 3] + T[:3, 3] + np.array([0.0, 0.0, 25.0])
    beams = sensor(center, yaw_deg)
    plan = plan_cycle(beams, D_MM, center, heights, flange_rotation=T[:3, :3], nominal_tool=nominal,
                      directions_deg=directions, both_ways=both_ways)
    sweeps = run(plan[:-1], tcp, a, beams)
    axis = shaft_axis_from_sweeps(sweeps[0], sweeps[1], sweeps[2], beams)
    tip = plan_cycle(beams, D_MM, center, heights, flange_rotation=T[:3, :3], nominal_tool=nominal,
                     tip_axis_flange=(axis.base_point_mm, axis.axis_flange))[-1]
    tips = run([tip], tcp, a, beams)
    assert tips[2] == ["tip"]
    return tuple(np.concatenate([x, y]) if isinstance(x, np.ndarray) else x + y
                 for x, y in zip(sweeps, tips)) + (beams,)


def errors(result, tcp, a):
    """Position error (mm) and axis error (deg, via the cross product: exact for tiny angles)."""
    axis_deg = np.degrees(np.arcsin(min(np.linalg.norm(np.cross(result.frame[:3, 2], a)), 1.0)))
    return float(np.linalg.norm(result.frame[:3, 3] - tcp)), float(axis_deg)


# ------------------------------------------------------------------ cycle geometry


def test_plan_cycle_keeps_orientation_and_sweeps_level():
    beams = sensor(np.array([600.0, 0.0, 200.0]))
    plan = plan_cycle(beams, D_MM, [600, 0, 200], [10.0, 25.0, 40.0], directions_deg=(0, 90, 45))
    assert [p.kind for p in plan].count("sweep") == 18 and plan[-1].kind == "tip"
    for p in plan:
        assert np.array_equal(p.start_flange[:3, :3], plan[0].start_flange[:3, :3])
        if p.kind == "sweep":
            assert p.start_flange[2, 3] == pytest.approx(p.end_flange[2, 3], abs=1e-12)
            assert p.pose_at(0.5)[2, 3] == pytest.approx(200.0 + 100.0 - p.height_mm, abs=1e-9)


def test_trigger_events_satisfy_the_recording_conditions(rng):
    """Every enter/leave: axis at d/2 from the beam on the approach (-) / far (+) side, the
    beam cutting the shaft (not beyond the tip); the tip: TCP on the plane normal to v."""
    tcp, a = random_tool(rng)
    flange_poses, ids, edges, vel, beams = measure(CONFIGS[1], tcp, a, directions=(0.0, 90.0, 45.0))
    B = as_beams(beams)
    assert edges.count("enter") == edges.count("leave") >= 12 and edges.count("tip") == 1
    for T, b, e, v in zip(flange_poses, ids, edges, vel):
        c, w = T[:3, :3] @ tcp + T[:3, 3], T[:3, :3] @ a
        if e == "tip":
            u = B[b].direction
            nv = (v - (v @ u) * u) / np.linalg.norm(v - (v @ u) * u)
            assert (c - B[b].point_mm) @ nv == pytest.approx(0.0, abs=1e-9)
            continue
        sigma, lam, n = axis_beam_geometry(c, w, B[b])
        assert sigma * np.sign(n @ v) == pytest.approx(-3.0 if e == "enter" else 3.0, abs=1e-9)
        assert lam < 0
        assert np.linalg.norm(v) == pytest.approx(20.0, rel=1e-6)


def test_trigger_events_follow_any_flange_motion():
    """A custom (rotating) flange motion is handled by root finding along s."""
    beams = sensor(np.array([600.0, 0.0, 200.0]))
    plan = plan_cycle(beams, D_MM, [600, 0, 200], [10.0])
    sweep = plan[0]

    def rocking(s: float) -> np.ndarray:
        T = sweep.pose_at(s)
        T[:3, :3] = T[:3, :3] @ Rotation.from_euler("x", 1.0 * s, degrees=True).as_matrix()
        return T

    ev = trigger_events(rocking, sweep, [0, 0, 100], [0, 0, 1], beams, D_MM)
    assert [e.edge for e in ev] == ["enter", "leave"]
    for e in ev:
        c = e.T_base_flange[:3, :3] @ [0, 0, 100] + e.T_base_flange[:3, 3]
        sigma, _, _ = axis_beam_geometry(c, e.T_base_flange[:3, 2], as_beams(beams)["by"])
        assert abs(sigma) == pytest.approx(3.0, abs=1e-9)


# ------------------------------------------------------------------ exact recovery


@pytest.mark.parametrize("config", CONFIGS,
                         ids=[f"{r}-{i % 2}" for i, (r, _) in enumerate(CONFIGS)])
def test_closed_form_and_fit_recover_a_random_tool_exactly(config, rng):
    for trial in range(2):
        tcp, a = random_tool(rng)
        flange_poses, ids, edges, vel, beams = measure(config, tcp, a, yaw_deg=17.0 * trial)
        closed = light_barrier_two_heights(flange_poses, ids, edges, beams, D_MM, vel)
        fitted = tcp_light_barrier(flange_poses, ids, edges, beams, D_MM, vel)
        blind = tcp_light_barrier(flange_poses, ids, edges, beams, D_MM)  # no velocities
        for result in (closed, fitted, blind):
            pos_mm, ang_deg = errors(result, tcp, a)
            assert pos_mm < 1e-6 and ang_deg < 1e-6
            assert result.report.max_error_mm < 1e-6
        ex = fitted.report.extras
        assert ex["runout_deg"] == pytest.approx(axis_angle_deg(a, [0, 0, 1]), abs=1e-6)
        assert ex["offset_mm"] == pytest.approx(np.hypot(*tcp[:2]), abs=1e-6)
        assert closed.report.extras["diameter_measured_mm"] == pytest.approx(D_MM, abs=1e-6)


def test_paper_equations_projection_angles_and_xy_euler(rng):
    """(10) from the plane offsets, (11) R = Ry(theta) Rx(phi) maps flange z onto the axis,
    (12) the offset at the flange, (13) TCP = base point + Z_h a."""
    tcp, a = random_tool(rng)
    flange_poses, ids, edges, vel, beams = measure(CONFIGS[0], tcp, a, heights=(10.0, 25.0, 40.0))
    ex = light_barrier_two_heights(flange_poses, ids, edges, beams, D_MM, vel).report.extras
    (z1, dx1, dy1), *_, (z2, dx2, dy2) = ex["planes"]
    assert len(ex["planes"]) == 3
    theta_x, theta_y = np.arctan((dx2 - dx1) / (z2 - z1)), np.arctan((dy2 - dy1) / (z2 - z1))
    assert np.degrees([theta_x, theta_y]) == pytest.approx([ex["theta_x_deg"], ex["theta_y_deg"]],
                                                           abs=1e-9)
    R = Rotation.from_euler("xy", [ex["phi_deg"], ex["theta_deg"]], degrees=True)
    assert R.apply([0, 0, 1]) == pytest.approx(a, abs=1e-9)
    phi = -np.degrees(np.arctan(np.tan(theta_y) * np.cos(theta_x)))
    assert ex["phi_deg"] == pytest.approx(phi, abs=1e-9)
    base = [dx1 - z1 * np.tan(theta_x), dy1 - z1 * np.tan(theta_y), 0.0]
    assert ex["base_point_mm"] == pytest.approx(base, abs=1e-9)
    assert base + ex["tool_height_mm"] * a == pytest.approx(tcp, abs=1e-6)
    assert runout_angles_deg(a)["runout_deg"] == pytest.approx(ex["runout_deg"], abs=1e-9)


def test_fit_handles_orientation_changing_between_passes(rng):
    """Each pass at its own flange orientation: the closed form refuses, the fit is exact."""
    tcp, a = random_tool(rng)
    center = np.array([500.0, 50.0, 300.0])
    beams = sensor(center, yaw_deg=30.0, angle_deg=75.0)
    passes = []
    for k, R in enumerate(Rotation.from_euler("xyz", rng.uniform(-12, 12, (5, 3)), degrees=True)):
        R0 = (R * Rotation.from_euler("x", 180, degrees=True)).as_matrix()
        nominal = np.eye(4)
        nominal[:3, 3] = tcp.round()
        plan = plan_cycle(beams, D_MM, center, [15.0 + 10 * k], flange_rotation=R0,
                          nominal_tool=nominal, directions_deg=(10.0 + 40 * k,), both_ways=False,
                          tip_axis_flange=(tcp, a))
        passes += list(plan[:-1]) + ([plan[-1]] if k == 0 else [])
    flange_poses, ids, edges, vel = run(passes, tcp, a, beams)
    with pytest.raises(CalibrationError) as err:
        light_barrier_two_heights(flange_poses, ids, edges, beams, D_MM, vel)
    assert err.value.loc[0] == "flange_poses" and "constant" in err.value.reason
    result = tcp_light_barrier(flange_poses, ids, edges, beams, D_MM, vel)
    pos_mm, ang_deg = errors(result, tcp, a)
    assert pos_mm < 1e-6 and ang_deg < 1e-6


def test_fit_handles_tilted_skew_beams(rng):
    """Beams 6 and 4 deg off level, 7 mm apart in height: the closed form refuses, the fit
    (with or without velocities) is exact."""
    tcp, a = random_tool(rng)
    center = np.array([450.0, -100.0, 250.0])
    tilt = Rotation.from_euler("yx", [[6, 0], [0, -4]], degrees=True)
    beams = {"bx": (center, tilt[0].apply([1, 0, 0])),
             "by": (center + [0, 0, 7.0], tilt[1].apply([0, 1, 0]))}
    nominal = np.eye(4)
    nominal[:3, 3] = tcp.round()
    R0 = Rotation.from_euler("xz", [180, 40], degrees=True).as_matrix()
    plan = plan_cycle(beams, D_MM, center, [12.0, 30.0, 45.0], nominal_tool=nominal,
                      flange_rotation=R0, tip_axis_flange=(tcp, a), directions_deg=(0, 90, 45))
    flange_poses, ids, edges, vel = run(plan, tcp, a, beams)
    with pytest.raises(CalibrationError) as err:
        light_barrier_two_heights(flange_poses, ids, edges, beams, D_MM, vel)
    assert err.value.loc[0] == "beams" and "off level" in err.value.reason
    for velocities in (vel, None):
        result = tcp_light_barrier(flange_poses, ids, edges, beams, D_MM, velocities)
        pos_mm, ang_deg = errors(result, tcp, a)
        assert pos_mm < 1e-6 and ang_deg < 1e-6


def test_one_way_passes_name_every_kind_of_one_way_pass(rng):
    """Exact either way; one_way_passes names the sweeps when every beam was crossed one way,
    and the tip search when it ran one way (the standard cycle's single search down)."""
    tcp, a = random_tool(rng)
    for both_ways in (False, True):
        flange_poses, ids, edges, vel, beams = measure(CONFIGS[3], tcp, a, both_ways=both_ways)
        result = tcp_light_barrier(flange_poses, ids, edges, beams, D_MM, vel)
        assert errors(result, tcp, a)[0] < 1e-6
        (w,) = result.report.warnings
        assert w.code == "one_way_passes" and w.severity == "warning"
        assert "tip search" in w.message
        assert ("every beam was crossed in one direction" in w.message) == (not both_ways)


def late(flange_poses, vel, mm):
    """Every trigger recorded ``mm`` late: the flange moved on along the TCP velocity (the
    flange orientation is constant during each pass, so it moves as the TCP does)."""
    out = flange_poses.copy()
    out[:, :3, 3] += mm * vel / np.linalg.norm(vel, axis=1, keepdims=True)
    return out


def with_tip_back(passes):
    """The passes plus the last one (the tip search) run backwards: up, out of the beam."""
    tip = passes[-1]
    return list(passes) + [dataclasses.replace(tip, start_flange=tip.end_flange,
                                               end_flange=tip.start_flange)]


def test_late_triggers_with_a_one_way_tip_search_are_flagged(rng):
    """All triggers 0.2 mm late, sweeps both ways: a tip search one way moves the TCP 0.2 mm
    along the axis unseen (one_way_passes names it); searching back up as well reveals the
    latency in the residuals and puts the TCP back."""
    tcp, a = random_tool(rng)
    robot, q = CONFIGS[1]
    T = forward_kinematics(ROBOTS[robot], q)
    nominal = np.eye(4)
    nominal[2, 3] = round(float(np.linalg.norm(tcp)) / 10.0) * 10.0
    center = T[:3, :3] @ nominal[:3, 3] + T[:3, 3] + np.array([0.0, 0.0, 25.0])
    beams = sensor(center)
    plan = plan_cycle(beams, D_MM, center, (10.0, 40.0), flange_rotation=T[:3, :3],
                      nominal_tool=nominal, tip_axis_flange=(tcp, a))
    flange_poses, ids, edges, vel = run(plan, tcp, a, beams)
    rep = tcp_light_barrier(late(flange_poses, vel, 0.2), ids, edges, beams, D_MM, vel)
    along = tool_frame(tcp, a)[:3, :3].T @ (rep.frame[:3, 3] - tcp)  # in the tool frame
    assert abs(along[2]) == pytest.approx(0.2, abs=0.01) and np.hypot(*along[:2]) < 0.01
    (w,) = rep.report.warnings
    assert w.code == "one_way_passes" and "every tip search moved towards the tip" in w.message
    flange_poses, ids, edges, vel = run(with_tip_back(plan), tcp, a, beams)
    assert edges.count("tip") == 2
    both = tcp_light_barrier(late(flange_poses, vel, 0.2), ids, edges, beams, D_MM, vel)
    assert both.report.warnings == ()
    assert errors(both, tcp, a)[0] < 0.01  # the two searches bracket the latency
    assert both.report.sigma_mm > 0.15  # and the residuals show it


def test_wrong_shaft_diameter_is_flagged_by_the_fit(rng):
    """6.2 mm given for a 6.0 mm shaft: the fit measures the diameter from the enter/leave
    triggers and names tool_diameter_mm; the right diameter raises nothing."""
    tcp, a = random_tool(rng)
    flange_poses, ids, edges, vel, beams = measure(CONFIGS[0], tcp, a)
    noisy = flange_poses.copy()
    noisy[:, :3, 3] += rng.normal(0.0, 0.005, (len(noisy), 3))
    for velocities in (vel, None):
        wrong = tcp_light_barrier(noisy, ids, edges, beams, 6.2, velocities).report
        assert wrong.extras["diameter_measured_mm"] == pytest.approx(D_MM, abs=0.01)
        (w,) = [f for f in wrong.warnings if f.code == "diameter_mismatch"]
        assert w.loc == ("tool_diameter_mm",) and "6.200 mm given" in w.message
        right = tcp_light_barrier(noisy, ids, edges, beams, D_MM, velocities).report
        assert "diameter_mismatch" not in {f.code for f in right.warnings}
        assert right.extras["diameter_standard_error_mm"] < 0.01
    closed = light_barrier_two_heights(noisy, ids, edges, beams, 6.2, vel).report
    assert "diameter_mismatch" in {f.code for f in closed.warnings}


@pytest.mark.parametrize("solve", [tcp_light_barrier, light_barrier_two_heights])
def test_paper_offset_and_runout_of_hand_built_tools(solve):
    """The paper's terms: pure runout (1.5 deg about flange +Y, L 150: the axis through the
    flange centre) has offset 0, where pendant's offset_mm is 150 sin 1.5 deg = 3.93 mm;
    pure offset (0.8, -0.5) mm parallel to flange z has runout 0; runout about flange +X
    (counter-clockwise) tilts the axis towards flange -y and is the paper's θx."""
    runout = Rotation.from_euler("y", 1.5, degrees=True).apply([0.0, 0.0, 1.0])
    tools = {"runout": (150.0 * runout, runout),
             "offset": (np.array([0.8, -0.5, 150.0]), np.array([0.0, 0.0, 1.0])),
             "runout_x": (150.0 * Rotation.from_euler("x", 1.2, degrees=True).apply([0, 0, 1.0]),
                          Rotation.from_euler("x", 1.2, degrees=True).apply([0, 0, 1.0]))}
    ex = {}
    for name, (tcp, a) in tools.items():
        flange_poses, ids, edges, vel, beams = measure(CONFIGS[0], tcp, a)
        ex[name] = solve(flange_poses, ids, edges, beams, D_MM, vel).report.extras
    r, o, rx = ex["runout"], ex["offset"], ex["runout_x"]
    assert r["paper_offset_mm"] == pytest.approx(0.0, abs=1e-6)
    assert r["offset_mm"] == pytest.approx(150 * np.sin(np.radians(1.5)), abs=1e-6)  # 3.93
    assert r["paper_runout_deg"] == pytest.approx(1.5, abs=1e-6)
    assert r["paper_theta_y_deg"] == pytest.approx(1.5, abs=1e-6)  # pendant's theta_x_deg
    assert r["theta_x_deg"] == pytest.approx(1.5, abs=1e-6)
    assert r["paper_theta_x_deg"] == pytest.approx(0.0, abs=1e-6)
    assert r["paper_tool_height_mm"] == pytest.approx(150.0, abs=1e-6)
    assert [o["paper_offset_x_mm"], o["paper_offset_y_mm"]] == pytest.approx([0.8, -0.5], abs=1e-6)
    assert o["paper_offset_mm"] == pytest.approx(np.hypot(0.8, 0.5), abs=1e-6)
    assert o["paper_runout_deg"] == pytest.approx(0.0, abs=1e-6)
    assert o["paper_theta_x_deg"] == pytest.approx(0.0, abs=1e-6)
    assert o["paper_theta_y_deg"] == pytest.approx(0.0, abs=1e-6)
    assert rx["paper_theta_x_deg"] == pytest.approx(1.2, abs=1e-6)
    assert rx["axis_flange"][1] < 0 and rx["paper_theta_y_deg"] == pytest.approx(0.0, abs=1e-6)
    assert rx["paper_offset_mm"] == pytest.approx(0.0, abs=1e-6)


# ------------------------------------------------------------------ noise, bounds, bad trigger


def test_noisy_triggers_recovered_within_the_stated_bounds(rng):
    hits = 0
    for trial in range(6):
        tcp, a = random_tool(rng)
        flange_poses, ids, edges, vel, beams = measure(CONFIGS[trial % 4], tcp, a,
                                                       heights=(10.0, 25.0, 40.0),
                                                       directions=(0.0, 90.0, 45.0))
        noisy = flange_poses.copy()
        noisy[:, :3, 3] += rng.normal(0.0, 0.01, (len(noisy), 3))
        result = tcp_light_barrier(noisy, ids, edges, beams, D_MM, vel)
        rep = result.report
        pos_mm, ang_deg = errors(result, tcp, a)
        assert 0.003 < rep.sigma_mm < 0.03
        assert pos_mm < 0.1 and ang_deg < 0.05
        hits += pos_mm <= rep.position_bound95_mm and ang_deg <= rep.angle_bound95_deg
        assert rep.covariance.shape == (5, 5) and rep.bad_point is None
    assert hits >= 5


def test_one_displaced_trigger_is_named(rng):
    tcp, a = random_tool(rng)
    flange_poses, ids, edges, vel, beams = measure(CONFIGS[2], tcp, a, heights=(10.0, 25.0, 40.0))
    noisy = flange_poses.copy()
    noisy[:, :3, 3] += rng.normal(0.0, 0.005, (len(noisy), 3))
    noisy[5, :3, 3] += 0.5 * vel[5] / np.linalg.norm(vel[5])  # a late trigger
    rep = tcp_light_barrier(noisy, ids, edges, beams, D_MM, vel).report
    assert rep.bad_point is not None and rep.bad_point.index == 5
    assert np.linalg.norm(rep.bad_point.refit_frame[:3, 3] - tcp) < 0.05
    assert "re-teach" in rep.guidance


# ------------------------------------------------------------------ refusals


@pytest.fixture
def cycle(rng):
    tcp, a = random_tool(rng)
    return measure(CONFIGS[0], tcp, a)


@pytest.mark.parametrize("solve", [tcp_light_barrier, light_barrier_two_heights])
def test_without_a_tip_search_the_height_is_refused(cycle, solve):
    flange_poses, ids, edges, vel, beams = cycle
    with pytest.raises(CalibrationError) as err:
        solve(flange_poses[:-1], ids[:-1], edges[:-1], beams, D_MM, vel[:-1])
    assert err.value.loc == ("edges",) and "add a tip search" in err.value.reason


@pytest.mark.parametrize("solve", [tcp_light_barrier, light_barrier_two_heights])
def test_sweeps_at_one_height_leave_the_runout_unobservable(rng, solve):
    tcp, a = random_tool(rng)
    flange_poses, ids, edges, vel, beams = measure(CONFIGS[0], tcp, a)
    top = flange_poses[0][2, 3] - 1.0  # the first height's sweeps, and the tip search
    keep = [k for k, T in enumerate(flange_poses) if edges[k] == "tip" or T[2, 3] > top]
    with pytest.raises(CalibrationError) as err:
        solve(flange_poses[keep], [ids[k] for k in keep], [edges[k] for k in keep], beams, D_MM,
              vel[keep])
    assert err.value.loc == ("flange_poses",) and "runout is unobservable" in err.value.reason


def test_bad_inputs_are_named(cycle):
    flange_poses, ids, edges, vel, beams = cycle
    bad = flange_poses.copy()
    bad[3, 0, 3] = np.nan
    with pytest.raises(CalibrationError) as err:
        tcp_light_barrier(bad, ids, edges, beams, D_MM, vel)
    assert err.value.loc == ("flange_poses", 3, 0, 3)
    with pytest.raises(CalibrationError) as err:
        tcp_light_barrier(flange_poses, ids[:2] + ["bz"] + ids[3:], edges, beams, D_MM, vel)
    assert err.value.loc == ("beam_ids", 2) and "unknown beam 'bz'" in err.value.reason
    with pytest.raises(CalibrationError) as err:
        tcp_light_barrier(flange_poses, ids, edges[:1] + ["exit"] + edges[2:], beams, D_MM, vel)
    assert err.value.loc == ("edges", 1)
    with pytest.raises(CalibrationError) as err:
        tcp_light_barrier(flange_poses, ids, edges[:-1], beams, D_MM, vel)
    assert err.value.loc == ("edges",) and "entries" in err.value.reason
    with pytest.raises(CalibrationError) as err:
        tcp_light_barrier(flange_poses, ids, edges, beams, 0.0, vel)
    assert err.value.loc == ("tool_diameter_mm",)
    vel_nan = vel.copy()
    vel_nan[0, 1] = np.inf
    with pytest.raises(CalibrationError) as err:
        tcp_light_barrier(flange_poses, ids, edges, beams, D_MM, vel_nan)
    assert err.value.loc == ("velocities_mm_s", 0, 1)
    with pytest.raises(CalibrationError) as err:
        tcp_light_barrier(flange_poses, ids, edges,
                          {"bx": beams["bx"], "by": ([0, 0, 0], [0, 0, 0])}, D_MM, vel)
    assert err.value.loc == ("beams", "by", "direction")


def test_one_beam_direction_only_is_refused(rng):
    tcp, a = random_tool(rng)
    flange_poses, ids, edges, vel, beams = measure(CONFIGS[0], tcp, a)
    keep = [k for k in range(len(ids)) if ids[k] == "bx"]  # the tip search is on bx too
    for solve in (tcp_light_barrier, light_barrier_two_heights):
        with pytest.raises(CalibrationError) as err:
            solve(flange_poses[keep], [ids[k] for k in keep], [edges[k] for k in keep], beams,
                  D_MM, vel[keep])
        assert "unobservable" in err.value.reason


def test_closed_form_refuses_a_tilted_beam(cycle):
    flange_poses, ids, edges, vel, beams = cycle
    point, _ = beams["by"]
    tilted = dict(beams, by=(point, [0.0, 1.0, 0.1]))
    with pytest.raises(CalibrationError) as err:
        light_barrier_two_heights(flange_poses, ids, edges, tilted, D_MM, vel)
    assert err.value.loc == ("beams", "by", "direction")

