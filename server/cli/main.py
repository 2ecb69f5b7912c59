"""The ``pendant`` command: serve the pendant, calibrate from a file, export a controller's tables.

    pendant serve [--host 127.0.0.1] [--port 8000] [--db URL] [--workers N] [--no-migrate]
                  [--job-workers 2] [--allow-host NAME] [--cors-origin URL] [--no-auth]
                  [--opcua-port 4840 [--opcua-pki DIR]] [--rws-port 8610 [--rws-controller NAME]]
                  [--kvp-port 7000 --kvp-user NAME [--kvp-controller NAME] [--kvp-host ADDR]
                   [--kvp-allow ADDR]]
    pendant db upgrade [--db URL]
    pendant opcua [--host 127.0.0.1] [--port 4840] [--db URL]
    pendant worker [--processes 2] [--db URL] [--job-time-s 600] [--job-memory-mb 2048]
    pendant slot tool|base N [--name ..] [--pose x,y,z,a,b,c] [--url URL]   (sends If-Match)
    pendant users add|list|revoke ...; pendant tokens create USER; pendant roles add|list
    pendant calibrate METHOD FILE [--robot KEY] [--tcp X,Y,Z] [--json]
    pendant export CONTROLLER --format kuka|abb|fanuc|ur|json [--db URL]
    pendant import FILE --controller NAME [--format kuka|abb|fanuc|ur|json] [--dry-run] [--db URL]
    pendant backup CONTROLLER [-o FILE] [--db URL]
    pendant restore FILE --controller NAME [--dry-run] [--db URL]

``calibrate`` reads taught poses from a JSON or CSV file (format in docs/api.md, "pendant
calibrate") and prints the report; it needs no service and no DB.

A mistake (a DB URL typo, a port in use, a bad file) is one line on stderr naming what is
wrong and what to type instead, and exit status 2; Ctrl-C is "interrupted" and status 130.
"""

from __future__ import annotations

import argparse
import csv
import difflib
import errno
import io
import itertools
import json
import os
import subprocess
import signal
import socket
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence, TextIO

import numpy as np

from server import __version__
from server.cli.analysis import add_analysis_commands
from server.service.backup import add_backup_commands
from server.service.transaction import retry_reason
from server.auth.cli import add_auth_commands
from server.cli.slot import add_slot_command
from server.menus import METHODS
from server.menus.methods import MethodInputs, TaughtData
from server.opcua.cli import add_opcua_commands, start_beside
from server.rws.cli import add_face_arguments, start_faces
from server.api.schemas import ReportOut
from server.service.external import (NO_CHAIN, chain_points, check_external_axes,
                                     rail_from_document, unplaced_positions)
from server.settings import ENV_PARENT_PID, parent_pid
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


