"""Errors as 422/404/409 (and the framework's 404/405) shaped like pydantic's: ``{"detail": [{"loc": [...], "msg": ...}]}``.

A solver's :class:`CalibrationError` names its field (``("flange_poses", 3)``); here it
becomes ``{"loc": ["body", "flange_poses", 3], "msg": reason, "type": "calibration"}``. No
route answers with a stack trace: anything unexpected is a 500 with a plain message.
"""

from __future__ import annotations

import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException

from db.crud import NotFound, StateConflict
from solvers.errors import CalibrationError, KinematicsError

log = logging.getLogger("pendant")


def detail(loc: tuple[str | int, ...], msg: str, kind: str) -> dict:
    return {"detail": [{"loc": list(loc), "msg": msg, "type": kind}]}


def body_loc(loc: tuple[str | int, ...]) -> tuple[str | int, ...]:
    return loc if loc[:1] in (("body",), ("path",), ("query",)) else ("body", *loc)


def install(app: FastAPI) -> None:
    """Register the handlers on ``app``."""

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
            msg = f"{request.method} is not a method of {request.url.path}"
            kind = "method_not_allowed"
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

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        log.exception("unexpected error on %s %s", request.method, request.url.path)
        return JSONResponse(status_code=500, content=detail(
            (), f"internal error ({type(exc).__name__}); the request changed nothing it had not "
                "committed; see the service log", "internal"))
