"""Errors as 422/404/409 (and the framework's 404/405) shaped like pydantic's: ``{"detail": [{"loc": [...], "msg": ...}]}``.

A solver's :class:`CalibrationError` names its field (``("flange_poses", 3)``); here it
becomes ``{"loc": ["body", "flange_poses", 3], "msg": reason, "type": "calibration"}``. No
route answers with a stack trace: anything unexpected is a 500 with a plain message.
"""

from __future__ import annotations

import logging
import re
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeout
from sqlalchemy.orm.exc import StaleDataError
from starlette.exceptions import HTTPException

from db.crud import NotFound, StateConflict
from server.api.preconditions import PreconditionFailed, PreconditionRequired, etag
from server.service.transaction import LOST, DatabaseBusy, unavailable
from solvers.errors import CalibrationError, KinematicsError

log = logging.getLogger("pendant")


def detail(loc: tuple[str | int, ...], msg: str, kind: str) -> dict:
    return {"detail": [{"loc": list(loc), "msg": msg, "type": kind}]}


def body_loc(loc: tuple[str | int, ...]) -> tuple[str | int, ...]:
    return loc if loc[:1] in (("body",), ("path",), ("query",)) else ("body", *loc)


S = "/controllers/{controller_id}/sessions/{session_id}"
# the operations that answer 409 when the state does not allow them (StateConflict)
CONFLICTS = {("post", "/controllers"), ("post", S + "/touch-up"),
             ("delete", S + "/points/{step}"), ("post", S + "/compute"), ("post", S + "/save"),
             ("post", S + "/discard"), ("post", S + "/run-cycle"),
             ("post", S + "/beam-recording"), ("post", "/users"),
             ("delete", "/users/{user_name}"), ("post", "/users/{user_name}/tokens")}
ERROR_SCHEMA = {"type": "object", "required": ["detail"], "properties": {"detail": {
    "type": "array", "items": {"type": "object", "required": ["loc", "msg", "type"],
                               "properties": {"loc": {"type": "array", "items": {}},
                                              "msg": {"type": "string"},
                                              "type": {"type": "string"}}}}}}
DOCUMENTED = {"401": "No credential, or an unknown, expired or revoked token",
              "403": "The role lacks the route's permission (or a cross-site command)",
              "404": "The path names something that does not exist",
              "409": "The state does not allow it"}


def allowed_methods(app: FastAPI, path: str) -> list[str]:
    """Every method some route of ``path`` has (the 405's ``Allow``), HEAD with GET."""
    methods: set[str] = set()
    for template, ops in app.openapi()["paths"].items():
        if re.fullmatch(re.sub(r"\\\{[^}]*\\\}", "[^/]+", re.escape(template)), path):
            methods |= {m.upper() for m in ops}
    if "GET" in methods:
        methods.add("HEAD")
    return sorted(methods)


