"""The RWS face: ABB Robot Web Services 1.0 (RobotWare 6) for one ABB-kind controller.

``pendant serve --rws-port 8610 [--rws-controller NAME]`` serves it beside REST (docs/rws.md).
One port serves one controller, as one RobotWare controller answers on its own address: RWS
paths name no controller, so a client's base URL chooses it.

Resources (``?json=1`` answers as RWS shapes them: ``_embedded._state[...]``; errors as
``_embedded.status`` with a code and a message):

- ``GET|POST /rw/rapid/symbol/data/RAPID/T_ROB1[/<module>]/<name>[?action=set]`` (value=)
- ``POST /rw/rapid/symbols?action=search-symbols``
- ``GET /rw/motionsystem/mechunits/ROB_1/jointtarget`` and ``.../robtarget?tool=&wobj=&coordinate=``
- ``GET /rw/panel/ctrlstate``, ``/rw/panel/opmode``, ``/rw/panel/speedratio``,
  ``/rw/rapid/execution``, ``/rw/rapid/tasks``
- ``GET|PUT /fileservice/$HOME/<module>.mod``: the export; a PUT is an import
- ``POST /subscription`` and the WebSocket ``/poll/<n>`` (subprotocol ``robapi2_subscription``)
  for PERS values.

Every request carries HTTP Digest credentials (:mod:`server.rws.digest`); what it may do is
its user's role, checked by :mod:`server.rws.ops` against REST's permission table.
"""

from __future__ import annotations

import asyncio
import html
import logging
import secrets
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qs, urlparse

import numpy as np
from pydantic import ValidationError
from sqlalchemy.orm import Session, sessionmaker
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import JSONResponse, PlainTextResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.types import ASGIApp
from starlette.websockets import WebSocket, WebSocketDisconnect

from db import crud
from server.auth.web import SiteGuard
from server.formats import abb
from server.rws import digest, ops, rapid
from server.service.transaction import retry_reason
from server.api.schemas import EntryIn
from solvers.errors import CalibrationError
from solvers.frames import abb_from_matrix, invert

log = logging.getLogger("pendant.rws")
MAX_BODY = 64 * 1024  # bytes of a form or a file a client may send
POLL_S = 0.2  # how often a subscription looks for changed values
SESSION_IDLE_S = 30 * 60  # an ABBCX login unused this long is forgotten (pendant's choice)
SESSIONS_MAX = 10_000  # ABBCX logins kept at once; the least recently used goes first
LOGINS_PER_USER = 64  # ABBCX logins of one user; past it, that user's least recently used goes
SUB_OPEN_WITHIN_S = 60.0  # a subscription whose WebSocket was not opened by then is dropped
SUBS_PER_USER = 64  # subscriptions a user holds at once (opened or waiting to be)
EXTAX_NONE = "9E+09"  # RAPID's "no external axis"
HOME = "$HOME"

# RWS status codes (RobotWare's HRESULT-style numbers where pendant knows them)
E_NOT_FOUND = -1073442805  # "symbol not found"
E_VALUE = -1073442773  # "invalid value / wrong type"
E_FORBIDDEN = -1073445859  # "not allowed for the user's grants"
E_AUTH = -1073445864  # "not authorized"
E_STALE = -1073445870  # "the data changed meanwhile"
E_NOT_OFFERED = -1073445877  # "resource or action not supported"
E_LARGE = -1073445876  # "request too large"
E_BUSY = -1073445863  # "the database cannot answer now: retry" (pendant's: a 503)


class RwsError(Exception):
    def __init__(self, http: int, code: int, msg: str):
        super().__init__(msg)
        self.http, self.code, self.msg = http, code, msg


@dataclass
class Subscription:
    """A ``POST /subscription``'s symbols, for its owner's WebSocket ``/poll/<n>``."""

    owner: str
    paths: list[str]
    made: float = field(default_factory=time.monotonic)
    opened: bool = False


