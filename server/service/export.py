"""A controller's tables as text: a controller file (KUKA, ABB, FANUC, UR), its external
kinematics (``kuka_machine``, ``abb_moc``) or its JSON backup. What ``GET .../export``, the
OPC UA ExportFile, ``pendant export`` and ``pendant backup`` give."""

from __future__ import annotations

import json

from sqlalchemy.orm import Session

from db import crud
from server.service import external
from server.service.controller_files import export_file


def export_text(db: Session, controller_id: int, fmt: str) -> str:
    """The controller's tables in ``fmt``: a controller file patched into the one last
    imported in that format, if any (docs/formats.md)."""
    c = crud.get_controller(db, controller_id)
    if fmt == "json":
        return json.dumps(crud.backup(db, c), indent=1)
    if fmt in external.EXPORT_FORMATS:  # the external kinematics (docs/formats.md)
        return external.export_external(db, controller_id, fmt)
    return export_file(db, controller_id, fmt)
