"""``pendant slot``: read or edit one tool/base slot or external kinematic of a running
service, with If-Match.

    pendant slot tool 3 [--url URL] [--controller 1]   # URL: --url, else $PENDANT_SERVICE
    pendant slot tool 3 --name pointer --pose 1.5,-2,180,0,0,0 [--etag '"4"']
    pendant slot tool 3 --x 1.75                    # X alone: y, z, a, b, c keep every digit
    pendant slot ext 1 --pose 520,380,80,0,0,0     # EX_KIN 1: --pose is its root frame

It reads the slot (and its ``ETag``), then writes it with ``If-Match`` so an edit never
overwrites a change someone else made in between: the service answers 412, and this command
prints what the slot holds now and exits 3 without writing. ``--etag`` sends the ETag of an
earlier read instead (what you saw, not what is there now).

Mistakes exit 2 with one line naming the field (``--pose: ...``) or the service's refusal
(``pendant: 404: ...``, ``pendant: 401: ... set PENDANT_TOKEN``), never raw JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import urllib.error
import urllib.request
from typing import Any

from server.settings import bearer_headers

EXIT_STALE = 3
DEFAULT_URL = "http://127.0.0.1:8000"
URL_ENV = "PENDANT_SERVICE"  # the service's URL, as --url / --service give it


class _BadArgument(ValueError):
    """A command-line value this command cannot use: exit 2 with the field and the reason."""


def _call(method: str, url: str, body: dict | None = None,
          headers: dict[str, str] | None = None) -> tuple[int, Any, Any]:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method, headers={
        **({"Content-Type": "application/json"} if data else {}), **bearer_headers(),
        **(headers or {})})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, r.headers, _json(r.read())
    except urllib.error.HTTPError as err:
        return err.code, err.headers, _json(err.read())


def _json(raw: bytes) -> Any:
    try:
        return json.loads(raw or b"null")
    except ValueError:
        return raw.decode("utf-8", "replace").strip()


def _refusal(status: int, answer: Any) -> str:
    """The service's refusal in one line: ``401: unknown token (...)``, ``404: no tool 99``."""
    detail = answer.get("detail") if isinstance(answer, dict) else answer
    if isinstance(detail, list):
        msgs = []
        for d in detail:
            loc = ".".join(str(x) for x in d.get("loc", []) if x not in ("body", "path", "query"))
            msgs.append(f"{loc}: {d.get('msg')}" if loc else str(d.get("msg")))
        text = "; ".join(msgs)
    else:
        text = str(detail or "").splitlines()[0] if detail else ""
    if status == 401:
        text = (text or "not logged in") + (" (set PENDANT_TOKEN to a token: pendant tokens "
                                            "create NAME)")
    return f"{status}: {text or 'refused'}"


def _pose(text: str) -> dict[str, float]:
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 6:
        raise _BadArgument(f"--pose: needs x,y,z,a,b,c (6 numbers), got {text!r}")
    return dict(zip("xyzabc", v))


PATHS = {"tool": "tools", "base": "bases", "ext": "external-kinematics"}


def _show(slot: dict, etag: str | None) -> str:
    if "root" in slot:  # an external kinematic: its root frame and axes
        p = slot["root"]
        label = f"ext {slot['number']} {slot['name']!r} ({slot['kind']}: {','.join(slot['axes'])})"
    else:
        p = slot["pose"]
        label = f"{slot['table']} {slot['number']} {slot['name']!r} ({slot['kind']})"
    return (f"{label}  "
            f"x {p['x']:.3f} y {p['y']:.3f} z {p['z']:.3f} mm  a {p['a']:.3f} b {p['b']:.3f} "
            f"c {p['c']:.3f} deg  ETag {etag}")


def run_slot(args: argparse.Namespace) -> int:
    try:
        return _run_slot(args)
    except _BadArgument as err:
        print(f"pendant: {err}", file=sys.stderr)
        return 2


def _run_slot(args: argparse.Namespace) -> int:
    base = args.url or os.environ.get(URL_ENV) or DEFAULT_URL
    pose = _pose(args.pose) if args.pose is not None else None  # a mistake before any request
    url = f"{base.rstrip('/')}/controllers/{args.controller}/{PATHS[args.table]}/{args.number}"
    try:
        status, headers, slot = _call("GET", url)
    except (urllib.error.URLError, OSError) as err:
        print(f"pendant: --url: the service at {base} did not answer ({err})", file=sys.stderr)
        return 2
    if status != 200:
        print(f"pendant: {_refusal(status, slot)}", file=sys.stderr)
        return 2
    body: dict[str, Any] = {}
    if args.name is not None:
        body["name"] = args.name
    if args.kind is not None:
        body["kind"] = args.kind
    if args.pose is not None:
        body["root" if args.table == "ext" else "pose"] = pose
    one = {k: getattr(args, k) for k in "xyzabc" if getattr(args, k, None) is not None}
    if one:  # PUT merges (JSON Merge Patch): the other components stay as stored
        if args.table == "ext" or args.pose is not None:
            print("pendant: --x .. --c: give them instead of --pose, for a tool or base",
                  file=sys.stderr)
            return 2
        body["pose"] = one
    if not body:
        print(_show(slot, headers.get("ETag")))
        return 0
    etag = args.etag or headers.get("ETag")
    status, headers, answer = _call("PUT", url, body, {"If-Match": etag})
    if status == 412:
        print(f"pendant: not written: {args.table} {args.number} changed since it was read "
              f"(If-Match {etag}). It holds now:\n  {_show(answer['current'], headers.get('ETag'))}",
              file=sys.stderr)
        return EXIT_STALE
    if status != 200:
        print(f"pendant: {_refusal(status, answer)}", file=sys.stderr)
        return 2
    print(_show(answer, headers.get("ETag")))
    return 0


def add_slot_command(subparsers: Any) -> None:
    """Register ``slot`` on the ``pendant`` command's subparsers."""
    s = subparsers.add_parser("slot", help="read or edit a tool/base slot or an external "
                                           "kinematic of a running service "
                                           "(sends If-Match: never a blind overwrite)")
    s.add_argument("table", choices=list(PATHS), help="tool, base or ext (EX_KIN 1..6)")
    s.add_argument("number", type=int)
    s.add_argument("--url", "--service", dest="url", metavar="URL",
                   help=f"the service (default: ${URL_ENV}, else {DEFAULT_URL}); its token in "
                        "$PENDANT_TOKEN (pendant tokens create NAME)")
    s.add_argument("--controller", default="1", help="controller id (1 = cell-1)")
    s.add_argument("--name")
    s.add_argument("--kind", choices=["tool", "workpiece", "base", "fixed_tool", "turntable",
                                      "positioner", "linear_unit", "none"])
    s.add_argument("--pose", help="x,y,z,a,b,c (mm, deg); ext: its root frame")
    for k, unit in zip("xyzabc", ("mm",) * 3 + ("deg",) * 3):
        s.add_argument(f"--{k}", type=float, help=f"{k} alone ({unit}); the others stay")
    s.add_argument("--etag", help='If-Match to send (an ETag you read earlier, e.g. \'"4"\'); '
                                  "default: the one read just now")
    s.set_defaults(func=run_slot)
