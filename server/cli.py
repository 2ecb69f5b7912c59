"""The ``pendant`` command: serve the pendant, calibrate from a file, export a controller's tables.

    pendant serve [--host 127.0.0.1] [--port 8000] [--db URL]
    pendant calibrate METHOD FILE [--robot KEY] [--tcp X,Y,Z] [--json]
    pendant export CONTROLLER --format kuka|abb|fanuc|ur|json [--db URL]

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
import signal
import socket
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Sequence, TextIO

import numpy as np

from server import __version__
from server.analysis_cli import add_analysis_commands
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
    lines += [f"{w.severity:8s}    {w.message}" for w in report.warnings
              if not (report.bad_point and w.code == "bad_point")]  # said once, above
    if report.guidance:
        lines.append(f"guidance    {report.guidance}")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------ main

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
    c.add_argument("--json", action="store_true", help="print the report as JSON")

    e = sub.add_parser("export", help="print a controller's tables as a controller file")
    e.add_argument("controller", help="controller name (or id), e.g. cell-1")
    e.add_argument("--format", choices=["kuka", "abb", "fanuc", "ur", "json"], default="kuka",
                   help="kuka: $config.dat; abb: a RAPID module; fanuc: frames; ur: a URScript; "
                        "json: the whole controller as a backup (default: %(default)s)")
    e.add_argument("--db", metavar="URL", help=DB_HELP)

    add_analysis_commands(sub)
    return p


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


def _open_app(db: str | None):  # noqa: ANN202
    """The app on ``--db``; a database that refuses the connection is one line, not a trace."""
    from sqlalchemy.exc import DBAPIError

    from server.app import create_app

    settings = _settings(db)
    try:
        return create_app(settings)
    except DBAPIError as err:
        reason = str(err.orig).strip().splitlines()[0] if err.orig else type(err).__name__
        raise CalibrationError(("--db",), f"cannot open {settings.db_url!r}: {reason}") from None


def _serve(app, host: str, port: int) -> None:  # noqa: ANN001
    """uvicorn on ``app``, whose second Ctrl-C stops at once with one line instead of
    cancelling the requests in flight (a 500 and a CancelledError trace per request and for
    the lifespan). What a request had committed stays; the interrupted one saves nothing more."""
    import uvicorn

    class Server(uvicorn.Server):
        def handle_exit(self, sig: int, frame: object) -> None:
            if self.should_exit and sig == signal.SIGINT:  # the second Ctrl-C
                busy = len(self.server_state.tasks)
                print(f"pendant: stopped at once; {busy} request(s) in progress abandoned "
                      "(they saved nothing)", file=sys.stderr, flush=True)
                os._exit(130)
            super().handle_exit(sig, frame)

    Server(uvicorn.Config(app, host=host, port=port)).run()


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
    """Refuse a port already in use before starting uvicorn, suggesting --port."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        try:
            probe.bind((host, port))
        except OSError as err:
            if err.errno == errno.EADDRINUSE:
                raise CalibrationError(("--port",), f"port {port} on {host} is in use (another "
                                       f"pendant serve?); choose another: pendant serve "
                                       f"--port {port + 1}") from None
            raise CalibrationError(("--host",), f"cannot listen on {host}:{port}: "
                                   f"{err.strerror}") from None


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "serve":
            _check_port_free(args.host, args.port)
            _serve(_open_app(args.db), args.host, args.port)
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
            from server.routers.export import export_text

            app = _open_app(args.db)
            with app.state.sessionmaker() as db:
                controller = crud.find_controller(db, args.controller)
                sys.stdout.write(export_text(db, controller.id, args.format))
            return 0
        if not hasattr(args, "func"):
            return 2
        name = Path(args.file).name if getattr(args, "file", None) else ""
        with progress_line(f"pendant {args.command} {name}".rstrip() + ": working"):
            return int(args.func(args) or 0)
    except CalibrationError as err:
        print(f"pendant: {'.'.join(str(x) for x in err.loc)}: {err.reason}", file=sys.stderr)
        return 2
    except LookupError as err:
        print(f"pendant: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"pendant: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("pendant: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    raise SystemExit(main())
