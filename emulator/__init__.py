"""The emulated robot controller: its arm, its cell's hidden truth, its motions and its state.

Pure: numpy/scipy and :mod:`solvers` only, no web and no database. :mod:`emulator.controller`
holds the cell, the motions (jog, approach, the light-barrier cycle) and the arm's hidden
physics; :mod:`emulator.state` the typed state the service loads and saves under the
controller's row lock. ``from emulator import jog`` etc. work as before from
``server.emulator`` (the module moved here unchanged).
"""

from emulator.controller import (APPROACH_S, CARTESIAN_AXES, DEMO_ROBOT, THERMAL_WARMUP_S,  # noqa: F401
                                 TOUCH_UP_S, Cell, CycleRun, Target, RobotPhysics, approach,
                                 build_cell, cell_for, home_joints, imperfections_document,
                                 imperfections_from_document, jog, motion_duration_s,
                                 robot_from_custom, rot, run_beam_cycle, solve_ik, tcp_pose,
                                 true_pose, updated_signs)
from emulator.state import ControllerState, after_cycle, moved, touched_up  # noqa: F401
