"""External kinematics: turntables, two-axis positioners and linear units (KUKA *Calibrate >
External kinematics*, ABB mechanical-unit calibration).

- ``ext.root_point``          :func:`root_point` -- a rotary axis from one mark (plane + circle).
- ``ext.root_point_numeric``  :func:`root_point_numeric` -- the root frame typed in.
- ``ext.offset``              :func:`offset` -- a 3-point base in the kinematic's flange frame.
- ``ext.offset_numeric``      :func:`offset_numeric` -- that base typed in.
- ``ext.linear_unit``         :func:`linear_unit` -- rail direction, encoder scale, straightness.
- ``ext.positioner_2axis``    :func:`positioner_2axis` -- tilt then turn, with their common normal.

The geometry (plane and circle fits) is in :mod:`solvers.external.circle`; a simulator with
hidden errors in :mod:`solvers.external_sim`. See docs/methods/external.md.
"""

from solvers.external.linear_unit import linear_unit
from solvers.external.offset import offset, offset_numeric
from solvers.external.positioner import positioner_2axis
from solvers.external.root_point import root_point, root_point_numeric

__all__ = ["root_point", "root_point_numeric", "offset", "offset_numeric", "linear_unit",
           "positioner_2axis"]