@dataclass
class RwsFace:
    """The face's settings and the subscriptions it holds."""

    make_session: sessionmaker[Session]
    controller: str | int | None = None  # name or id; None: the lowest-id ABB controller
    auth: bool = True
    seen: digest.Seen = field(default_factory=digest.Seen)
    # ABBCX cookie -> (user, when last used), least recently used first
    sessions: OrderedDict[str, tuple[str, float]] = field(default_factory=OrderedDict)
    # user -> that user's ABBCX cookies, least recently used first
    logins: dict[str, OrderedDict[str, None]] = field(default_factory=dict)
    subscriptions: dict[int, Subscription] = field(default_factory=dict)
    next_sub: int = 1

    def controller_id(self) -> int:
        return ops.pinned(self, "abb")

    def login(self, cookie: str | None, user: str) -> str | None:
        """The ABBCX login ``cookie`` of ``user`` marked used; a new cookie to set when it is
        not that user's live login (None: keep it)."""
        now = time.monotonic()
        if cookie is not None and self.session_user(cookie, now) == user:
            self.sessions[cookie] = (user, now)
            self.sessions.move_to_end(cookie)
            self.logins[user].move_to_end(cookie)
            return None
        cookie = secrets.token_urlsafe(24)
        self.sessions[cookie] = (user, now)
        mine = self.logins.setdefault(user, OrderedDict())
        mine[cookie] = None
        # a client that sends no cookie back (curl, a script) makes a login per request: one
        # user's requests pushed every other user's logins out of SESSIONS_MAX
        while len(mine) > LOGINS_PER_USER:
            self.forget(next(iter(mine)))
        while len(self.sessions) > SESSIONS_MAX:
            self.forget(next(iter(self.sessions)))
        return cookie

    def forget(self, cookie: str) -> None:
        """The ABBCX login ``cookie`` ended (logout, idle, room for others)."""
        found = self.sessions.pop(cookie, None)
        if found is not None:
            mine = self.logins.get(found[0], {})
            mine.pop(cookie, None)
            if not mine:
                self.logins.pop(found[0], None)

    def session_user(self, cookie: str, now: float | None = None) -> str | None:
        """The user of a live ABBCX login; a login unused for :data:`SESSION_IDLE_S` is
        forgotten (a cookie copied off a PC does not open subscriptions for ever)."""
        found = self.sessions.get(cookie)
        if found is None:
            return None
        if (now if now is not None else time.monotonic()) - found[1] > SESSION_IDLE_S:
            self.forget(cookie)
            return None
        return found[0]

    def add_subscription(self, owner: str, paths: list[str]) -> int:
        """A new subscription's number. Subscriptions whose socket was not opened within
        :data:`SUB_OPEN_WITHIN_S` are dropped first; a user holds at most
        :data:`SUBS_PER_USER` (a client that subscribes and never opens one filled memory)."""
        now = time.monotonic()
        for n in [n for n, sub in self.subscriptions.items()
                  if not sub.opened and now - sub.made > SUB_OPEN_WITHIN_S]:
            del self.subscriptions[n]
        held = sum(1 for sub in self.subscriptions.values() if sub.owner == owner)
        if held >= SUBS_PER_USER:
            raise RwsError(429, E_NOT_OFFERED, f"{owner} holds {held} subscriptions, at most "
                           f"{SUBS_PER_USER}: close one (or open its socket within "
                           f"{SUB_OPEN_WITHIN_S:g} s of subscribing)")
        n = self.next_sub
        self.next_sub += 1
        self.subscriptions[n] = Subscription(owner, paths)
        return n


# ----------------------------------------------------------------------------- answers

def _wants_json(request: Request) -> bool:
    return request.query_params.get("json") == "1"


def _xhtml(states: list[dict[str, Any]], base: str) -> str:
    items = []
    for s in states:
        spans = "".join(f'<span class="{html.escape(k)}">{html.escape(str(v))}</span>'
                        for k, v in s.items() if not k.startswith("_"))
        items.append(f'<li class="{html.escape(s.get("_type", ""))}" '
                     f'title="{html.escape(s.get("_title", ""))}">{spans}</li>')
    return ('<?xml version="1.0" encoding="utf-8"?><html xmlns="http://www.w3.org/1999/xhtml">'
            f'<head><base href="{html.escape(base)}"/></head><body><div class="state">'
            f'<ul>{"".join(items)}</ul></div></body></html>')


