"""The one error every solver raises for bad input: it names the field and the reason."""

from __future__ import annotations


class CalibrationError(ValueError):
    """Bad or degenerate input to a solver.

    ``loc`` is the path of the offending field, named like the API fields
    (``("flange_poses", 3)``); ``reason`` says what is wrong in plain words.
    ``server/api/errors.py`` turns it into a 422 ``{"detail": [{"loc": [...], "msg": reason}]}``.

    Examples
    --------
    >>> e = CalibrationError(("flange_poses", 3), "within 2.1 deg of pose 0")
    >>> e.loc, e.reason
    (('flange_poses', 3), 'within 2.1 deg of pose 0')
    """

    def __init__(self, loc: tuple[str | int, ...], reason: str):
        super().__init__(f"{'.'.join(str(p) for p in loc)}: {reason}")
        self.loc = tuple(loc)
        self.reason = reason


class KinematicsError(CalibrationError):
    """A pose the robot cannot take: a joint limit, an unreachable target, a singularity."""