def _rail_option(text: str) -> dict[str, Any]:
    """``--rail AXIS:X,Y,Z[:calibrated]`` as ``inputs.rail``, checked (CalibrationError naming
    --rail)."""
    parts = text.split(":")
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2].strip() != "calibrated"):
        raise CalibrationError(("--rail",), f"must be AXIS:X,Y,Z or AXIS:X,Y,Z:calibrated "
                               f"(e.g. E1:0,1,0), got {text!r}")
    doc = {"axis": parts[0].strip().upper(), "direction": _vec(parts[1], 3, "--rail"),
           "calibrated": len(parts) == 3}
    try:
        rail_from_document(doc)
    except CalibrationError as err:  # the option is one field: name it
        raise CalibrationError(("--rail",), err.reason) from None
    return doc


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
        ext = {f"E{i}": float(row[f"e{i}"]) for i in range(1, 7) if row.get(f"e{i}")}
        if ext:  # the external axis values of the touch-up (ext.* menus)
            p["external_axes"] = ext
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
                       None if p.get("velocity_mm_s") is None else tuple(p["velocity_mm_s"]),
                       external_axes=check_external_axes(p.get("external_axes"),
                                                         ("points", k, "external_axes")))
            for k, p in enumerate(points)]
    arr = {k: None if inputs.get(k) is None else np.asarray(inputs[k], dtype=float)
           for k in ("tcp_mm", "reference_tcp_mm", "fixed_tcp_mm", "known_mm")}
    beams = {b["id"]: (np.asarray(b["point_mm"], float), np.asarray(b["direction"], float))
             for b in inputs.get("beams", [])}
    pose = Pose(**inputs["pose"]) if inputs.get("pose") else None
    external = None
    if method.startswith("ext."):
        from server.menus.external import inputs_from_document
        external = inputs_from_document(inputs.get("kinematic"), data)
    # a robot on a rail: the touch-ups put in the world through it, as the service does
    # (server.service.external.chain_points); without one, varying axis values are named
    findings: list = []
    chain: dict[str, Any] = {}
    if inputs.get("rail") is not None:
        data, findings, chain = chain_points(rail_from_document(inputs["rail"]), data, method)
    elif not method.startswith("ext.") and method not in NO_CHAIN:
        findings = unplaced_positions(data)
    mi = MethodInputs(pose=pose, beams=beams, tool_diameter_mm=inputs.get("tool_diameter_mm"),
                      external=external, **arr)  # type: ignore[arg-type]
    known = inputs.get("known_mm")
    params = {} if known is None else {"known_points_mm": known}
    result = METHODS[method].solve(data, mi, params)
    if not findings and not chain:
        return result
    r = result.report
    extras = {**r.extras, "chain": chain} if chain else r.extras
    return replace(result, report=replace(r, warnings=tuple(r.warnings) + tuple(findings),
                                          extras=extras))


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
                          ("95% Mahalanobis", report.mahalanobis_bound95, ""),
                          ("TRE", report.tre_mm, "mm")):
        if v is not None:
            lines.append(f"{name:20s}{v:.4f} {unit}".rstrip())
    if report.sigma_mm is not None and report.sigma_source is not None:
        source = (f"from the residuals, {report.dof} dof" if report.sigma_source == "residual"
                  else "assumed, not measured")
        lines.append(f"{'sigma':20s}{report.sigma_mm:.4f} mm ({source})")
    if report.bad_point:
        lines.append(f"bad point   {report.bad_point.message}")
    lines += [f"{w.severity:8s}    {w.message}" for w in report.warnings
              if not (report.bad_point and w.code == "bad_point")]  # said once, above
    if report.guidance:
        lines.append(f"guidance    {report.guidance}")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------ main

EX_TEMPFAIL = 75  # sysexits.h: a temporary failure, try again (the database busy or gone)

DESCRIPTION = """A controller-side teach-pendant emulator: the Calibrate menus as a REST
service and a browser pendant, calibration from recorded poses, controller file export, and
the sim-vs-reality analysis. Run "pendant COMMAND --help" for a command's options."""

DB_HELP = ("database URL, e.g. sqlite:///path/to/pendant.db or "
           "postgresql+psycopg://user@host/pendant (default: $PENDANT_DB_URL, else pendant.db "
           "in the user data directory)")


