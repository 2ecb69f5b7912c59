"""Optimistic concurrency for people: a write names the version it read (``If-Match``).

Controllers, slots and sessions carry a ``version`` (revision 0003) that every change bumps;
its tag is the strong ETag ``"<version>"``. An operation given an ``if_match`` that no longer
matches is refused with :class:`PreconditionFailed` carrying the current value (REST answers
412 with it, so the client can show it and ask again); a slot write without one is refused
with :class:`PreconditionRequired` (REST's 428, RFC 6585): a blind overwrite of a slot someone
else just calibrated is the loss this prevents. ``*`` means "whatever it holds now"
(RFC 9110, 13.1.1) and is the explicit way to overwrite.

The current value is the face's to present: an operation takes ``present`` (the face's view
of the row, e.g. REST's ``...Out`` builder) and calls it only when it refuses.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from pydantic import BaseModel

Row = TypeVar("Row")
Present = Callable[[Any], BaseModel]  # the face's view of a row, for a refused write


def etag(version: int) -> str:
    return f'"{int(version)}"'


def matches(if_match: str, version: int) -> bool:
    """RFC 9110 strong comparison: ``*`` or one of the listed tags equals ``"<version>"``."""
    if if_match.strip() == "*":
        return True
    return etag(version) in (t.strip() for t in if_match.split(","))


class PreconditionFailed(Exception):
    """412: the resource changed since the client read it; carries the current value."""

    def __init__(self, what: str, sent: str, version: int, current: dict[str, Any]):
        super().__init__(what)
        self.what, self.sent, self.version, self.current = what, sent, version, current


class PreconditionRequired(Exception):
    """428: a slot write without ``If-Match``."""

    def __init__(self, what: str):
        super().__init__(what)
        self.what = what


def check(if_match: str | None, version: int, current: Callable[[], BaseModel | None],
          what: str, required: bool = False) -> None:
    """Refuse the write unless ``if_match`` matches ``version`` (412), or is missing on a
    ``required`` write (428). ``what`` names the resource ("tool 6 of controller 1")."""
    if if_match is None:
        if required:
            raise PreconditionRequired(what)
        return
    if not matches(if_match, version):
        value = current()
        raise PreconditionFailed(what, if_match, version,
                                 {} if value is None else value.model_dump(mode="json"))


def check_row(if_match: str | None, row: Row, present: Present | None, what: str,
              required: bool = False) -> Row:
    """:func:`check` of a versioned ``row``, its current value shown by ``present``; the row."""
    check(if_match, row.version, lambda: None if present is None else present(row),  # type: ignore[attr-defined]
          what, required)
    return row
