"""``pendant analyze`` and ``pendant simulate``: the analysis from the command line.

    pendant analyze RECORDING.json [--json] [--folds K] [--seed S] [--split blocked|random]
                    [--save-model MODEL.json] [--service URL]
    pendant predict MODEL.json RECORDING.json [--refit-setup] [--json] [--service URL]
    pendant simulate KIND --robot KEY [--effect NAME[:JOINT]=VALUE ...] [--noise MM]
                     [--payload KG] [--n N] [--seed S] -o FILE
    pendant plan ROBOT --effects EFFECT[:JOINT],... [--n 30] [--workspace X0,Y0,Z0,X1,Y1,Z1]
                 [--instrument tracker|touch] [--payload KG] [--seed S] [-o PLAN.json]
                 [--record REC.json [--effect NAME[:JOINT]=VALUE ...] [--noise MM]]

``--effect`` (repeatable) switches on one hidden effect of the simulated robot, in the units
of the analysis report: ``offset:J=DEG``, ``a:J=MM``, ``d:J=MM``, ``alpha:J=DEG``,
``compliance:J=DEG_PER_NM``, ``backlash:J=DEG``, ``drift=MM`` (along base z),
``latency=MS``, ``deflection=MM_PER_N``, ``tau=S`` (the drift's warm-up time constant; none:
linear), ``cyclic:J=DEG@PERIODS`` (a gear's periodic error in the controller's sense),
``gear:J=DEG@PERIODS[@PHASE_DEG]`` (a ``gear_transmission_error`` harmonic, repeatable).

``plan`` proposes poses that pin down the named effects (D-optimal, docs/analysis.md); with
``--record`` it also writes a simulated tracker recording measured at those poses. Example::

    pendant simulate tracker --robot ur10 --effect compliance:2=0.0005 --payload 5 -o rec.json
    pendant analyze rec.json
    pendant plan ur10 --effects joint_compliance:2,link_length --payload 5 -o plan.json \
        --record rec.json --effect compliance:2=0.0005
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
          "deflection": "tool_deflection_mm_per_N", "tau": "thermal_tau_s"}


def parse_effects(specs: list[str], n_joints: int, noise_mm: float):  # noqa: ANN201
    """``Imperfections`` from ``--effect`` strings (see the module docstring)."""
    from solvers.physics import Imperfections

    per: dict[str, list[float]] = {}
    dh: dict[tuple[str, int], float] = {}
    scalar: dict[str, float] = {}
    cyclic: dict[int, tuple[float, float]] = {}
    gears: list[tuple[int, float, float, float]] = []
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
            if name == "gear":
                parts = value.split("@")
                if not 1 <= len(parts) <= 3:
                    raise ValueError
                amp, periods, phase = parts + ["1", "0"][len(parts) - 1:]
                if joint is None or not 1 <= joint <= n_joints:
                    raise ValueError
                gears.append((joint, float(amp), float(periods), float(phase)))
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
            known = ", ".join(sorted([*PER_JOINT, *DH, *SCALAR, "cyclic", "gear"]))
            raise CalibrationError(("--effect",), f"unknown effect {name!r}; known: {known}")
    return Imperfections(**{k: tuple(v) for k, v in per.items()}, dh_delta=dh, cyclic_error=cyclic,
                         gear_transmission_error=tuple(gears), noise_mm=noise_mm, **scalar)


def _call(base: str, method: str, path: str, body: bytes | None = None) -> Any:
    """One request to the service; its JSON answer, or CalibrationError with its named error."""
    import urllib.error
    import urllib.request

    from server.settings import bearer_headers

    req = urllib.request.Request(base.rstrip("/") + path, data=body, method=method,
                                 headers={"content-type": "application/json", **bearer_headers()})
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
                       poll_s: float = 0.3, split: str | None = None) -> dict[str, Any]:
    """Store the recording on the service, queue its analysis (202: a job), follow the job
    with its progress on stderr, and return the stored report. Ctrl-C cancels the job."""
    import time

    rec = _call(base, "POST", "/recordings", text.encode("utf-8"))
    query = f"folds={folds}&seed={seed}" + (f"&split={split}" if split else "")
    job = _call(base, "POST", f"/recordings/{rec['id']}/analyze?{query}")
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
        report = analyze_on_service(args.service, text, args.folds, args.seed, split=args.split)
        if args.save_model:
            report["model"] = _call(args.service, "GET", f"/analysis/{report['id']}/model")
    else:
        from server.formats.recording import parse_recording
        from solvers.analysis import analyze

        report = analyze(parse_recording(doc), folds=args.folds, seed=args.seed,
                         split=args.split)
    model = report.pop("model", None)
    if args.save_model:
        if model is None:
            raise CalibrationError(("--save-model",), "the analysis returned no model")
        Path(args.save_model).write_text(json.dumps(model, indent=1), encoding="utf-8")
        print(f"wrote {args.save_model}: robot-model/1 with {len(model['effects'])} effects",
              file=sys.stderr)
    print(json.dumps(report, indent=1) if args.json else render_text(report))
    return 0


def _read_json(path: Path, field: str) -> Any:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as err:
        raise CalibrationError((field,), f"cannot read {path}: {err.strerror}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise CalibrationError((field,), f"{path} is not JSON: {err.msg} at line "
                               f"{err.lineno}") from None


def run_predict(args: argparse.Namespace) -> int:
    model = _read_json(args.model, "model")
    doc = _read_json(args.file, "recording")
    if args.service:
        body = json.dumps({"model": model, "recording": doc,
                           "refit_setup": bool(args.refit_setup)}).encode("utf-8")
        out = _call(args.service, "POST", "/predict", body)
    else:
        from server.formats.recording import parse_recording
        from solvers.analysis.blas import single_thread
        from solvers.analysis.model import predict

        rec = parse_recording(doc, measurements_optional=True)
        with single_thread():
            out = predict(model, rec, refit_setup=args.refit_setup)
    if args.json:
        print(json.dumps(out))
    else:
        rms = f", RMS {out['rms_mm']:.4f} mm against the measurements" if "rms_mm" in out else ""
        print(f"predicted {out['n_samples']} samples"
              f"{' (setup refitted)' if out['refit_setup'] else ''}{rms}")
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


def run_plan(args: argparse.Namespace) -> int:
    from solvers.analysis.plan import Workspace, parse_effects as plan_effects
    from solvers.analysis.plan import plan_poses, record_plan

    if args.robot not in ROBOTS:
        raise CalibrationError(("robot",), "unknown robot; known: " + ", ".join(sorted(ROBOTS)))
    robot = ROBOTS[args.robot]
    ws = None if args.workspace is None else Workspace.parse(args.workspace, robot)
    payload = (args.payload, (0.0, 0.0, 50.0))
    plan = plan_poses(robot, plan_effects(args.effects, robot.dof), args.n, workspace=ws,
                      instrument=args.instrument, payload=payload, seed=args.seed)
    text = json.dumps(plan, indent=1)
    if args.output:
        Path(args.output).write_text(text, encoding="utf-8")
        print(f"wrote {args.output}: {plan['n_poses']} poses for "
              f"{', '.join(plan['parameters'])}", file=sys.stderr)
    else:
        print(text)
    if args.record:
        if args.instrument != "tracker":
            raise CalibrationError(("--record",), "records a tracker recording: plan with "
                                   "--instrument tracker (touch poses are taught on the pendant)")
        imp = parse_effects(args.effect or [], robot.dof, args.noise)
        doc = record_plan(robot, plan["joints_deg"], imp, seed=args.seed, payload=payload)
        Path(args.record).write_text(json.dumps(doc, indent=1), encoding="utf-8")
        print(f"wrote {args.record}: {len(doc['samples'])} tracker samples at the plan's poses",
              file=sys.stderr)
    return 0


def add_analysis_commands(subparsers: Any) -> None:
    """Register ``analyze``, ``predict``, ``simulate`` and ``plan`` on the ``pendant`` command's
    subparsers."""
    a = subparsers.add_parser("analyze", help="name the physics a robot's rigid model leaves out "
                                              "(from a robot-recording/1 file)")
    a.add_argument("file", type=Path, help="robot-recording/1 JSON document")
    a.add_argument("--json", action="store_true", help="print the analysis-report/1 JSON")
    a.add_argument("--folds", type=int, default=5, help="K of the K-fold cross-validation (5)")
    a.add_argument("--seed", type=int, default=0, help="seed of the fold assignment (0)")
    a.add_argument("--split", choices=["blocked", "random"], default=None,
                   help="how samples are dealt to the folds: blocked (contiguous runs in "
                        "recorded order; the default for tracker recordings ordered in time) "
                        "or random")
    a.add_argument("--save-model", type=Path, default=None, metavar="MODEL.json",
                   help="also write the fitted robot-model/1 (for pendant predict)")
    a.add_argument("--service", metavar="URL", help="($PENDANT_TOKEN: its token) analyse on a pendant service (e.g. "
                   "http://127.0.0.1:8000): the recording and report are stored there, the "
                   "analysis runs as a job in its workers (Ctrl-C cancels it)")
    a.set_defaults(func=run_analyze)

    r = subparsers.add_parser("predict", help="predict a recording with a saved robot-model/1 "
                                              "(pendant analyze --save-model)")
    r.add_argument("model", type=Path, help="robot-model/1 JSON document")
    r.add_argument("file", type=Path, help="robot-recording/1 of the same robot")
    r.add_argument("--refit-setup", action="store_true",
                   help="another session: fit the instrument frame, tool point and per-session "
                        "terms to this recording first, the robot's parameters held")
    r.add_argument("--json", action="store_true", help="print the prediction/1 JSON")
    r.add_argument("--service", metavar="URL", help="($PENDANT_TOKEN: its token) predict on a "
                   "pendant service (POST /predict)")
    r.set_defaults(func=run_predict)

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

    p = subparsers.add_parser("plan", help="propose poses that pin down chosen effects "
                                           "(D-optimal; optionally record them)")
    p.add_argument("robot", help="robot key (" + ", ".join(sorted(ROBOTS)) + ")")
    p.add_argument("--effects", action="append", required=True, metavar="EFFECT[:JOINT],...",
                   help="joint_offset, link_length, link_twist, joint_compliance, "
                        "tool_deflection; no joint: every joint")
    p.add_argument("--n", type=int, default=30, help="number of poses (30)")
    p.add_argument("--workspace", default=None, metavar="X0,Y0,Z0,X1,Y1,Z1",
                   help="box for the TCP, mm in base (default in front of the robot)")
    p.add_argument("--instrument", choices=["tracker", "touch"], default="tracker")
    p.add_argument("--payload", type=float, default=0.0, help="payload mass, kg (at 50 mm on flange z)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-o", "--output", type=Path, default=None, help="write the plan here (else stdout)")
    p.add_argument("--record", type=Path, default=None,
                   help="also write a simulated tracker recording at the plan's poses")
    p.add_argument("--effect", action="append", metavar="NAME[:JOINT]=VALUE",
                   help="--record: hidden effect, as for simulate")
    p.add_argument("--noise", type=float, default=0.02, help="--record: noise per axis, mm")
    p.set_defaults(func=run_plan)