def answer(request: Request, states: list[dict[str, Any]], status: int = 200) -> Response:
    base = str(request.base_url).rstrip("/") + request.url.path.rsplit("/", 1)[0] + "/"
    if _wants_json(request):
        return JSONResponse({"_links": {"base": {"href": base}},
                             "_embedded": {"_state": states}}, status_code=status)
    return Response(_xhtml(states, base), status_code=status,
                    media_type="application/xhtml+xml")


def error(request: Request, err: RwsError, headers: dict[str, str] | None = None) -> Response:
    base = str(request.base_url)
    if _wants_json(request) or err.http != 401:
        body = {"_links": {"base": {"href": base}},
                "_embedded": {"_state": [], "status": {"code": err.code, "msg": err.msg}}}
        return JSONResponse(body, status_code=err.http, headers=headers)
    return PlainTextResponse(err.msg, status_code=err.http, headers=headers)


# ------------------------------------------------------------------------------- auth

def _client(request: Request | WebSocket) -> str | None:
    return request.client.host if request.client else None


def _uri(scope: dict[str, Any]) -> str:
    path = scope.get("raw_path", b"").decode("latin-1") or scope["path"]
    q = scope.get("query_string", b"").decode("latin-1")
    return path + ("?" + q if q and "?" not in path else "")


async def authenticate(face: RwsFace, request: Request | WebSocket,
                       method: str) -> ops.Caller:
    """The caller of a request with valid Digest credentials; RwsError(401) otherwise."""
    if not face.auth:
        return ops.no_auth_caller("rws", _client(request))
    header = request.headers.get("authorization")
    params = digest.parse(header) if header else None
    if params is None:
        raise RwsError(401, E_AUTH, "HTTP Digest credentials required (realm validusers)")
    uri = _uri(request.scope)
    parsed = urlparse(uri)  # how requests signs a path with ';' parameters: without them
    signed_as = parsed.path + ("?" + parsed.query if parsed.query else "")
    if params.get("uri") not in (uri, signed_as):
        raise RwsError(401, E_AUTH, "the Digest uri is not this request's")
    verdict = await run_in_threadpool(
        digest.verify, params, method,
        lambda name: ops.rws_ha1(face.make_session, name), face.seen)
    if verdict.user is None:
        raise RwsError(401, E_AUTH, verdict.reason) if not verdict.stale else \
            _Stale(verdict.reason)
    who = await run_in_threadpool(ops.caller, face.make_session, verdict.user, "rws",
                                  _client(request))
    if who is None:
        raise RwsError(401, E_AUTH, "the user is revoked")
    return who


class _Stale(RwsError):
    def __init__(self, msg: str):
        super().__init__(401, E_AUTH, msg)


def guarded(face: RwsFace, handler):
    """A route handler with Digest auth, RWS errors and the session cookie."""
    async def endpoint(request: Request) -> Response:
        try:
            length = int(request.headers.get("content-length") or 0)
            if length > MAX_BODY:
                raise RwsError(413, E_LARGE, f"the body has {length} bytes; at most {MAX_BODY}")
            who = await authenticate(face, request, request.method)
            response = await handler(face, request, who)
        except RwsError as err:
            headers = None
            if err.http == 401:
                headers = {"WWW-Authenticate": digest.challenge(isinstance(err, _Stale))}
            return error(request, err, headers)
        except Exception as err:  # the database busy or gone: REST's 503, in RWS's shape
            why = retry_reason(err)
            log.warning("rws: %s %s: %s", request.method, request.url.path, why)
            return error(request, RwsError(503, E_BUSY, why), {"Retry-After": "1"})
        cookie = None if handler is logout else face.login(request.cookies.get("ABBCX"), who.name)
        if cookie is not None:
            response.set_cookie("ABBCX", cookie, httponly=True, samesite="strict",
                                max_age=SESSION_IDLE_S)
        return response
    return endpoint


