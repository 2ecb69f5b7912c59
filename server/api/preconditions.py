"""Optimistic concurrency for people: ``ETag`` on what they read, ``If-Match`` on what they write.

The check itself is the service's (``server.service.preconditions``); here are the HTTP sides:
the ``If-Match`` header (428 without it on a slot write, 412 when stale) and the ``ETag`` of
an answer.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import Header, Response
from sqlalchemy.orm import Session

from server.service.preconditions import (PreconditionFailed, PreconditionRequired, check, etag,
                                          matches)

__all__ = ["IfMatch", "PreconditionFailed", "PreconditionRequired", "check", "etag", "matches",
           "set_etag"]

IfMatch = Annotated[str | None, Header(
    alias="If-Match", description='the ETag of the version you read (``"3"``), or ``*``; '
                                  'required on slot writes (428 without), 412 when stale')]


def set_etag(response: Response, db: Session, obj: Any) -> None:
    """Set ``ETag`` of ``obj`` (flushed first, so a change made by this request counts)."""
    db.flush()
    response.headers["ETag"] = etag(obj.version)
