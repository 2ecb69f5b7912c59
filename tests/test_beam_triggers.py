"""One beam-trigger simulator (solvers.beam_cycle): the emulated controller's light-barrier
cycle and the recording simulator switch the beams alike.

The same rigid arm, tool and beams: the emulator runs the paper's cycle (sweeps along base x
and y, then the tip search), the simulator its own passes (an oblique direction, here chosen
along base y, at four turns about the tool axis). Where their passes coincide (along +y and
-y at the same heights through the crossing) every trigger is at the same TCP position, and
a trigger latency moves it by ``latency * speed`` along the motion in both.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from emulator import RobotPhysics, build_cell, home_joints, run_beam_cycle
from server.formats.recording import parse_recording
from solvers.beam_cycle import plan_cycle, refine_trigger, trigger_events
from solvers.dh import forward_kinematics
from solvers.errors import CalibrationError, KinematicsError
from solvers.frames import Pose
from solvers.physics import Imperfections
from solvers.robots import ROBOTS
from solvers.simulate import simulate_recording

ROBOT = ROBOTS["kuka_kr6_r900_sixx"]
TOOL = Pose(z=180.0)  # true = nominal: the simulator's tool is its file's tool
D_MM = 10.0           # the emulator's half travel d + 20 equals the simulator's d/2 + 25
SPEED_MM_S = 20.0     # the emulator's plan speed
HEIGHTS_MM = (10.0, 40.0)
CROSSING = np.array([450.0, -150.0, 200.0])
# the simulator passes along u1 - 0.6 u2 (not the bisector): with these beams that is +y
_TH = np.radians(-45.0)
BEAMS = {"b1": (CROSSING, np.array([0.6 * np.cos(_TH), np.sqrt(1 - 0.36 * np.cos(_TH) ** 2), 0.0])),
         "b2": (CROSSING, np.array([np.cos(_TH), np.sin(_TH), 0.0]))}


def _key(beam: str, edge: str, v: np.ndarray, tcp: np.ndarray) -> tuple:
    """Which trigger: beam, edge, direction of motion, height of the sweep."""
    height = None if edge == "tip" else round(float(tcp[2]), 3)
    return beam, edge, tuple(np.round(v / np.linalg.norm(v), 6) + 0.0), height


def emulated(latency_ms: float) -> dict[tuple, np.ndarray]:
    """TCP at each trigger the emulated controller records (its cycle on a rigid arm)."""
    cell = dataclasses.replace(build_cell(ROBOT.name, float(ROBOT.reach_mm), 1),
                               T_flange_tool=TOOL.as_matrix())
    physics = RobotPhysics(Imperfections(trigger_latency_ms=latency_ms), 0.0, np.zeros(6))
    run = run_beam_cycle(ROBOT, cell, np.array(home_joints(ROBOT)), TOOL.as_matrix(), BEAMS,
                         D_MM, HEIGHTS_MM, physics)
    out = {}
    for e in run.triggers:
        tcp = (e.T_base_flange @ TOOL.as_matrix())[:3, 3]
        out[_key(e.beam_id, e.edge, e.tcp_velocity_mm_s, tcp)] = tcp
    return out


def simulated(latency_ms: float) -> list[tuple[tuple, np.ndarray]]:
    """TCP of each recorded sample of a simulated beam recording (rigid arm)."""
    sensor = {"beams": [{"id": k, "point_mm": p.tolist(), "direction": u.tolist()}
                        for k, (p, u) in BEAMS.items()], "tool_diameter_mm": D_MM}
    rec = parse_recording(simulate_recording(
        "beam", ROBOT, Imperfections(trigger_latency_ms=latency_ms), 18, seed=0, tool_mm=TOOL,
        sensor=sensor, heights=list(HEIGHTS_MM), speed_mm_s=SPEED_MM_S))
    tcp = forward_kinematics(rec.robot, rec.joints_deg, rec.tool)[:, :3, 3]
    return [(_key(str(b), str(e), v, c), c)
            for b, e, v, c in zip(rec.beam_ids, rec.edges, rec.tcp_velocity_mm_s, tcp)]


@pytest.fixture(scope="module")
def runs() -> dict:
    return {lat: (emulated(lat), simulated(lat)) for lat in (0.0, 50.0)}


@pytest.mark.parametrize("latency_ms", [0.0, 50.0])
def test_emulator_and_simulator_trigger_at_the_same_poses(runs, latency_ms):
    """16 sweep triggers (2 beams x enter/leave x 2 heights x both ways) and the tip on the
    emulator's tip beam: the same TCP to 1e-9 mm."""
    emu, sim = runs[latency_ms]
    matched = [(tcp, emu[key]) for key, tcp in sim if key in emu]
    assert len(matched) == 17  # the simulator also records the tip on b2; the emulator's
    # tip search stops at its first beam
    assert {key[1] for key, _ in sim if key in emu} == {"enter", "leave", "tip"}
    for tcp_sim, tcp_emu in matched:
        assert np.abs(tcp_sim - tcp_emu).max() < 1e-9


@pytest.mark.parametrize("which", [0, 1], ids=["emulator", "simulator"])
def test_latency_records_the_trigger_later_along_the_motion(runs, which):
    """50 ms at 20 mm/s: every recorded TCP 1 mm further along the commanded motion."""
    on_time, late = (dict(runs[lat][which]) if which else runs[lat][which] for lat in (0.0, 50.0))
    assert len(on_time) >= 17 and on_time.keys() == late.keys()
    for key, tcp in on_time.items():
        v = np.array(key[2]) * SPEED_MM_S
        assert np.abs(late[key] - (tcp + v * 0.05)).max() < 1e-9


# ------------------------------------------------------------------ the simulator's parts

BEAM_BY = {"by": ([600.0, 0.0, 200.0], [0.0, 1.0, 0.0])}


def test_a_beam_above_the_flange_plane_cuts_nothing():
    """The shaft ends at the flange: a 100 mm tool swept 150 mm below the beam triggers
    nothing, 40 mm below it triggers enter and leave."""
    low, high = plan_cycle(BEAM_BY, 6.0, [600, 0, 200], [40.0, 150.0], directions_deg=(0.0,),
                           both_ways=False)[:2]
    assert [e.edge for e in trigger_events(None, low, [0, 0, 100], [0, 0, 1], BEAM_BY, 6.0)] \
        == ["enter", "leave"]
    assert trigger_events(None, high, [0, 0, 100], [0, 0, 1], BEAM_BY, 6.0) == []


def test_refine_refuses_a_motion_that_never_switches_the_beam():
    sweep = plan_cycle(BEAM_BY, 6.0, [600, 0, 200], [40.0], directions_deg=(0.0,))[0]
    ev = trigger_events(None, sweep, [0, 0, 100], [0, 0, 1], BEAM_BY, 6.0)[0]
    with pytest.raises(KinematicsError) as err:  # the flange stands at the pass start
        refine_trigger(ev, lambda s: sweep.pose_at(0.0), sweep, [0, 0, 100], [0, 0, 1],
                       BEAM_BY, 6.0, loc=("sensor", "beams"))
    assert err.value.loc == ("sensor", "beams")
    assert "no enter trigger of beam 'by'" in err.value.reason


def test_negative_latency_is_refused_by_name():
    sweep = plan_cycle(BEAM_BY, 6.0, [600, 0, 200], [40.0], directions_deg=(0.0,))[0]
    with pytest.raises(CalibrationError) as err:
        trigger_events(None, sweep, [0, 0, 100], [0, 0, 1], BEAM_BY, 6.0, latency_ms=-1.0)
    assert err.value.loc == ("trigger_latency_ms",)
