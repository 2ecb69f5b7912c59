"""The ``pendant`` command: serve the pendant, calibrate from a file, export a controller's tables.

    pendant serve [--host 127.0.0.1] [--port 8000] [--db URL] [--workers N] [--no-migrate]
    pendant db upgrade [--db URL]
    pendant slot tool|base N [--name ..] [--pose x,y,z,a,b,c] [--url URL]   (sends If-Match)
    pendant calibrate METHOD FILE [--robot KEY] [--tcp X,Y,Z] [--json]
    pendant export CONTROLLER --format kuka|abb|fanuc|ur|json [--db URL]

``calibrate`` reads taught poses from a JSON or CSV file (format in docs/api.md, "pendant
calibrate") and prints the report; it needs no service and no DB.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from server.analysis_cli import add_analysis_commands
from server.slot_cli import add_slot_command
from server.methods import METHODS, MethodInputs, TaughtData
from server.schemas import ReportOut
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.report import CalibrationResult
from solvers.robots import ROBOTS


# ------------------------------------------------------------------------------- calibrate

def _vec(text: str, n: int, name: str) -> list[float]:
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise CalibrationError((name,),
                               f"must be {n} comma-separated numbers, got {text!r}") from None
    if len(v) != n or not all(np.isfinite(v)):
        raise CalibrationError((name,), f"must be {n} finite comma-separated numbers, got {text!r}")
    return v


def _flange(point: dict[str, Any], k: int, robot_key: str | None) -> np.ndarray:
    from solvers.dh import forward_kinematics

    if "joints_deg" in point:
        if robot_key is None:
            raise CalibrationError(("points", k, "joints_deg"), "joint values need the robot: "
                                   "give \"robot\" in the file or --robot")
        if robot_key not in ROBOTS:
            raise CalibrationError(("robot",), f"unknown robot {robot_key!r}; the library has "
                                   f"{', '.join(sorted(ROBOTS))}")
        return forward_kinematics(ROBOTS[robot_key], point["joints_deg"])
    pose = point.get("flange_pose", point)
    try:
        return Pose(*(float(pose[c]) for c in "xyzabc")).as_matrix()
    except (KeyError, TypeError, ValueError):
        raise CalibrationError(("points", k), "needs joints_deg, flange_pose {x..c}, "
                               "or x, y, z, a, b, c") from None


def read_points_file(path: Path) -> tuple[list[dict[str, Any]], dict[str, Any], str | None]:
    """(points, inputs, robot) from a JSON document or a CSV table (docs/api.md)."""
    text = path.read_text(encoding="utf-8")
    if path.suffix.lower() == ".json":
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as err:
            raise CalibrationError(("file",), f"not JSON: {err.msg} at line {err.lineno}") from None
        if isinstance(doc, list):
            doc = {"points": doc}
        return list(doc.get("points", [])), dict(doc.get("inputs", {})), doc.get("robot")
    rows = list(csv.DictReader(io.StringIO(text)))
    points: list[dict[str, Any]] = []
    for k, row in enumerate(rows):
        row = {(key or "").strip(): (v or "").strip() for key, v in row.items()}
        try:
            if "j1" in row:
                q = [float(row[f"j{i}"]) for i in range(1, 8) if row.get(f"j{i}")]
                p: dict[str, Any] = {"joints_deg": q}
            else:
                p = {c: float(row[c]) for c in "xyzabc"}
        except (KeyError, ValueError):
            raise CalibrationError(("file", f"line {k + 2}"),
                                   "needs columns x,y,z,a,b,c or j1..jn with numbers") from None
        if row.get("beam"):
            p.update(beam=row["beam"], edge=row.get("edge"))
            if row.get("vx"):
                p["velocity_mm_s"] = [float(row["vx"]), float(row["vy"]), float(row["vz"])]
        points.append(p)
    return points, {}, None


def calibrate_file(method: str, path: Path, robot: str | None = None,
                   overrides: dict[str, Any] | None = None) -> CalibrationResult:
    """Solve ``method`` from the taught poses in ``path``; returns the CalibrationResult."""
    if method not in METHODS:
        raise CalibrationError(("method",),
                               f"unknown method {method!r}; one of {', '.join(METHODS)}")
    points, inputs, file_robot = read_points_file(path)
    inputs.update(overrides or {})
    robot = robot or file_robot
    data = [TaughtData(_flange(p, k, robot), p.get("beam"), p.get("edge"),
                       None if p.get("velocity_mm_s") is None else tuple(p["velocity_mm_s"]))
            for k, p in enumerate(points)]
    arr = {k: None if inputs.get(k) is None else np.asarray(inputs[k], dtype=float)
           for k in ("tcp_mm", "reference_tcp_mm", "fixed_tcp_mm", "known_mm")}
    beams = {b["id"]: (np.asarray(b["point_mm"], float), np.asarray(b["direction"], float))
             for b in inputs.get("beams", [])}
    pose = Pose(**inputs["pose"]) if inputs.get("pose") else None
    mi = MethodInputs(pose=pose, beams=beams, tool_diameter_mm=inputs.get("tool_diameter_mm"),
                      **arr)  # type: ignore[arg-type]
    known = inputs.get("known_mm")
    params = {} if known is None else {"known_points_mm": known}
    return METHODS[method].solve(data, mi, params)


def format_report(report: ReportOut) -> str:
    f = report.frame
    lines = [f"method      {report.method}",
             f"frame       x {f.x:.3f}  y {f.y:.3f}  z {f.z:.3f} mm   "
             f"a {f.a:.3f}  b {f.b:.3f}  c {f.c:.3f} deg"]
    if report.residuals_mm:
        lines.append("point  residual_mm" + ("  residual_deg" if report.residuals_deg else ""))
        for k, r in enumerate(report.residuals_mm):
            deg = f"  {report.residuals_deg[k]:12.4f}" if report.residuals_deg else ""
            lines.append(f"{k + 1:5d}  {r:11.4f}{deg}")
        lines.append(f"max {report.max_error_mm:.4f} mm   mean {report.mean_error_mm:.4f} mm   "
                     f"rms {report.rms_error_mm:.4f} mm")
    for name, v, unit in (("95% position bound", report.position_bound95_mm, "mm"),
                          ("95% angle bound", report.angle_bound95_deg, "deg"),
                          ("TRE", report.tre_mm, "mm")):
        if v is not None:
            lines.append(f"{name:20s}{v:.4f} {unit}")
    if report.bad_point:
        lines.append(f"bad point   {report.bad_point.message}")
    lines += [f"{w.severity:8s}    {w.message}" for w in report.warnings]
    if report.guidance:
        lines.append(f"guidance    {report.guidance}")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------ main

def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pendant", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("serve", help="run the pendant service (REST API and the pendant page)")
    s.add_argument("--host", default="127.0.0.1")
    s.add_argument("--port", type=int, default=8000)
    s.add_argument("--db", help="database URL (default: PENDANT_DB_URL, else a SQLite file in "
                                "the user data dir)")
    s.add_argument("--workers", type=int, default=1,
                   help="API processes on this port (uvicorn workers; all share the database)")
    s.add_argument("--no-migrate", action="store_true",
                   help="refuse an old schema instead of migrating it (run `pendant db upgrade`)")

    d = sub.add_parser("db", help="the database's schema")
    dsub = d.add_subparsers(dest="db_command", required=True)
    up = dsub.add_parser("upgrade", help="migrate the schema to this version's (Alembic upgrade "
                                         "head, under a database-wide lock)")
    up.add_argument("--db", help="database URL")

    c = sub.add_parser("calibrate",
                       help="solve a calibration menu from taught poses in a JSON/CSV file")
    c.add_argument("method", choices=sorted(METHODS))
    c.add_argument("file", type=Path)
    c.add_argument("--robot", choices=sorted(ROBOTS), help="arm of joint values in the file")
    c.add_argument("--tcp", help="X,Y,Z of the calibrated touching tool (ABC menus: the tool's "
                                 "own XYZ)")
    c.add_argument("--reference-tcp", help="X,Y,Z of the reference tool (XYZ Reference)")
    c.add_argument("--fixed-tcp", help="X,Y,Z of the calibrated fixed tool (workpiece menus)")
    c.add_argument("--json", action="store_true", help="print the report as JSON")

    e = sub.add_parser("export", help="print a controller's tables as a controller file")
    e.add_argument("controller", help="controller name (or id)")
    e.add_argument("--format", choices=["kuka", "abb", "fanuc", "ur", "json"], default="kuka")
    e.add_argument("--db", help="database URL")

    add_analysis_commands(sub)
    add_slot_command(sub)
    return p


def _settings(db: str | None):  # noqa: ANN202
    from server.settings import Settings

    return Settings(db_url=db) if db else Settings()


WORKER_HEALTHCHECK_S = 60


class SchemaOutOfDate(RuntimeError):
    """Raised by ``serve --no-migrate`` on an old schema (server.app.SchemaOutOfDate)."""


def serve(args: argparse.Namespace) -> int:
    """Run the service: one process, or ``--workers N`` uvicorn processes on one database.

    The schema is checked once here, before any worker starts (migrated under the database
    lock, or refused with ``--no-migrate``); each worker checks it again."""
    import os

    import uvicorn

    from server import app as app_module
    from server.settings import ENV_DB_URL, ENV_MIGRATE

    settings = _settings(args.db)
    if args.workers < 1:
        raise CalibrationError(("--workers",), f"must be >= 1, got {args.workers}")
    try:
        if args.workers == 1:
            from dataclasses import replace

            application = app_module.create_app(replace(settings, migrate=not args.no_migrate))
            uvicorn.run(application, host=args.host, port=args.port)
            return 0
        from db.session import make_engine

        app_module.check_schema(make_engine(settings.db_url), not args.no_migrate)
    except app_module.SchemaOutOfDate as err:
        raise SchemaOutOfDate(str(err)) from None
    os.environ[ENV_DB_URL] = settings.db_url  # the workers build server.app:app from these
    os.environ[ENV_MIGRATE] = "0" if args.no_migrate else "1"
    # a worker imports numpy/scipy before it can answer the supervisor's ping: on a busy host
    # that takes longer than uvicorn's 5 s default, and the worker would be killed as hung
    uvicorn.run("server.app:app", host=args.host, port=args.port, workers=args.workers,
                timeout_worker_healthcheck=WORKER_HEALTHCHECK_S)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "serve":
            return serve(args)
        if args.command == "db":
            from db.session import make_engine, upgrade

            url = _settings(args.db).db_url
            before, head = upgrade(make_engine(url))
            print(f"pendant: schema {before or 'empty'} -> {head}" if before != head
                  else f"pendant: schema is {head} (nothing to do)")
            return 0
        if args.command == "calibrate":
            given = (("tcp_mm", args.tcp), ("reference_tcp_mm", args.reference_tcp),
                     ("fixed_tcp_mm", args.fixed_tcp))
            overrides = {k: _vec(v, 3, f"--{k.replace('_mm', '').replace('_', '-')}")
                         for k, v in given if v}
            result = calibrate_file(args.method, args.file, args.robot, overrides)
            report = ReportOut.from_result(result)
            print(report.model_dump_json(indent=1) if args.json else format_report(report))
            return 0
        if args.command == "export":
            from db import crud
            from server.app import create_app
            from server.routers.export import export_text

            app = create_app(_settings(args.db))
            with app.state.sessionmaker() as db:
                controller = crud.find_controller(db, args.controller)
                sys.stdout.write(export_text(db, controller.id, args.format))
            return 0
        return int(args.func(args) or 0) if hasattr(args, "func") else 2
    except SchemaOutOfDate as err:
        print(f"pendant: {err}", file=sys.stderr)
        return 2
    except CalibrationError as err:
        print(f"pendant: {'.'.join(str(x) for x in err.loc)}: {err.reason}", file=sys.stderr)
        return 2
    except LookupError as err:
        print(f"pendant: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"pendant: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