def _methods_epilog() -> str:
    width = max(len(name) for name in METHODS)
    return "methods:\n" + "\n".join(f"  {name:{width}s}  {m.title}" for name, m in METHODS.items())


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="pendant", description=DESCRIPTION)
    p.add_argument("--version", action="version", version=f"pendant {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser("serve", help="run the pendant service (REST API and the pendant page)",
                       description="Run the service: the pendant page at /, the API docs at "
                                   "/docs (served offline).")
    s.add_argument("--host", default="127.0.0.1",
                   help="address to listen on; 0.0.0.0 for every interface (default: %(default)s)")
    s.add_argument("--port", type=int, default=8000,
                   help="TCP port to listen on (default: %(default)s)")
    s.add_argument("--db", metavar="URL", help=DB_HELP)
    s.add_argument("--workers", type=int, default=1,
                   help="API processes on this port (uvicorn workers; all share the database)")
    s.add_argument("--no-migrate", action="store_true",
                   help="refuse an old schema instead of migrating it (run `pendant db upgrade`)")

    d = sub.add_parser("db", help="the database's schema")
    dsub = d.add_subparsers(dest="db_command", required=True)
    up = dsub.add_parser("upgrade", help="migrate the schema to this version's (Alembic upgrade "
                                         "head, under a database-wide lock)")
    up.add_argument("--db", metavar="URL", help=DB_HELP)

    s.add_argument("--job-workers", type=int, default=2, metavar="N",
                   help="job worker processes started with the service (analyses, restores); "
                        "0: none here, run `pendant worker` elsewhere (default 2)")
    _job_limits(s)

    w = sub.add_parser("worker", help="run queued jobs (analyses, restores) in a bounded pool of "
                                      "processes; any number of hosts may share one database")
    w.add_argument("--processes", type=int, default=2, metavar="N",
                   help="jobs run at once, one process each (default 2)")
    w.add_argument("--db", metavar="URL", help=DB_HELP)
    w.add_argument("--exit-with-parent", action="store_true", help=argparse.SUPPRESS)
    _job_limits(w)

    s.add_argument("--allow-host", action="append", default=[], metavar="NAME",
                   help="a Host name clients use besides the loopback names (repeatable; "
                        "PENDANT_ALLOWED_HOSTS, comma-separated, adds more)")
    s.add_argument("--cors-origin", action="append", default=[], metavar="URL",
                   help="an origin whose pages may call the API (CORS; closed by default)")
    s.add_argument("--no-auth", action="store_true",
                   help="demo only: no login, everyone an Administrator; loopback hosts only")
    s.add_argument("--trusted-proxy", action="append", default=[], metavar="IP",
                   help="a reverse proxy whose X-Forwarded-For/-Proto is believed (repeatable; "
                        "PENDANT_TRUSTED_PROXIES, comma-separated, adds more); from anyone "
                        "else the headers are ignored (the audit records the peer)")
    s.add_argument("--opcua-port", type=int, metavar="PORT",
                   help="also serve the OPC UA face on this port (a process of its own on the "
                        "same database; docs/opcua.md)")
    s.add_argument("--opcua-pki", type=Path, metavar="DIR",
                   help="the OPC UA face's PKI folder (its certificate and key, trusted/ and "
                        "rejected/ client certificates; default: <db file>-opcua-pki beside a "
                        "SQLite file, else one per database in the user data dir)")
    add_face_arguments(s)

    c = sub.add_parser("calibrate",
                       help="solve a calibration menu from taught poses in a JSON/CSV file",
                       description="Solve a calibration menu from taught poses (JSON or CSV, "
                                   "format in docs/api.md) and print the report. Needs no "
                                   "service and no DB.",
                       epilog=_methods_epilog(), formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("method", metavar="METHOD", help="the menu, one of the methods listed below")
    c.add_argument("file", type=Path, metavar="FILE", help="taught poses: JSON or CSV")
    c.add_argument("--robot", choices=sorted(ROBOTS), metavar="KEY",
                   help=f"arm of joint values in the file: {', '.join(sorted(ROBOTS))}")
    c.add_argument("--tcp", help="X,Y,Z of the calibrated touching tool (ABC menus: the tool's "
                                 "own XYZ)")
    c.add_argument("--reference-tcp", help="X,Y,Z of the reference tool (XYZ Reference)")
    c.add_argument("--fixed-tcp", help="X,Y,Z of the calibrated fixed tool (workpiece menus)")
    c.add_argument("--rail", metavar="AXIS:X,Y,Z",
                   help="the robot rides on a rail moved by external axis AXIS (E1..E6) along "
                        "X,Y,Z in its base: the touch-ups are put in the world through it. "
                        "Machine data, unless :calibrated follows (AXIS:X,Y,Z:calibrated: the "
                        "direction comes from a calibration); only a calibrated rail puts "
                        "points touched at different positions in one frame")
    c.add_argument("--json", action="store_true", help="print the report as JSON")

    e = sub.add_parser("export", help="print a controller's tables as a controller file")
    e.add_argument("controller", help="controller name (or id), e.g. cell-1")
    e.add_argument("--format", choices=["kuka", "abb", "fanuc", "ur", "json", "kuka_machine",
                                        "abb_moc"], default="kuka",
                   help="kuka: $config.dat; abb: a RAPID module; fanuc: frames; ur: a URScript; "
                        "json: the whole controller as a backup; kuka_machine: the external "
                        "kinematics ($machine.dat $ETn_..., $config.dat MACHINE_DEF); abb_moc: "
                        "their MOC.cfg base frames (default: %(default)s)")
    e.add_argument("--db", metavar="URL", help=DB_HELP)

    i = sub.add_parser("import", help="read a controller file into a controller's tables "
                                      "(--dry-run: show what would change)")
    i.add_argument("file", type=Path)
    i.add_argument("--controller", required=True, help="controller name (or id)")
    i.add_argument("--format", choices=["kuka", "abb", "fanuc", "ur", "json"],
                   help="default from the file name: .dat kuka, .mod/.modx/.sys abb, "
                        ".txt/.ls fanuc, .va fanuc (a controller's SYSFRAME.VA), .script ur, "
                        ".json a backup (as pendant restore)")
    i.add_argument("--dry-run", action="store_true",
                   help="write nothing; print per slot its values before -> after")
    i.add_argument("--slots", help="apply only these slots of the file, e.g. tool3,base1 "
                                   "(the others keep what they hold)")
    i.add_argument("--db", help="database URL")

    add_analysis_commands(sub)
    add_backup_commands(sub)
    add_slot_command(sub)
    add_auth_commands(sub)
    add_opcua_commands(sub)
    _state_defaults(p)
    return p


def _state_defaults(parser: argparse.ArgumentParser) -> None:
    """Every option's ``--help`` names its default (docs/api.md says so): an option with a
    default its help does not state gets "(default: VALUE)" appended, in every subcommand."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                _state_defaults(child)
            continue
        d = action.default
        if (not action.option_strings or action.help == argparse.SUPPRESS
                or d is None or d is False or d in (argparse.SUPPRESS, "", [])
                or "default" in (action.help or "")):
            continue
        action.help = f"{action.help} (default: %(default)s)" if action.help else "default: %(default)s"


IMPORT_SUFFIXES = {".dat": "kuka", ".mod": "abb", ".modx": "abb", ".sys": "abb", ".txt": "fanuc",
                   ".ls": "fanuc", ".va": "fanuc", ".script": "ur",
                   ".json": "json"}


def import_file(args: argparse.Namespace) -> int:
    """``pendant import``: the same checks and write path as POST .../import."""
    from db import crud
    from server.api.app import create_app
    from server.service import transaction
    from server.service.controller_files import apply_import, parse_file

    fmt = args.format or IMPORT_SUFFIXES.get(args.file.suffix.lower())
    if fmt is None:
        raise CalibrationError(("--format",), f"cannot tell the format of {args.file.name}; "
                               "give --format kuka|abb|fanuc|ur|json")
    if fmt == "json":  # a JSON backup: what pendant restore does
        from server.service.backup import run_restore_file

        return run_restore_file(args)
    from server.service.controller_files import value_changes
    from server.formats import decode_file

    text, encoding = decode_file(args.file.read_bytes())  # KSS, RobotWare: Windows-1252
    slots = None
    if args.slots:
        slots = [_slot_ref(ref) for ref in args.slots.split(",")]
    app = create_app(_settings(args.db))
    maker = app.state.sessionmaker
    with maker() as db:
        cid = crud.find_controller(db, args.controller).id
    parsed = parse_file(fmt, text)  # before the write: the writers' turn is not held meanwhile
    # a dry run writes nothing: a reader's session; else the write every face runs
    with (maker() if args.dry_run
          else transaction.writing(maker, cid, operation="import_tables")) as db:
        result = apply_import(db, crud.get_controller(db, cid), fmt, text, parsed,
                              args.dry_run, encoding, slots)
    for c in result.slots:
        if not c.changed:
            continue
        after = c.after or {"name": "(unused)", "kind": ""}
        before = c.before or {"name": "(unused)", "kind": ""}
        what = f"  kind {c.kind_change}" if c.kind_change else ""
        print(f"{c.table} {c.number:>2}: {before['name']!r} -> {after['name']!r} "
              f"({after['kind'] or 'emptied'}){what}")
        for label, old, new in value_changes(c.before, c.after):
            print(f"    {label:<8} {old} -> {new}")
    for k in result.skipped:
        print(f"skipped line {k.line}: {k.field}: {k.reason}")
    changed = sum(c.changed for c in result.slots)
    verb = "would change" if args.dry_run else "changed"
    print(f"{args.file.name}: {changed} slot(s) {verb}, {len(result.skipped)} declaration(s) "
          f"skipped{' (dry run: nothing written)' if args.dry_run else ''}")
    return 0


def _slot_ref(ref: str) -> tuple[str, int]:
    """``tool3`` / ``base12`` (as --slots gives them) -> ("tool", 3)."""
    import re

    m = re.fullmatch(r"\s*(tool|base)\s*([0-9]{1,6})\s*", ref)
    if not m:
        raise CalibrationError(("--slots",), f"expected tool<n> or base<n>, got {ref!r}")
    return m.group(1), int(m.group(2))


def _job_limits(p: argparse.ArgumentParser) -> None:
    from server.jobs.worker import DEFAULT_MEMORY_MB, DEFAULT_TIME_S

    p.add_argument("--job-time-s", type=float, default=DEFAULT_TIME_S,
                   help=f"a job running longer is stopped and fails (default {DEFAULT_TIME_S:g})")
    p.add_argument("--job-memory-mb", type=int, default=DEFAULT_MEMORY_MB,
                   help=f"address space of a job's process (default {DEFAULT_MEMORY_MB})")


def _positive(value: int | float, option: str) -> None:
    if value <= 0:
        raise CalibrationError((option,), f"must be > 0, got {value}")


def start_job_workers(db_url: str, args: argparse.Namespace) -> subprocess.Popen | None:
    """``pendant worker`` as a child of ``serve`` (stops when serve stops); None for 0."""
    if args.job_workers <= 0:
        return None
    cmd = [sys.executable, "-m", "server.cli", "worker", "--db", db_url, "--exit-with-parent",
           "--processes", str(args.job_workers), "--job-time-s", str(args.job_time_s),
           "--job-memory-mb", str(args.job_memory_mb)]
    # a session of its own: a terminal's Ctrl-C reaches serve alone, which stops its children
    return subprocess.Popen(cmd, start_new_session=True,
                            env={**os.environ, ENV_PARENT_PID: str(os.getpid())})


def run_worker(args: argparse.Namespace) -> int:
    import logging

    from server.jobs.worker import Limits, Pool

    _positive(args.processes, "--processes")
    _positive(args.job_time_s, "--job-time-s")
    _positive(args.job_memory_mb, "--job-memory-mb")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    pool = Pool(_settings(args.db).db_url, args.processes,
                Limits(args.job_time_s, args.job_memory_mb),
                parent_pid=parent_pid() if args.exit_with_parent else None)
    pool.run()
    return 0


def db_url_problem(url: str) -> str | None:
    """Why ``url`` cannot be a database URL, with what to type instead; None when it can."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    example = "sqlite:///path/to/pendant.db"
    try:
        parsed = make_url(url)
    except ArgumentError:
        hint = f"sqlite:///{Path(url).resolve()}" if url.strip() else example
        return f"{url!r} is not a database URL; for a SQLite file write {hint}"
    try:
        dialect = parsed.get_dialect()
    except NoSuchModuleError:
        name = parsed.drivername.split("+")[0]
        near = difflib.get_close_matches(name, ["sqlite", "postgresql", "mysql"], n=1)
        guess = f"did you mean {near[0]}? " if near else ""
        return (f"unknown database {name!r} in {url!r}; {guess}write sqlite:///... "
                f"(e.g. {example}) or postgresql+psycopg://user@host/pendant")
    try:
        dialect.import_dbapi()
    except ImportError as err:
        package = {"psycopg2": "psycopg2-binary", "psycopg": "'psycopg[binary]'",
                   "MySQLdb": "mysqlclient"}.get(err.name or "", err.name)
        return (f"{url!r} needs the Python driver {err.name!r}, which is not installed: "
                f"pip install {package}")
    if parsed.get_backend_name() == "sqlite" and parsed.database not in (None, "", ":memory:"):
        folder = Path(parsed.database).expanduser().resolve().parent
        if not folder.is_dir():
            return f"the folder {folder} of {url!r} does not exist; create it (mkdir -p {folder})"
    return None


def _settings(db: str | None):  # noqa: ANN202
    """Settings for ``--db`` (else $PENDANT_DB_URL, else the default file), the URL checked
    first: a typo is one line saying what to type (CalibrationError on --db)."""
    from server.settings import ENV_DB_URL, Settings, default_db_url

    url = db or default_db_url()
    problem = db_url_problem(url)
    if problem:
        raise CalibrationError(("--db" if db else ENV_DB_URL,), problem)
    return Settings(db_url=url)


def _open_app(db: str | None, **overrides: object):  # noqa: ANN202
    """The app on ``--db``; a database that refuses the connection is one line, not a trace."""
    import dataclasses

    from sqlalchemy.exc import DBAPIError

    from server.api.app import create_app

    settings = dataclasses.replace(_settings(db), **overrides)
    try:
        return create_app(settings)
    except DBAPIError as err:
        reason = str(err.orig).strip().splitlines()[0] if err.orig else type(err).__name__
        raise CalibrationError(("--db",), f"cannot open {settings.db_url!r}: {reason}") from None


ENV_TRUSTED_PROXIES = "PENDANT_TRUSTED_PROXIES"


def proxy_options(args: argparse.Namespace) -> dict[str, object]:
    """uvicorn's options for forwarded headers: believed only from ``--trusted-proxy`` /
    $PENDANT_TRUSTED_PROXIES (uvicorn's default believes 127.0.0.1, so any local process
    could write another client address into the audit)."""
    env = [p.strip() for p in os.environ.get(ENV_TRUSTED_PROXIES, "").split(",") if p.strip()]
    trusted = list(getattr(args, "trusted_proxy", []) or []) + env
    return {"proxy_headers": bool(trusted), "forwarded_allow_ips": ",".join(trusted) or ""}


def _serve(app, host: str, port: int, **options: object) -> None:  # noqa: ANN001
    """uvicorn on ``app``, whose second Ctrl-C stops at once with one line instead of
    cancelling the requests in flight (a 500 and a CancelledError trace per request and for
    the lifespan). What a request had committed stays; the interrupted one saves nothing more."""
    import uvicorn

    class Server(uvicorn.Server):
        interrupted = False
        reraising = False  # uvicorn (0.29 on) raises the Ctrl-C it caught again, after its stop

        def handle_exit(self, sig: int, frame: object) -> None:
            if self.should_exit and sig == signal.SIGINT:  # the second Ctrl-C
                self.stop_now()
            self.interrupted = self.interrupted or sig == signal.SIGINT
            super().handle_exit(sig, frame)

        def stop_now(self) -> None:
            busy = len(self.server_state.tasks)
            print(f"pendant: stopped at once; {busy} request(s) in progress abandoned "
                  "(they saved nothing)", file=sys.stderr, flush=True)
            os._exit(130)

        @contextmanager
        def capture_signals(self) -> Iterator[None]:
            inner = super().capture_signals()  # type: ignore[misc]
            inner.__enter__()
            try:
                yield
            finally:
                self.reraising = True  # it restores the handlers, then raises what it caught
                try:
                    inner.__exit__(None, None, None)
                finally:
                    self.reraising = False

    server = Server(uvicorn.Config(app, host=host, port=port, **options))

    def after_uvicorn(sig: int, frame: object) -> None:
        # SIGINT outside uvicorn's own handler: before it starts, uvicorn's raising again the
        # Ctrl-C it stopped for, and (a second Ctrl-C) while the event loop winds down after it.
        # asyncio's handler raised the second one wherever the loop was (a traceback, status 1).
        if server.interrupted and not server.reraising:
            server.stop_now()
        raise KeyboardInterrupt

    main_thread = threading.current_thread() is threading.main_thread()  # signals: only there
    if main_thread:
        signal.signal(signal.SIGINT, after_uvicorn)  # so asyncio.run installs none of its own
    try:
        server.run()
    finally:
        if main_thread and not server.interrupted:
            signal.signal(signal.SIGINT, signal.default_int_handler)
    if server.interrupted:  # uvicorn before 0.29 returns after a Ctrl-C; later ones re-raise it
        raise KeyboardInterrupt


SPINNER = "|/-\\"


@contextmanager
def progress_line(label: str, stream: TextIO | None = None) -> Iterator[None]:
    """On a terminal, a line that shows ``label`` is still running: a spinner and the seconds
    so far, redrawn ten times a second and erased at the end. Elsewhere (a pipe, a file, a
    test) it prints nothing. For work whose length is not known in advance (an analysis)."""
    stream = stream or sys.stderr
    if not stream.isatty():
        yield
        return
    done = threading.Event()
    start = time.monotonic()

    def draw() -> None:
        for k in itertools.count():
            stream.write(f"\r{SPINNER[k % 4]} {label} {time.monotonic() - start:5.1f} s")
            stream.flush()
            if done.wait(0.1):
                break
        stream.write("\r\033[K")
        stream.flush()

    thread = threading.Thread(target=draw, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()


def _check_port_free(host: str, port: int) -> None:
    """Refuse a port already in use before starting uvicorn, suggesting --port. The probe
    binds with ``SO_REUSEADDR``, as uvicorn does: connections of a service just stopped, left
    in TIME_WAIT, do not hold the port; a listener does."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as err:
            if err.errno == errno.EADDRINUSE:
                raise CalibrationError(("--port",), f"port {port} on {host} is in use (another "
                                       f"pendant serve?); choose another: pendant serve "
                                       f"--port {port + 1}") from None
            raise CalibrationError(("--host",), f"cannot listen on {host}:{port}: "
                                   f"{err.strerror}") from None


WORKER_HEALTHCHECK_S = 60


class SchemaOutOfDate(RuntimeError):
    """Raised by ``serve --no-migrate`` on an old schema (server.api.app.SchemaOutOfDate)."""


def serve(args: argparse.Namespace) -> int:
    """Run the service: one process, or ``--workers N`` uvicorn processes on one database.

    The app is built once here first: the schema is migrated under the database lock (or
    refused with ``--no-migrate``), the demo controller and, on first start, the
    Administrator are made, and the Administrator's login link is printed. Each worker then
    builds its own app from the same settings (passed on in the environment)."""
    import os

    import uvicorn
    from sqlalchemy.engine import make_url

    from server.api import app as app_module
    from server.settings import (ENV_ALLOWED_HOSTS, ENV_CORS_ORIGINS, ENV_DB_URL, ENV_MIGRATE,
                                 ENV_NO_AUTH, LOOPBACK_HOSTS)

    if args.workers < 1:
        raise CalibrationError(("--workers",), f"must be >= 1, got {args.workers}")
    _positive(args.job_time_s, "--job-time-s")
    _positive(args.job_memory_mb, "--job-memory-mb")
    if args.opcua_pki is not None and not args.opcua_port:
        raise CalibrationError(("--opcua-pki",), "goes with --opcua-port (the OPC UA face's PKI "
                                                 "folder)")
    _check_port_free(args.host, args.port)
    loopback = args.host in LOOPBACK_HOSTS
    if args.no_auth and not loopback:
        print(f"pendant: --host: --no-auth serves loopback only (127.0.0.1, localhost, ::1), "
              f"not {args.host}", file=sys.stderr)
        return 2
    extra_hosts = list(args.allow_host)
    if not loopback and args.host not in ("0.0.0.0", "::"):
        extra_hosts.append(args.host)
    base_settings = _settings(args.db)
    overrides = {"migrate": not args.no_migrate, "auth": not args.no_auth,
                 "allowed_hosts": base_settings.allowed_hosts + tuple(extra_hosts),
                 "cors_origins": tuple(args.cors_origin)}
    try:
        application = _open_app(args.db, **overrides)
    except app_module.SchemaOutOfDate as err:
        raise SchemaOutOfDate(str(err)) from None
    settings = application.state.settings
    shown = "localhost" if args.host in ("0.0.0.0", "::") else args.host
    base = f"http://{'[::1]' if shown == '::1' else shown}:{args.port}"
    shown_db = make_url(settings.db_url).render_as_string(hide_password=True)  # no password
    print(f"pendant: database: {shown_db}", file=sys.stderr)
    if args.no_auth:
        print("pendant: WARNING: --no-auth: NO LOGIN. Anyone who can reach this port may move "
              "the robot and change every frame. A demo on loopback only.", file=sys.stderr)
    elif application.state.first_token:
        t = application.state.first_token
        print(f"pendant: first start: created the Administrator \"admin\". Log in once with\n"
              f"    {base}/login.html#token={t}\n"
              f"(valid 24 h, shown only now; API: Authorization: Bearer {t}).\n"
              f"More users: pendant users add NAME --role Expert; pendant tokens create NAME",
              file=sys.stderr)
    else:
        print(f"pendant: serving {base}; a login link for the Administrator: "
              f"pendant tokens create admin --db '{shown_db}'", file=sys.stderr)
    workers = start_job_workers(settings.db_url, args)  # the schema is current by now
    face = (start_beside(args.host, args.opcua_port, settings.db_url, auth=settings.auth,
                         pki=args.opcua_pki) if args.opcua_port else None)
    try:
        controller_faces = start_faces(args, application.state.sessionmaker, settings.auth,
                                       settings.allowed_hosts)
    except BaseException:
        for child in (workers, face):
            if child is not None:
                child.terminate()
        raise
    try:
        if args.workers == 1:
            application.state.service_process = True  # a service process (server.api.app.lifespan)
            _serve(application, args.host, args.port, **proxy_options(args))
        else:
            # each worker builds server.api.app:app from the environment (server.settings)
            os.environ.update({
                ENV_DB_URL: settings.db_url, ENV_MIGRATE: "0" if args.no_migrate else "1",
                ENV_NO_AUTH: "0" if settings.auth else "1",
                ENV_ALLOWED_HOSTS: ",".join(settings.allowed_hosts),
                ENV_CORS_ORIGINS: ",".join(settings.cors_origins)})
            # a worker imports numpy/scipy before it can answer the supervisor's ping: on a busy
            # host that takes longer than uvicorn's 5 s default, and it would be killed as hung
            uvicorn.run("server.api.app:app", host=args.host, port=args.port, workers=args.workers,
                        timeout_worker_healthcheck=WORKER_HEALTHCHECK_S, **proxy_options(args))
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # stopping: one more Ctrl-C changes nothing
        for running in controller_faces:
            running.stop()
        for child in (workers, face):
            if child is not None:
                child.terminate()
                child.wait(timeout=30)
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
        if args.command == "worker":
            return run_worker(args)
        if args.command == "calibrate":
            given = (("tcp_mm", args.tcp), ("reference_tcp_mm", args.reference_tcp),
                     ("fixed_tcp_mm", args.fixed_tcp))
            overrides = {k: _vec(v, 3, f"--{k.replace('_mm', '').replace('_', '-')}")
                         for k, v in given if v}
            if args.rail:
                overrides["rail"] = _rail_option(args.rail)
            result = calibrate_file(args.method, args.file, args.robot, overrides)
            report = ReportOut.from_result(result)
            print(report.model_dump_json(indent=1) if args.json else format_report(report))
            return 0
        if args.command == "export":
            from db import crud
            from server.service.export import export_text

            app = _open_app(args.db)
            with app.state.sessionmaker() as db:
                controller = crud.find_controller(db, args.controller)
                if args.format in ("kuka", "abb", "fanuc", "ur"):  # the file's own encoding
                    from server.service.controller_files import export_file_bytes

                    raw, _ = export_file_bytes(db, controller.id, args.format)
                    sys.stdout.flush()
                    sys.stdout.buffer.write(raw)
                    sys.stdout.buffer.flush()
                else:
                    sys.stdout.write(export_text(db, controller.id, args.format))
            return 0
        if args.command == "import":
            import getpass

            from server.auth import audit

            # audited as the user running it, as `pendant users/tokens/roles` are (cli:<os user>)
            with audit.acting_as({"user_name": f"cli:{getpass.getuser()}", "role": None,
                                  "source": "cli"}):
                return import_file(args)
        if not hasattr(args, "func"):
            return 2
        name = Path(args.file).name if getattr(args, "file", None) else ""
        with progress_line(f"pendant {args.command} {name}".rstrip() + ": working"):
            return int(args.func(args) or 0)
    except SchemaOutOfDate as err:
        print(f"pendant: {err}", file=sys.stderr)
        return 2
    except CalibrationError as err:
        print(f"pendant: {'.'.join(str(x) for x in err.loc)}: {err.reason}", file=sys.stderr)
        return 2
    except LookupError as err:
        print(f"pendant: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `pendant analyze ... | head`: the reader left; not an error to print
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # the interpreter's last flush goes nowhere
        return 141  # 128 + SIGPIPE, as a shell reports a command a pipe stopped
    except OSError as err:  # a missing file: "pendant: FILE: No such file or directory"
        where = err.filename if err.filename is not None else None
        print(f"pendant: {where}: {err.strerror}" if where and err.strerror else f"pendant: {err}",
              file=sys.stderr)
        return 2
    except UnicodeDecodeError as err:
        print(f"pendant: {args.file}: not UTF-8 text ({err.reason} at byte {err.start})",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # leaving: one more Ctrl-C changes nothing
        print("pendant: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # the database busy or gone: one line, to try again (EX_TEMPFAIL)
        why = retry_reason(err)
        print(f"pendant: {why}", file=sys.stderr)
        return EX_TEMPFAIL


if __name__ == "__main__":
    raise SystemExit(main())
