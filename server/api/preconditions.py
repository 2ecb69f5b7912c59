"""Optimistic concurrency for people: ``ETag`` on what they read, ``If-Match`` on what they write.

Controllers, slots and sessions carry a ``version`` (revision 0003) that every change bumps;
its ETag is the strong tag ``"<version>"``. A write with ``If-Match`` that no longer matches is
refused with **412** and the current value (so the client can show it and ask again); a slot
write without ``If-Match`` is refused with **428** (RFC 6585): a blind overwrite of a slot
someone else just calibrated is the loss this prevents. ``If-Match: *`` means "whatever it
holds now" (RFC 9110, 13.1.1) and is the explicit way to overwrite.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any

from fastapi import Header, Response
from pydantic import BaseModel
from sqlalchemy.orm import Session

IfMatch = Annotated[str | None, Header(
    alias="If-Match", description='the ETag of the version you read (``"3"``), or ``*``; '
                                  'required on slot writes (428 without), 412 when stale')]


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


def check(if_match: str | None, version: int, current: Callable[[], BaseModel], what: str,
          required: bool = False) -> None:
    """Refuse the write unless ``if_match`` matches ``version`` (412), or is missing on a
    ``required`` write (428). ``what`` names the resource ("tool 6 of controller 1")."""
    if if_match is None:
        if required:
            raise PreconditionRequired(what)
        return
    if not matches(if_match, version):
        raise PreconditionFailed(what, if_match, version, current().model_dump(mode="json"))


def set_etag(response: Response, db: Session, obj: Any) -> None:
    """Set ``ETag`` of ``obj`` (flushed first, so a change made by this request counts)."""
    db.flush()
    response.headers["ETag"] = etag(obj.version)
