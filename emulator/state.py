"""The emulated controller's state, typed: what it remembers between two requests.

A :class:`ControllerState` is loaded from the controller's row and saved back in one
request, while that request holds the row lock (``server.api.deps``), so two processes never
move the robot from the same stale joints. Its transitions are pure functions: a motion
(:func:`moved`), a touch-up (:func:`touched_up`) and the light-barrier cycle
(:func:`after_cycle`). The database and the web stay outside this package.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from emulator.controller import TOUCH_UP_S, CycleRun, motion_duration_s, updated_signs
from solvers.dh import RobotModel


@dataclass(frozen=True)
class ControllerState:
    """Joints shown (deg), the emulated clock (s since power-on), the direction each joint
    last moved (+1, -1, 0 = unknown; the backlash flank, or None before the first motion) and
    the count of motions (it seeds the operator's aim)."""

    joints_deg: tuple[float, ...]
    clock_s: float = 0.0
    motion_sign: tuple[float, ...] | None = None
    motion_count: int = 0

    def signs(self) -> np.ndarray:
        """``motion_sign`` as an array (zeros before the first motion)."""
        n = len(self.joints_deg)
        return np.zeros(n) if self.motion_sign is None else np.array(self.motion_sign, float)


def moved(robot: RobotModel, state: ControllerState, q: object,
          extra_s: float = 0.0) -> ControllerState:
    """The state after commanding joints ``q``: the joints that moved turn their flank, the
    clock advances by the move's time plus ``extra_s``, one more motion is counted.

    >>> from solvers.robots import ROBOTS
    >>> s = moved(ROBOTS["kuka_kr6_r900_sixx"], ControllerState((0.0,) * 6), [10, 0, 0, 0, 0, 0])
    >>> s.motion_sign[:2], s.motion_count, s.clock_s > 0
    ((1.0, 0.0), 1, True)
    """
    q_new = tuple(float(x) for x in q)  # type: ignore[union-attr]
    signs = updated_signs(state.signs(), state.joints_deg, q_new)
    return ControllerState(joints_deg=q_new,
                           clock_s=state.clock_s + motion_duration_s(robot, state.joints_deg,
                                                                     q_new) + extra_s,
                           motion_sign=tuple(float(v) for v in signs),
                           motion_count=state.motion_count + 1)


def touched_up(state: ControllerState) -> ControllerState:
    """The state after a touch-up: the clock advances by :data:`TOUCH_UP_S`."""
    return replace(state, clock_s=state.clock_s + TOUCH_UP_S)


def after_cycle(state: ControllerState, run: CycleRun) -> ControllerState:
    """The state after the light-barrier cycle ``run`` (where it stopped, its clock)."""
    return ControllerState(joints_deg=tuple(float(q) for q in run.joints_deg),
                           clock_s=float(run.clock_s),
                           motion_sign=tuple(float(v) for v in run.motion_sign),
                           motion_count=state.motion_count + 1)
