"""The operations on a controller itself: create one, delete one, give its emulated arm
imperfections, set its emulated clock, set its external machines' hidden errors."""

from __future__ import annotations

from typing import Any

from sqlalchemy.orm import Session

from db import crud
from db.models import Controller
from emulator import external as ext_emu
from emulator import (home_joints, imperfections_document, imperfections_from_document,
                      robot_from_custom)
from server.auth import audit
from server.service import external
from server.service.preconditions import Present
from server.service.robot import controller, robot_of
from solvers.errors import CalibrationError
from solvers.physics import Imperfections
from solvers.robots import ROBOTS


def create_controller(db: Session, name: str, robot: str | None, custom_robot: dict | None,
                      cell_seed: int, external_axes: bool = False) -> Controller:
    """A new controller with a library arm (``robot``) or a custom DH table (``custom_robot``,
    which wins), at HOME; ``external_axes`` gives its cell E1..E4."""
    key = None if custom_robot else robot
    if custom_robot is None and key is None:
        raise CalibrationError(("robot",), "give robot (a library key) or custom_robot (a DH "
                               "table); both are null")
    if key is not None and key not in ROBOTS:
        library = ", ".join(sorted(ROBOTS))
        raise CalibrationError(("robot",), f"unknown robot {key!r}; the library has {library}")
    arm = robot_from_custom(custom_robot) if custom_robot else ROBOTS[key]  # type: ignore[index]
    c = crud.create_controller(db, name, key, custom_robot, cell_seed, home_joints(arm))
    if external_axes:
        external.enable(db, c, arm.reach_mm)
    return c


def delete_controller(db: Session, controller_id: int, if_match: str | None = None,
                      present: Present | None = None) -> None:
    """Remove a controller with its tables, history and sessions."""
    crud.delete_controller(db, controller(db, controller_id, if_match, present))


def set_physics(db: Session, controller_id: int, document: dict[str, Any],
                if_match: str | None = None, present: Present | None = None) -> Controller:
    """Give the emulated arm the imperfections of ``document`` (``{}`` = the rigid arm again),
    checked against the arm (CalibrationError naming the field)."""
    c = controller(db, controller_id, if_match, present)
    imp = imperfections_from_document(document, robot_of(c).dof)
    c.physics = None if imp == Imperfections() else imperfections_document(imp)
    return c


def set_clock(db: Session, controller_id: int, clock_s: float, if_match: str | None = None,
              present: Present | None = None) -> Controller:
    """Set the emulated clock: 0 = just powered (cold), the warm-up or more = warm."""
    c = controller(db, controller_id, if_match, present)
    before = float(c.clock_s or 0.0)
    c.clock_s = float(clock_s)
    audit.record(db, "emulator.clock", controller_id=c.id, before={"clock_s": before},
                 after={"clock_s": c.clock_s})
    return c


def set_external_errors(db: Session, controller_id: int, errors: dict[str, Any],
                        if_match: str | None = None, present: Present | None = None
                        ) -> tuple[Controller, dict[str, dict[str, float]]]:
    """Replace the external machines' hidden errors (checked, naming the field); the controller
    and the errors. ``if_match`` is the controller's ETag, as for its physics."""
    c = controller(db, controller_id, if_match, present)
    external.values_of(c, "controller_id")
    doc = ext_emu.check_errors(errors)
    audit.record(db, "emulator.external", controller_id=c.id,
                 before={"external_errors": c.external_errors}, after={"external_errors": doc})
    c.external_errors = doc
    return c, doc