async def call(fn, *args: Any, **kw: Any) -> Any:
    """An ops call in a thread, its exceptions as RWS errors."""
    try:
        return await run_in_threadpool(fn, *args, **kw)
    except ops.Refused as err:
        raise RwsError(403, E_FORBIDDEN, str(err)) from None
    except ops.Stale as err:
        raise RwsError(409, E_STALE, str(err)) from None
    except crud.NotFound as err:
        raise RwsError(404, E_NOT_FOUND, str(err)) from None
    except ValidationError as err:  # the API's own bounds (EntryIn)
        e = err.errors()[0]
        raise RwsError(400, E_VALUE, f"value.{'.'.join(str(x) for x in e['loc'])}: "
                       f"{e['msg']}") from None
    except CalibrationError as err:  # FormatError too: the field and the reason
        loc = ".".join(str(x) for x in err.loc)
        raise RwsError(400, E_VALUE, f"{loc}: {err.reason}") from None


async def body_of(request: Request, what: str = "the body") -> bytes:
    """The request's body, read up to :data:`MAX_BODY` bytes: a longer one is refused (413)
    as soon as it is seen, a chunked one too, never read whole into memory first."""
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > MAX_BODY:
            raise RwsError(413, E_LARGE, f"{what} has more than {MAX_BODY} bytes")
        chunks.append(chunk)
    return b"".join(chunks)


async def form_values(request: Request) -> dict[str, list[str]]:
    """Every value of each field of the request's form, read once."""
    body = await body_of(request)
    try:
        return parse_qs(body.decode("utf-8"), keep_blank_values=True, strict_parsing=False)
    except UnicodeDecodeError:
        raise RwsError(400, E_VALUE, "the form is not UTF-8") from None


async def form(request: Request) -> dict[str, str]:
    """The request's form, the last value of each field."""
    return {k: v[-1] for k, v in (await form_values(request)).items()}


# ----------------------------------------------------------------------------- symbols

def _symbols(face: RwsFace, who: ops.Caller, for_write: bool = False) -> list[rapid.Symbol]:
    """The symbols; ``for_write``: looked up by a set, which needs no read permission (REST's
    PUT of a slot needs frames:commit only)."""
    cid = face.controller_id()
    text = ops.export(face.make_session, who, cid, "abb", for_write=for_write)
    all_slots = ops.slots(face.make_session, who, cid, for_write=for_write)
    numbers: dict[str, list[int]] = {}
    for s in all_slots:
        numbers.setdefault(s.table, []).append(s.number)
    return rapid.symbols(text, numbers, {(s.table, s.number) for s in all_slots if s.used})


async def symbols_of(face: RwsFace, who: ops.Caller) -> list[rapid.Symbol]:
    return await call(_symbols, face, who)


def _state_of(sym: rapid.Symbol) -> dict[str, Any]:
    return {"_type": "rap-data", "_title": sym.url, "value": sym.value}


async def symbol_data(face: RwsFace, request: Request, who: ops.Caller) -> Response:
    path = request.path_params["path"]
    writer = request.method == "POST" and any(p in who.permissions
                                              for p in ops.EDIT_SLOT.values())
    syms = await call(_symbols, face, who, writer)
    try:
        sym = rapid.find(syms, path)
    except LookupError as err:
        raise RwsError(400 if request.method == "POST" else 404, E_NOT_FOUND, str(err)) from None
    if request.method == "GET":
        return answer(request, [_state_of(sym)])
    action = request.query_params.get("action")
    if action != "set":
        raise RwsError(400, E_NOT_OFFERED, f"action={action!r}: pendant offers action=set")
    fields = await form(request)
    if "value" not in fields:
        raise RwsError(400, E_VALUE, "value: missing (form field value=<RAPID literal>)")
    await call(_set_symbol, face, who, sym, fields["value"])
    return Response(status_code=204)


