"""The emulated controller as its own pure package: no web, no database; its typed state's
transitions are what the service stores."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import emulator
from emulator import ControllerState, moved, touched_up
from solvers.robots import ROBOTS

ARM = ROBOTS["kuka_kr6_r900_sixx"]


def test_the_package_imports_no_web_and_no_database():
    code = ("import sys, emulator; bad = [m for m in ('fastapi', 'starlette', 'sqlalchemy', "
            "'server', 'db') if m in sys.modules]; print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_a_motion_turns_the_flanks_of_the_joints_that_moved_and_advances_the_clock():
    home = tuple(emulator.home_joints(ARM))
    s0 = ControllerState(home, clock_s=5.0, motion_sign=(-1.0,) * 6, motion_count=3)
    q = np.array(home) + [2.0, 0, -1.0, 0, 0, 0]
    s1 = moved(ARM, s0, q, extra_s=1.5)
    assert s1.joints_deg == tuple(q)
    assert s1.motion_sign == (1.0, -1.0, -1.0, -1.0, -1.0, -1.0)  # A3 moved down: still -1
    assert s1.motion_count == 4
    assert s1.clock_s == pytest.approx(5.0 + emulator.motion_duration_s(ARM, home, q) + 1.5)
    assert s0.joints_deg == home  # frozen: a transition makes a new state


def test_standing_still_keeps_the_flanks_and_a_touch_up_takes_its_time():
    home = tuple(emulator.home_joints(ARM))
    s0 = ControllerState(home)
    s1 = moved(ARM, s0, home)
    assert s1.motion_sign == (0.0,) * 6 and s1.clock_s == 0.0 and s1.motion_count == 1
    assert touched_up(s1).clock_s == emulator.TOUCH_UP_S
