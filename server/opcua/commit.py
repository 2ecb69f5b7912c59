"""CommitFrame: an OPC UA client writes a slot through the service's hand edit.

The same as ``PUT /controllers/{id}/tools|bases/{n}`` with ``If-Match``: the body is checked by
the API's ``EntryIn`` (one set of bounds), :func:`server.service.slots.edit_slot` writes it in
a write as every face runs one (:func:`server.service.transaction.writing`: SQLite ``BEGIN
IMMEDIATE``; the controller's row locked on PostgreSQL), a stale version is refused, and :func:`db.crud.change_entry` records history, the
audit (source ``opcua``) and the ``frame-committed`` event in that transaction.
"""

from __future__ import annotations

import logging
from typing import Any

from asyncua import ua
from pydantic import ValidationError
from sqlalchemy.orm import Session, sessionmaker

from db import crud
from server.api.schemas import EntryIn
from server.service import slots, transaction
from server.service.preconditions import PreconditionFailed, etag
from solvers.errors import CalibrationError

log = logging.getLogger("pendant.opcua")


def commit_frame(make_session: sessionmaker[Session], controller_id: int, table: str, number: int,
                 frame: Any, name: str | None, expected_version: int,
                 who: dict[str, Any]) -> int | ua.StatusCode:
    """The slot's new version, or the status that refuses the commit:

    - ``BadInvalidArgument``: not six finite numbers, or a value outside the API's bounds;
    - ``BadInvalidState``: the slot changed since ``expected_version`` was read (read again);
    - ``BadNodeIdUnknown``: the controller is gone;
    - ``BadResourceUnavailable``: the database cannot answer now (another writer held it past
      the writers' wait, no connection free, the connection lost: REST's 503,
      :func:`server.service.transaction.unavailable`): try again.
    """
    try:
        values6 = [float(v) for v in frame]
        if len(values6) != 6:
            raise ValueError("Frame needs X, Y, Z, A, B, C")
        body = EntryIn(name=name or None, pose=dict(zip("xyzabc", values6)))
    except (TypeError, ValueError, ValidationError):
        return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
    try:
        with transaction.writing(make_session, controller_id, operation="commit_frame",
                                 who=who) as db:
            e = slots.edit_slot(db, controller_id, table, number, body,
                                etag(int(expected_version)))
    except crud.NotFound:
        return ua.StatusCode(ua.StatusCodes.BadNodeIdUnknown)
    except CalibrationError:
        return ua.StatusCode(ua.StatusCodes.BadInvalidArgument)
    except PreconditionFailed:
        return ua.StatusCode(ua.StatusCodes.BadInvalidState)
    except Exception as err:
        why = transaction.retry_reason(err)
        log.warning("opcua: CommitFrame of %s %d: %s", table, number, why)
        return ua.StatusCode(ua.StatusCodes.BadResourceUnavailable)
    return int(e.version)