def _set_symbol(face: RwsFace, who: ops.Caller, sym: rapid.Symbol, value: str) -> None:
    if sym.table is None or sym.number is None:
        raise CalibrationError(("symbol",), f"{sym.name} is no slot's data; pendant writes "
                               "tooldata, wobjdata and the loaddata <wobj>_load of a slot")
    parsed = rapid.parse_value(sym, value)
    cid = face.controller_id()
    if sym.dtype == "loaddata":  # the load of a robot-held work object
        if parsed is None:
            body, clear = EntryIn(), True
        else:
            ld = parsed
            body, clear = EntryIn(load={  # type: ignore[arg-type]
                "mass_kg": ld.mass_kg, "com_mm": list(ld.com_mm),
                "inertia_kgm2": list(ld.inertia_kgm2),
                "inertia_axes_deg": list(ld.inertia_axes_deg)}), False
    else:
        rapid.kind_allowed(sym, parsed.kind)  # type: ignore[attr-defined]
        # an unnamed slot's symbol is named after its kind (wobj6, a coordinated cwobj6): one
        # whose kind the set changes keeps the name the client wrote it under
        name = None
        if parsed.kind != sym.kind:  # type: ignore[attr-defined]
            now = ops.slot(face.make_session, who, cid, sym.table, sym.number, for_write=True)
            name = sym.name if now.entry is None or not now.entry.name else None
        body, clear = ops.entry_body(parsed, name)  # type: ignore[arg-type]
        clear = clear and sym.dtype == "tooldata"  # a wobjdata's load is its own symbol
    ops.commit_slot(face.make_session, who, cid, sym.table, sym.number, body, clear_load=clear)


async def search_symbols(face: RwsFace, request: Request, who: ops.Caller) -> Response:
    if request.query_params.get("action") != "search-symbols":
        raise RwsError(400, E_NOT_OFFERED, "pendant offers action=search-symbols")
    fields = await form(request)
    block = fields.get("blockurl", "RAPID").strip("/")
    vartyp = fields.get("vartyp", "any").lower()
    symtyp = fields.get("symtyp", "per").lower()
    syms = await symbols_of(face, who)
    out = []
    for s in syms:
        if not (f"RAPID/{rapid.TASK}/{s.module}".upper().startswith(block.upper())):
            continue
        if vartyp not in ("any", s.dtype) or symtyp not in ("per", "any", "dat"):
            continue
        out.append({"_type": "rap-sympropvar-li", "_title": s.url, "name": s.name,
                    "symburl": s.url, "symtyp": "per", "named": "true", "dattyp": s.dtype,
                    "ndim": "0", "dim": "", "local": "false", "rdonly": "false",
                    "taskpers": "false", "typurl": f"RAPID/{s.dtype}"})
    return answer(request, out)


# ----------------------------------------------------------------------------- motion

def _mechunit(request: Request) -> None:
    unit = request.path_params["unit"]
    if unit.upper() != "ROB_1":
        raise RwsError(404, E_NOT_FOUND, f"no mechanical unit {unit!r}; pendant has ROB_1")


def _extax(state: ops.RobotState) -> list[str]:
    ext = state.external_axes or {}
    return [f"{float(ext[k]):.6g}" if k in ext else EXTAX_NONE
            for k in ("E1", "E2", "E3", "E4", "E5", "E6")]


async def jointtarget(face: RwsFace, request: Request, who: ops.Caller) -> Response:
    _mechunit(request)
    state = await call(ops.robot, face.make_session, who, await call(face.controller_id))
    q = list(state.joints_deg) + [EXTAX_NONE] * (6 - len(state.joints_deg))
    s: dict[str, Any] = {"_type": "ms-jointtarget", "_title": "ROB_1"}
    s.update({f"rax_{i + 1}": (f"{v:.6f}" if isinstance(v, float) else v)
              for i, v in enumerate(q[:6])})
    s.update({f"eax_{k}": v for k, v in zip("abcdef", _extax(state))})
    return answer(request, [s])


def _frame_of(syms: list[rapid.Symbol], name: str, dtype: str, slots: dict) -> np.ndarray:
    """T of the tool (T_flange_tcp) or work object (T_world_wobj) symbol ``name``."""
    if name.lower() in ("tool0", "wobj0"):
        return np.eye(4)
    hit = [s for s in syms if s.name.upper() == name.upper() and s.dtype == dtype]
    if not hit:
        raise RwsError(400, E_NOT_FOUND, f"{'tool' if dtype == 'tooldata' else 'wobj'}: "
                       f"no {dtype} {name!r}")
    s = hit[0]
    if dtype == "tooldata" and s.kind != "tool":
        raise RwsError(400, E_VALUE, f"tool: {name} is a stationary tool (robhold FALSE); "
                       "pendant gives robtargets of robot-held tools")
    if dtype == "wobjdata" and s.kind == "workpiece":
        raise RwsError(400, E_VALUE, f"wobj: {name} is held by the robot (robhold TRUE); "
                       "pendant gives robtargets in fixed work objects")
    return ops.frame_matrix(slots.get((s.table, s.number)))