def document_errors(app: FastAPI) -> None:
    """Add the 401/403 (by server/auth/permissions.py), 404 (a path parameter) and 409
    (``CONFLICTS``) answers to the OpenAPI of every operation that can give them."""
    from server.auth.permissions import PUBLIC, SIGNED_IN, required

    build = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is not None:
            return app.openapi_schema
        spec = build()
        spec.setdefault("components", {}).setdefault("schemas", {})["Error"] = ERROR_SCHEMA
        ref = {"content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}
        for path, ops in spec.get("paths", {}).items():
            for method, op in ops.items():
                need = required(method.upper(), path)
                codes = []
                if need != PUBLIC:
                    codes += ["401"] + ([] if need == SIGNED_IN else ["403"])
                if "{" in path:
                    codes.append("404")
                if (method, path) in CONFLICTS:
                    codes.append("409")
                for code in codes:
                    op.setdefault("responses", {}).setdefault(
                        code, {"description": DOCUMENTED[code], **ref})
        app.openapi_schema = spec
        return spec

    app.openapi = openapi  # type: ignore[method-assign]


def install(app: FastAPI) -> None:
    """Register the handlers on ``app``."""
    document_errors(app)

    @app.exception_handler(CalibrationError)
    async def _calibration(_: Request, exc: CalibrationError) -> JSONResponse:
        kind = "kinematics" if isinstance(exc, KinematicsError) else "calibration"
        return JSONResponse(status_code=422, content=detail(body_loc(exc.loc), exc.reason, kind))

    @app.exception_handler(RequestValidationError)
    async def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        # pydantic's own shape, without the echoed input (a NaN in it is not JSON)
        items = [{"loc": list(e.get("loc", ())), "msg": str(e.get("msg", "")),
                  "type": str(e.get("type", ""))} for e in exc.errors()]
        return JSONResponse(status_code=422, content={"detail": items})

    @app.exception_handler(HTTPException)
    async def _http(request: Request, exc: HTTPException) -> JSONResponse:
        # the framework's own refusals (a body that is not JSON text, an unknown route, a
        # method the route does not have) in the same shape as every other error
        if isinstance(exc.detail, dict) and "msg" in exc.detail:  # server.auth's 401/403
            return JSONResponse(status_code=exc.status_code, content={"detail": [exc.detail]},
                                headers=getattr(exc, "headers", None))
        status, msg, loc = exc.status_code, str(exc.detail), ()
        if status == 400 and "parsing the body" in msg:
            status, loc = 422, ("body",)
            msg = "is not JSON text the API can read (UTF-8 JSON expected)"
            kind = "json_invalid"
        elif status == 404:
            loc, msg = ("path",), f"no route {request.method} {request.url.path}"
            kind = "not_found"
        elif status == 405:
            allowed = allowed_methods(request.app, request.url.path)
            msg = (f"{request.method} is not a method of {request.url.path}; it has "
                   f"{', '.join(allowed)}")
            kind = "method_not_allowed"
            return JSONResponse(status_code=405, content=detail(loc, msg, kind),
                                headers={"Allow": ", ".join(allowed)})
        else:
            kind = "http"
        return JSONResponse(status_code=status, content=detail(loc, msg, kind),
                            headers=getattr(exc, "headers", None))

    @app.exception_handler(NotFound)
    async def _not_found(_: Request, exc: NotFound) -> JSONResponse:
        return JSONResponse(status_code=404,
                            content=detail(("path", *exc.loc), exc.reason, "not_found"))

    @app.exception_handler(StateConflict)
    async def _conflict(_: Request, exc: StateConflict) -> JSONResponse:
        return JSONResponse(status_code=409, content=detail(exc.loc, exc.reason, "conflict"))

    @app.exception_handler(PreconditionFailed)
    async def _stale(_: Request, exc: PreconditionFailed) -> JSONResponse:
        msg = (f"{exc.what} changed since you read it: If-Match {exc.sent} but its ETag is now "
               f"{etag(exc.version)}; nothing was written. Its current value is in 'current'")
        content = {**detail(("header", "If-Match"), msg, "precondition_failed"),
                   "current": exc.current}
        return JSONResponse(status_code=412, content=content, headers={"ETag": etag(exc.version)})

    @app.exception_handler(PreconditionRequired)
    async def _required(_: Request, exc: PreconditionRequired) -> JSONResponse:
        msg = (f"writing {exc.what} needs If-Match: GET it, then send its ETag (or * to "
               "overwrite whatever it holds)")
        return JSONResponse(status_code=428, content=detail(("header", "If-Match"), msg,
                                                            "precondition_required"))

    @app.exception_handler(StaleDataError)
    async def _lost_race(_: Request, exc: StaleDataError) -> JSONResponse:
        # a row's version changed under this write (cannot happen under the row lock, but a
        # version check that fails must never be a silent overwrite)
        return JSONResponse(status_code=409, content=detail(
            (), "the row changed while this request ran; nothing was written: read and retry",
            "conflict"))

    @app.exception_handler(DatabaseBusy)
    @app.exception_handler(OperationalError)
    @app.exception_handler(PoolTimeout)
    async def _unavailable(request: Request, exc: Exception) -> JSONResponse:
        why = unavailable(exc)
        if why is None:
            return await _unexpected(request, exc)
        if isinstance(exc, PoolTimeout):
            log.warning("every database connection of this process stayed busy: %s", exc)
        elif why == LOST:
            log.warning("the connection to the database was lost during %s %s: %s",
                        request.method, request.url.path, exc.orig)
            return JSONResponse(status_code=503, headers={"Retry-After": "1"}, content=detail(
                (), f"{why}, or repeat it with the same Idempotency-Key", "connection_lost"))
        elif isinstance(exc, OperationalError):
            log.warning("the database could not serve %s %s: %s", request.method,
                        request.url.path, str(exc.orig).strip().splitlines()[0] if exc.orig
                        else exc)
        return JSONResponse(status_code=503, headers={"Retry-After": "1"},
                            content=detail((), why, "busy"))

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error on %s %s", request.method, request.url.path)
        return JSONResponse(status_code=500, content=detail(
            (), f"internal error ({type(exc).__name__}); the request changed nothing it had not "
                "committed; see the service log", "internal"))
