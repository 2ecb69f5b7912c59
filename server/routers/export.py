"""Export: the tables as a controller file (KUKA, ABB, FANUC, UR) or a JSON backup, and import.

The file formats live in server/formats; here only the slots are turned into
``FrameEntry`` values and back. A JSON backup holds the whole controller incl. history.
"""

from __future__ import annotations

import json

from fastapi import APIRouter, Request, Response

from db import crud
from db.models import FrameEntry as SlotRow
from server.auth.audit import mark_operation, record
from server.auth.guard import require
from server.deps import SessionDep
from server.schemas import ExportFormat, ImportIn, ImportOut
from solvers.errors import CalibrationError
from solvers.frames import Pose

router = APIRouter(prefix="/controllers/{controller_id}", tags=["Export"])

MEDIA = {"kuka": ("text/plain", "$config.dat"), "abb": ("text/plain", "CalibData.mod"),
         "fanuc": ("text/plain", "frames.ls"), "ur": ("text/plain", "frames.script"),
         "json": ("application/json", "backup.json")}


def _is_used(e: SlotRow) -> bool:
    return bool(e.name) or any(v != 0.0 for v in e.pose_values()) or e.mass_kg is not None


def to_frame_entries(rows: list[SlotRow]) -> list:
    """The used slots as server.formats FrameEntry values (load only on robot-held kinds)."""
    from server.formats import FrameEntry, LoadData

    out = []
    for e in rows:
        if not _is_used(e):
            continue
        load = None
        if e.mass_kg is not None and e.kind in ("tool", "workpiece"):
            com = tuple(v or 0.0 for v in (e.com_x_mm, e.com_y_mm, e.com_z_mm))
            inertia = tuple(v or 0.0 for v in
                            (e.inertia_x_kgm2, e.inertia_y_kgm2, e.inertia_z_kgm2))
            load = LoadData(e.mass_kg, com, inertia)  # type: ignore[arg-type]
        pose = Pose(*e.pose_values())
        out.append(FrameEntry(e.number, e.name, e.kind, pose, load))  # type: ignore[arg-type]
    return out


def export_text(db: SessionDep, controller_id: int, fmt: str) -> str:
    """The controller's tables in ``fmt`` (also used by ``pendant export``)."""
    c = crud.get_controller(db, controller_id)
    if fmt == "json":
        return json.dumps(crud.backup(db, c), indent=1)
    from server import formats

    writer = {"kuka": formats.export_kuka, "abb": formats.export_abb, "fanuc": formats.export_fanuc,
              "ur": formats.export_ur}[fmt]
    return writer(to_frame_entries(crud.list_entries(db, controller_id)))


@router.get("/export", response_class=Response,
            responses={200: {"content": {"text/plain": {}, "application/json": {}}}})
def export(controller_id: int, db: SessionDep, request: Request,
           format: ExportFormat = "kuka") -> Response:
    """Download the tables as a controller file (``format=kuka|abb|fanuc|ur``) or the whole
    controller as a JSON backup (``format=json``, incl. history and sessions; needs
    ``backup:write``)."""
    if format == "json":
        require(request, "backup:write")
    text = export_text(db, controller_id, format)
    media, filename = MEDIA[format]
    name = crud.get_controller(db, controller_id).name
    return Response(text, media_type=media,
                    headers={"Content-Disposition": f'attachment; filename="{name}-{filename}"'})


@router.post("/import")
def import_tables(controller_id: int, body: ImportIn, db: SessionDep,
                  request: Request) -> ImportOut:
    """Read a KUKA ``$config.dat``, an ABB RAPID module or a JSON backup into the tables.

    Controller files overwrite the slots they name (each change recorded in history and the
    audit); a JSON backup (needs ``backup:restore``) replaces the tables, history and
    sessions of this controller, and the audit keeps every earlier change."""
    c = crud.get_controller(db, controller_id)
    if body.format == "json":
        require(request, "backup:restore")
        mark_operation("backup.restore")
        from server.backup import parse_backup
        from server.routers.common import robot_of
        from solvers.dh import check_joint_limits

        doc = parse_backup(body.text)  # checked: nothing a later read cannot handle is stored
        joints = (doc.get("controller") or {}).get("joints_deg")
        if joints is not None:
            robot = robot_of(c)
            loc = ("text", "controller", "joints_deg")
            if len(joints) != robot.dof:
                raise CalibrationError(loc, f"has {len(joints)} values; this controller's robot "
                                       f"has {robot.dof} joints")
            try:
                check_joint_limits(robot, joints)
            except CalibrationError as err:
                raise CalibrationError(loc + tuple(err.loc[1:]), err.reason) from None
        n_before = len(crud.history(db, c.id))
        try:
            n, h = crud.restore_backup(db, c, doc)
        except (KeyError, TypeError, ValueError) as err:
            raise CalibrationError(("text",),
                                   f"malformed backup: {type(err).__name__} {err}") from None
        record(db, "backup.restore", controller_id=c.id, before={"history_rows": n_before},
               after={"history_rows": h, "entries": n})
        return ImportOut(format="json", entries=n, history=h)
    from server import formats

    reader = formats.import_kuka if body.format == "kuka" else formats.import_abb
    entries = reader(body.text)
    if not entries:
        raise CalibrationError(("text",), "no tool, base, workpiece or fixed-tool entry found in "
                               f"this {body.format} text")
    for fe in entries:
        table = "tool" if fe.kind in ("tool", "workpiece") else "base"
        e = crud.get_entry(db, controller_id, table, fe.number)
        values = dict(zip(("x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg"),
                          fe.pose.as_array().tolist()))
        values.update(name=fe.name, kind=fe.kind, method=f"import.{body.format}", session_id=None,
                      error_max_mm=None, error_rms_mm=None)
        if fe.load is not None:
            com, inertia = fe.load.com_mm, fe.load.inertia_kgm2
            values.update(mass_kg=fe.load.mass_kg, com_x_mm=com[0], com_y_mm=com[1],
                          com_z_mm=com[2],
                          inertia_x_kgm2=inertia[0], inertia_y_kgm2=inertia[1],
                          inertia_z_kgm2=inertia[2])
        crud.change_entry(db, e, values, reason="import")
    return ImportOut(format=body.format, entries=len(entries))