def _robtarget(face: RwsFace, who: ops.Caller, tool: str, wobj: str, coordinate: str) -> dict:
    cid = face.controller_id()
    syms = _symbols(face, who)
    slots = {(s.table, s.number): s.entry for s in ops.slots(face.make_session, who, cid)}
    T_flange_tcp = _frame_of(syms, tool, "tooldata", slots)
    T_world_wobj = _frame_of(syms, wobj, "wobjdata", slots)
    state = ops.robot(face.make_session, who, cid)
    T_world_tcp = ops.tcp_in(face.make_session, who, cid, T_flange_tcp)
    c = coordinate.lower()
    if c in ("base", "world"):  # pendant's world is the robot base
        T = T_world_tcp
    elif c == "wobj":
        T = invert(T_world_wobj) @ T_world_tcp
    else:
        raise RwsError(400, E_VALUE, f"coordinate: {coordinate!r}; pendant gives Base, World "
                       "and Wobj")
    pos, q = abb_from_matrix(T)
    joints = list(state.joints_deg) + [0.0] * 6
    cf = [int(np.floor(joints[i] / 90.0)) for i in (0, 3, 5)]
    s: dict[str, Any] = {"_type": "ms-robtargets", "_title": "ROB_1"}
    s.update({k: f"{float(v):.6f}" for k, v in zip("xyz", pos)})
    s.update({f"q{i + 1}": f"{float(v):.9f}" for i, v in enumerate(q)})
    s.update({"cf1": str(cf[0]), "cf4": str(cf[1]), "cf6": str(cf[2]), "cfx": "0"})
    s.update({f"eax{k}": v for k, v in zip("abcdef", _extax(state))})
    return s


async def robtarget(face: RwsFace, request: Request, who: ops.Caller) -> Response:
    _mechunit(request)
    p = request.query_params
    s = await call(_robtarget, face, who, p.get("tool", "tool0"), p.get("wobj", "wobj0"),
                   p.get("coordinate", "Base"))
    return answer(request, [s])


# ------------------------------------------------------------------------ panel, rapid

STATES: dict[str, dict[str, Any]] = {
    "/rw/panel/ctrlstate": {"_type": "pnl-ctrlstate", "_title": "ctrlstate",
                            "ctrlstate": "motoron"},
    "/rw/panel/opmode": {"_type": "pnl-opmode", "_title": "opmode", "opmode": "MANR"},
    "/rw/panel/speedratio": {"_type": "pnl-speedratio", "_title": "speedratio",
                             "speedratio": "100"},
    "/rw/rapid/execution": {"_type": "rap-execution", "_title": "execution",
                            "ctrlexecstate": "stopped", "cycle": "once"},
}
TASKS = [{"_type": "rap-task-li", "_title": rapid.TASK, "name": rapid.TASK, "type": "normal",
          "taskstate": "linked", "excstate": "ready", "active": "On", "motiontask": "TRUE"}]


async def panel(face: RwsFace, request: Request, who: ops.Caller) -> Response:
    if request.method != "GET" or request.query_params.get("action"):
        raise RwsError(400, E_NOT_OFFERED, f"{request.url.path}: pendant's emulated controller "
                       "is read here, not commanded (the pendant's REST API jogs it)")
    await call(ops.robot, face.make_session, who, await call(face.controller_id))  # may read?
    path = request.url.path.rstrip("/")
    return answer(request, TASKS if path == "/rw/rapid/tasks" else [STATES[path]])


async def logout(face: RwsFace, request: Request, who: ops.Caller) -> Response:
    face.forget(request.cookies.get("ABBCX", ""))
    response = Response(status_code=204)
    response.delete_cookie("ABBCX")  # and no new login is set (guarded skips it here)
    return response


# ------------------------------------------------------------------------- file service

def _module_file(face: RwsFace, who: ops.Caller) -> tuple[str, str]:
    text = ops.export(face.make_session, who, face.controller_id(), "abb")
    m = abb.MODULE_LINE.search(text)
    return (m.group(1) if m else rapid.DEFAULT_MODULE) + ".mod", text


