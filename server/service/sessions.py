"""The operations of a menu run (a calibration session): touch up a step.

Read top to bottom, a touch-up is: the controller and the session (under the request's write
lock), the caller's ``If-Match``, the step to fill, the flange pose (the emulated arm's joints,
or joints / a flange pose recorded on a real controller), the point written, and the emulated
controller's clock advanced. One transaction: the request's.
"""

from __future__ import annotations

from sqlalchemy.orm import Session

import emulator
from db import crud
from db.models import CalibSession
from server.api.preconditions import check
from server.api.routers.common import (check_step, flange_pose_of, next_step, session_out, state_of,
                                   store_state)
from server.api.schemas import TouchUpIn
from solvers.errors import CalibrationError


def touch_up(db: Session, controller_id: int, session_id: int, body: TouchUpIn,
             if_match: str | None = None) -> CalibSession:
    """Fill a step of session ``session_id`` (``body.step``, default the next empty one) with
    the emulated robot's current joints, or with ``body.joints_deg`` / ``body.flange_pose``
    recorded on a real controller. A re-teach overwrites the step; a computed result becomes
    stale. 412 when ``if_match`` is not the session's version; 409 when it is closed."""
    c = crud.get_controller(db, controller_id)
    s = crud.get_session(db, controller_id, session_id)
    check(if_match, s.version, lambda: session_out(s), f"session {s.id} of controller {c.id}")
    crud.require_open(s)
    if body.joints_deg is not None and body.flange_pose is not None:
        raise CalibrationError(("flange_pose",), "give joints_deg or flange_pose, not both")
    step = next_step(s) if body.step is None else body.step
    check_step(s, step)
    if body.flange_pose is not None:
        pose, joints, source = body.flange_pose.to_pose(), None, "flange_pose"
    elif body.joints_deg is not None:
        joints, source = list(body.joints_deg), "joints"
        pose = flange_pose_of(c, joints)
    else:
        joints, source = list(c.joints_deg), "touch_up"
        pose = flange_pose_of(c, joints)
    emulated = source == "touch_up"
    crud.put_point(db, s, step, source, pose.as_array(), joints, t_s=float(c.clock_s or 0.0),
                   motion_sign=c.motion_sign if emulated else None,
                   external_axes=c.external_axes if emulated else body.external_axes)
    store_state(c, emulator.touched_up(state_of(c)))
    return s
