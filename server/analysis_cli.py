"""``pendant analyze`` and ``pendant simulate``: the analysis from the command line.

    pendant analyze RECORDING.json [--json] [--folds K] [--seed S] [--service URL]
    pendant simulate KIND --robot KEY [--effect NAME[:JOINT]=VALUE ...] [--noise MM]
                     [--payload KG] [--n N] [--seed S] -o FILE

``--effect`` (repeatable) switches on one hidden effect of the simulated robot, in the units
of the analysis report: ``offset:J=DEG``, ``a:J=MM``, ``d:J=MM``, ``alpha:J=DEG``,
``compliance:J=DEG_PER_NM``, ``backlash:J=DEG``, ``drift=MM`` (along base z),
``latency=MS``, ``deflection=MM_PER_N``, ``cyclic:J=DEG@PERIODS`` (a gear's periodic error, not
in the analysis's library). Example::

    pendant simulate tracker --robot ur10 --effect compliance:2=0.0005 --payload 5 -o rec.json
    pendant analyze rec.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from solvers.errors import CalibrationError
from solvers.robots import ROBOTS

PER_JOINT = {"offset": "joint_offset_deg", "compliance": "compliance_deg_per_Nm",
             "backlash": "backlash_deg"}
DH = {"a": "a_mm", "d": "d_mm", "alpha": "alpha_deg"}
SCALAR = {"drift": "thermal_drift_mm", "latency": "trigger_latency_ms",
          "deflection": "tool_deflection_mm_per_N"}


def parse_effects(specs: list[str], n_joints: int, noise_mm: float):  # noqa: ANN201
    """``Imperfections`` from ``--effect`` strings (see the module docstring)."""
    from solvers.physics import Imperfections

    per: dict[str, list[float]] = {}
    dh: dict[tuple[str, int], float] = {}
    scalar: dict[str, float] = {}
    cyclic: dict[int, tuple[float, float]] = {}
    for spec in specs:
        try:
            name, value = spec.split("=", 1)
            name, _, joint_s = name.partition(":")
            joint = int(joint_s) if joint_s else None
            if name == "cyclic":
                amp, _, periods = value.partition("@")
                if joint is None or not 1 <= joint <= n_joints:
                    raise ValueError
                cyclic[joint] = (float(amp), float(periods or 1))
                continue
            v = float(value)
        except ValueError:
            raise CalibrationError(("--effect",), f"cannot read {spec!r}: use NAME[:JOINT]=VALUE, "
                                   "e.g. compliance:2=0.0005 or latency=3") from None
        if name in PER_JOINT or name in DH:
            if joint is None or not 1 <= joint <= n_joints:
                raise CalibrationError(("--effect",), f"{spec!r}: {name} needs a joint 1..{n_joints}")
            if name in DH:
                dh[(DH[name], joint)] = v
            else:
                per.setdefault(PER_JOINT[name], [0.0] * n_joints)[joint - 1] = v
        elif name in SCALAR:
            scalar[SCALAR[name]] = v
        else:
            known = ", ".join(sorted([*PER_JOINT, *DH, *SCALAR, "cyclic"]))
            raise CalibrationError(("--effect",), f"unknown effect {name!r}; known: {known}")
    return Imperfections(**{k: tuple(v) for k, v in per.items()}, dh_delta=dh, cyclic_error=cyclic,
                         noise_mm=noise_mm, **scalar)


def _call(base: str, method: str, path: str, body: bytes | None = None) -> Any:
    """One request to the service; its JSON answer, or CalibrationError with its named error."""
    import urllib.error
    import urllib.request

    req = urllib.request.Request(base.rstrip("/") + path, data=body, method=method,
                                 headers={"content-type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return json.loads(r.read() or b"null")
    except urllib.error.HTTPError as err:
        try:
            item = json.loads(err.read())["detail"][0]
            loc, msg = tuple(str(x) for x in item["loc"]) or ("service",), item["msg"]
        except (ValueError, KeyError, IndexError, TypeError):
            loc, msg = ("service",), f"{err.code} {err.reason}"
        raise CalibrationError(loc, f"{msg} ({err.code})") from None
    except urllib.error.URLError as err:
        raise CalibrationError(("--service",), f"no answer from {base}: {err.reason}") from None


def analyze_on_service(base: str, text: str, folds: int, seed: int,
                       poll_s: float = 0.3) -> dict[str, Any]:
    """Store the recording on the service, queue its analysis (202: a job), follow the job
    with its progress on stderr, and return the stored report. Ctrl-C cancels the job."""
    import time

    rec = _call(base, "POST", "/recordings", text.encode("utf-8"))
    job = _call(base, "POST", f"/recordings/{rec['id']}/analyze?folds={folds}&seed={seed}")
    try:
        while job["state"] not in ("done", "failed", "cancelled"):
            print(f"job {job['id']}: {job['state']} {100 * job['progress']:.0f} % "
                  f"{job['message']}", file=sys.stderr)
            time.sleep(poll_s)
            job = _call(base, "GET", job["links"]["self"])
    except KeyboardInterrupt:
        _call(base, "POST", job["links"]["cancel"])
        print(f"job {job['id']}: cancel requested", file=sys.stderr)
        raise
    if job["state"] == "cancelled":
        raise CalibrationError(("job", job["id"]), "was cancelled")
    if job["state"] == "failed":
        item = job["error"]["detail"][0]
        raise CalibrationError(tuple(item["loc"]) or ("job", job["id"]),
                               f"{item['msg']} ({job['error']['status']})")
    return _call(base, "GET", job["links"]["result"])


def run_analyze(args: argparse.Namespace) -> int:
    from solvers.analysis import render_text

    text = Path(args.file).read_text(encoding="utf-8")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as err:
        raise CalibrationError(("file",), f"not JSON: {err.msg} at line {err.lineno}") from None
    if args.service:
        report = analyze_on_service(args.service, text, args.folds, args.seed)
    else:
        from server.recording import parse_recording
        from solvers.analysis import analyze

        report = analyze(parse_recording(doc), folds=args.folds, seed=args.seed)
    print(json.dumps(report, indent=1) if args.json else render_text(report))
    return 0


def run_simulate(args: argparse.Namespace) -> int:
    from solvers.simulate import simulate_recording

    robot = ROBOTS[args.robot]
    imp = parse_effects(args.effect or [], robot.dof, args.noise)
    payload: Any = (args.payload, [0.0, 0.0, 50.0]) if args.payload else None
    doc = simulate_recording(args.kind, robot, imp, args.n, seed=args.seed, payload=payload)
    Path(args.output).write_text(json.dumps(doc, indent=1), encoding="utf-8")
    print(f"wrote {args.output}: {len(doc['samples'])} {args.kind} samples of {robot.name}",
          file=sys.stderr)
    return 0


def add_analysis_commands(subparsers: Any) -> None:
    """Register ``analyze`` and ``simulate`` on the ``pendant`` command's subparsers."""
    a = subparsers.add_parser("analyze", help="name the physics a robot's rigid model leaves out "
                                              "(from a robot-recording/1 file)")
    a.add_argument("file", type=Path, help="robot-recording/1 JSON document")
    a.add_argument("--json", action="store_true", help="print the analysis-report/1 JSON")
    a.add_argument("--folds", type=int, default=5, help="K of the K-fold cross-validation (5)")
    a.add_argument("--seed", type=int, default=0, help="seed of the fold assignment (0)")
    a.add_argument("--service", metavar="URL", help="analyse on a pendant service (e.g. "
                   "http://127.0.0.1:8000): the recording and report are stored there, the "
                   "analysis runs as a job in its workers (Ctrl-C cancels it)")
    a.set_defaults(func=run_analyze)

    s = subparsers.add_parser("simulate", help="write a simulated robot-recording/1 with hidden effects")
    s.add_argument("kind", choices=["touch", "tracker", "beam"])
    s.add_argument("--robot", required=True, choices=sorted(ROBOTS))
    s.add_argument("--effect", action="append", metavar="NAME[:JOINT]=VALUE",
                   help="hidden effect, repeatable (offset, a, d, alpha, compliance, backlash, "
                        "drift, latency, deflection, cyclic:J=DEG@PERIODS)")
    s.add_argument("--noise", type=float, default=0.02, help="measurement noise per axis, mm (0.02)")
    s.add_argument("--payload", type=float, default=0.0, help="payload mass, kg (at 50 mm on the flange z)")
    s.add_argument("--n", type=int, default=None, help="number of samples (kind's default)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("-o", "--output", required=True, type=Path, help="file to write")
    s.set_defaults(func=run_simulate)