async def fileservice(face: RwsFace, request: Request, who: ops.Caller) -> Response:
    path = request.path_params.get("path", "").strip("/")
    home = [HOME, "HOME:", "HOME"]
    folder, _, file = path.rpartition("/")
    if request.method == "PUT" and folder in home and file.lower().endswith(".mod"):
        # an import: data:import, as POST .../import (the module is not read first)
        body = await body_of(request, "the file")
        try:
            new = body.decode("utf-8")
        except UnicodeDecodeError:
            raise RwsError(400, E_VALUE, "file: not UTF-8 text") from None
        await call(ops.import_file, face.make_session, who, await call(face.controller_id),
                   "abb", new)
        return Response(status_code=201)
    name, text = await call(_module_file, face, who)
    if path in home or path == "":
        listing = [{"_type": "fs-file", "_title": name, "fs-size": str(len(text.encode())),
                    "fs-readonly": "false"}]
        return answer(request, listing)
    if folder not in home or not file.lower().endswith(".mod"):
        raise RwsError(404, E_NOT_FOUND, f"no file {path!r}; pendant serves {HOME}/{name}")
    if request.method == "GET":
        if file.lower() != name.lower():
            raise RwsError(404, E_NOT_FOUND, f"no file {path!r}; pendant serves {HOME}/{name}")
        return Response(text.encode("utf-8"), media_type="text/plain; charset=utf-8")
    raise RwsError(400, E_NOT_OFFERED, f"{request.method} {path}: pendant reads (GET) and "
                   "imports (PUT) the module")


# ------------------------------------------------------------------------ subscriptions

async def subscribe(face: RwsFace, request: Request, who: ops.Caller) -> Response:
    values = await form_values(request)
    fields = {k: v[-1] for k, v in values.items()}
    resources = [r for r in values.get("resources", []) if r]
    paths = []
    syms = await symbols_of(face, who) if resources else []  # once, not once per resource
    for r in resources:
        res = fields.get(r, "")
        prefix = "/rw/rapid/symbol/data/RAPID/"
        if not (res.startswith(prefix) and res.endswith(";value")):
            raise RwsError(400, E_NOT_OFFERED, f"resource {r} = {res!r}: pendant subscribes "
                           "PERS values (/rw/rapid/symbol/data/RAPID/T_ROB1/<name>;value)")
        sym_path = res[len(prefix):-len(";value")]
        try:
            rapid.find(syms, sym_path)
        except LookupError as err:
            raise RwsError(400, E_NOT_FOUND, str(err)) from None
        paths.append(sym_path)
    if not paths:
        raise RwsError(400, E_VALUE, "resources: none given")
    sub_id = face.add_subscription(who.name, paths)
    ws = str(request.base_url).replace("http:", "ws:").rstrip("/") + f"/poll/{sub_id}"
    body = ('<?xml version="1.0" encoding="utf-8"?><html xmlns="http://www.w3.org/1999/xhtml">'
            f'<head><title>poll</title></head><body><div class="state"><a href="{ws}" '
            f'rel="self">poll</a></div></body></html>')
    return Response(body, status_code=201, media_type="application/xhtml+xml",
                    headers={"Location": ws})


def _event(sym: rapid.Symbol) -> str:
    url = f"/rw/rapid/symbol/data/{sym.url};value"
    return ('<?xml version="1.0" encoding="utf-8"?><html xmlns="http://www.w3.org/1999/xhtml">'
            '<head><base href="/"/></head><body><div class="state"><ul>'
            f'<li class="rap-data" title="{html.escape(sym.url)}"><a href="{url}" rel="self"/>'
            f'<span class="value">{html.escape(sym.value)}</span></li></ul></div></body></html>')


async def poll(face: RwsFace, ws: WebSocket) -> None:
    digits = ws.path_params["sub"]  # Starlette's {sub:int} refused 5000 digits with a 500
    sub_id = int(digits) if digits.isascii() and digits.isdigit() and len(digits) <= 9 else 0
    sub = face.subscriptions.get(sub_id)
    try:
        who = await _ws_caller(face, ws)
    except RwsError:
        await ws.close(code=1008)
        return
    if sub is None or sub.owner != who.name or sub.opened:  # one socket per subscription
        await ws.close(code=1008)
        return
    sub.opened, paths = True, sub.paths
    await ws.accept(subprotocol="robapi2_subscription")
    last: dict[str, str] = {}
    try:
        first = True
        while True:
            try:  # the user as the database has them now: a revocation ends the socket
                now = who if not face.auth else await run_in_threadpool(
                    ops.caller, face.make_session, who.name, "rws", who.client)
                if now is None:
                    raise ops.Refused("frames:read", who)
                syms = await run_in_threadpool(_symbols, face, now)
            except (ops.Refused, crud.NotFound):
                await ws.close(code=1008)
                return
            for p in paths:
                try:
                    sym = rapid.find(syms, p)
                except LookupError:
                    continue
                if not first and last.get(p) != sym.value:
                    await ws.send_text(_event(sym))
                last[p] = sym.value
            first = False
            # the next look in POLL_S, whatever the client sends meanwhile (each message ended
            # the wait early: a client sending frames fast made its socket look 37 times a
            # second); receiving notices its leaving, and ignores text and binary alike
            next_look = time.monotonic() + POLL_S
            while (left := next_look - time.monotonic()) > 0:
                try:
                    message = await asyncio.wait_for(ws.receive(), left)
                except TimeoutError:
                    break
                if message["type"] == "websocket.disconnect":
                    raise WebSocketDisconnect(message.get("code", 1000))
    except WebSocketDisconnect:
        pass
    finally:
        face.subscriptions.pop(sub_id, None)


async def _ws_caller(face: RwsFace, ws: WebSocket) -> ops.Caller:
    """A WebSocket's caller: its Digest header, else the ABBCX session cookie of its login."""
    if not face.auth:
        return ops.no_auth_caller("rws", _client(ws))
    try:
        return await authenticate(face, ws, "GET")
    except RwsError:
        name = face.session_user(ws.cookies.get("ABBCX", ""))
        who = None if name is None else await run_in_threadpool(
            ops.caller, face.make_session, name, "rws", _client(ws))
        if who is None:
            raise
        return who


def create_rws_app(face: RwsFace, allowed_hosts: tuple[str, ...] = ("*",)) -> ASGIApp:
    """The ASGI app of the face, behind the REST service's site guard
    (:class:`server.auth.web.SiteGuard`): a command from another site's page is refused
    (403: a browser that keeps Digest credentials for the robot's address would send them
    with any page's form), and so is a ``Host`` not in ``allowed_hosts`` (400: DNS
    rebinding), as on REST."""
    def r(path: str, handler, methods: list[str]) -> Route:
        return Route(path, guarded(face, handler), methods=methods)

    async def ws_endpoint(ws: WebSocket) -> None:
        await poll(face, ws)

    routes = [
        r("/rw/rapid/symbol/data/RAPID/{path:path}", symbol_data, ["GET", "POST"]),
        r("/rw/rapid/symbols", search_symbols, ["POST"]),
        r("/rw/motionsystem/mechunits/{unit}/jointtarget", jointtarget, ["GET"]),
        r("/rw/motionsystem/mechunits/{unit}/robtarget", robtarget, ["GET"]),
        *[r(p, panel, ["GET", "POST"]) for p in (*STATES, "/rw/rapid/tasks")],
        r("/fileservice/{path:path}", fileservice, ["GET", "PUT", "DELETE"]),
        r("/fileservice", fileservice, ["GET"]),
        r("/subscription", subscribe, ["POST"]),
        r("/logout", logout, ["GET"]),
        WebSocketRoute("/poll/{sub}", ws_endpoint),
    ]

    async def not_found(request: Request, exc: Exception) -> Response:
        status = getattr(exc, "status_code", 404)
        msg = (f"{request.method} {request.url.path}: not a resource pendant's RWS face serves "
               "(docs/rws.md)")
        return error(request, RwsError(status, E_NOT_OFFERED, msg))

    return SiteGuard(Starlette(routes=routes, exception_handlers={404: not_found,
                                                                  405: not_found}),
                     allowed_hosts)
