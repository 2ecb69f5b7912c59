"""The app-level dependency every route passes: who is asking, may they, and is it cross-site?

1. The route's permission comes from ``permissions.ROUTES`` by the matched path template
   (``request.scope["route"].path``); an undeclared route is refused to everyone.
2. The credential is a bearer token (``Authorization: Bearer pdt_...``, source ``api``) or the
   browser login's HttpOnly cookie (source ``pendant``). A cookie-authenticated command
   (any method but GET/HEAD/OPTIONS) also needs the login's CSRF token in ``X-CSRF-Token``
   (double submit: the page reads it from the ``pendant_csrf`` cookie, which another site's
   page cannot read). After the idle timeout a browser login acts as an Operator.
3. No credential: 401; a credential without the permission: 403 naming the permission.

The actor, the request id and the client address go into ``audit.CONTEXT`` for the audit hook.
"""

from __future__ import annotations

import asyncio
import hmac
import uuid
from datetime import timedelta
from typing import Any

from fastapi import HTTPException, Request
from sqlalchemy import update
from starlette.concurrency import run_in_threadpool

from db.auth_models import WebSession
from db.models import utcnow
from server.auth import audit, tokens
from server.auth.permissions import PERMISSIONS, PUBLIC, SIGNED_IN, required
from server.service import transaction

SESSION_COOKIE = "pendant_session"
CSRF_COOKIE = "pendant_csrf"
CSRF_HEADER = "x-csrf-token"
SAFE_METHODS = ("GET", "HEAD", "OPTIONS")
TOUCH_EVERY_S = 5.0  # a login's last command time is written at most this often


def _refuse(status: int, loc: tuple[str, ...], msg: str, kind: str) -> HTTPException:
    headers = {"WWW-Authenticate": 'Bearer realm="pendant"'} if status == 401 else None
    return HTTPException(status, detail={"loc": list(loc), "msg": msg, "type": kind},
                         headers=headers)


def _bearer_secret(header: str) -> str:
    scheme, _, secret = header.partition(" ")
    if scheme.lower() != "bearer" or not secret.strip():
        raise _refuse(401, ("header", "authorization"),
                      "must be 'Bearer <token>' (pendant tokens create)", "unauthorized")
    if tokens.is_certificate_secret(secret.strip()):  # a certificate's public fingerprint
        raise _refuse(401, ("header", "authorization"),
                      "unknown, expired or revoked token", "unauthorized")
    return secret.strip()


def _bearer_actor(request: Request, digest: str) -> tokens.Actor:
    """The actor of a bearer token not in the cache (read from the DB, in a thread)."""
    actor = tokens.verified_actor(request.app.state.sessionmaker, digest)
    if actor is None:
        raise _refuse(401, ("header", "authorization"),
                      "unknown, expired or revoked token", "unauthorized")
    return actor


def _cookie_actor(request: Request, cookie: str) -> tokens.Actor:
    """The actor of the browser login's cookie; raises 401 on an ended one, 403 on a command
    without the login's CSRF token."""
    settings = request.app.state.settings
    awake = None  # the login a command keeps awake (reads do not)
    with request.app.state.sessionmaker() as db:
        found_web = tokens.web_session(db, cookie)
        if found_web is None:
            raise _refuse(401, ("cookie", SESSION_COOKIE),
                          "the login has ended or expired; log in again", "unauthorized")
        ws, user = found_web
        actor = tokens.web_actor(db, ws, user, settings.idle_timeout_s)
        if request.method not in SAFE_METHODS:
            sent = request.headers.get(CSRF_HEADER, "")
            if not hmac.compare_digest(sent.encode(), ws.csrf_token.encode()):
                raise _refuse(403, ("header", CSRF_HEADER), "a command from the browser needs "
                              "the login's CSRF token (cross-site request refused)", "csrf")
            if not actor.idle and utcnow() - ws.last_seen_at > timedelta(seconds=TOUCH_EVERY_S):
                awake = ws.id
    if awake is not None:
        _keep_awake(request.app.state.sessionmaker, awake)
    return actor


def _keep_awake(maker: Any, web_session_id: int) -> None:
    """Note a browser login's command (its idle timeout starts again): a write of its own, in
    the writers' turn. Written in the reading transaction above, it failed at once on SQLite
    ("database is locked", a 503) whenever another writer committed between the read and it."""
    with transaction.writer_in_turn(maker) as db:
        db.execute(update(WebSession).where(WebSession.id == web_session_id)
                   .values(last_seen_at=utcnow()))
        db.commit()


_VERIFYING: dict[tuple[asyncio.AbstractEventLoop, str, int], asyncio.Task] = {}


def _verification(request: Request, digest: str) -> asyncio.Task:
    """The one verification of the token ``digest`` running in this event loop (a task of its
    own, which a request that leaves does not cancel): when its cache entry expires, the
    requests that carry the token at that moment (20, under ``wrk``) wait for one lookup
    instead of taking a thread and three queries each. A request that comes after the cache
    was emptied (a revocation here) never joins a verification that began before it."""
    loop = asyncio.get_running_loop()
    key = (loop, digest, tokens.CACHE.generation)
    task = _VERIFYING.get(key)
    if task is None:
        task = _VERIFYING[key] = loop.create_task(
            run_in_threadpool(_bearer_actor, request, digest))

        def done(t: asyncio.Task) -> None:
            _VERIFYING.pop(key, None)
            if not t.cancelled():
                t.exception()  # retrieved: the requests that waited raise it themselves

        task.add_done_callback(done)
    return task


async def _actor(request: Request) -> tokens.Actor | None:
    """The actor of the request's credential (None: no credential); raises 401 on a bad one.

    A bearer token verified in the last second comes from ``tokens.CACHE`` without a thread
    or a query (docs/security.md, "Credentials"); else from one verification shared by the
    requests that carry it meanwhile (:func:`_verification`)."""
    header = request.headers.get("authorization")
    if header is not None:
        digest = tokens.sha256(_bearer_secret(header))
        actor = tokens.CACHE.get(digest)
        return actor or await asyncio.shield(_verification(request, digest))
    cookie = request.cookies.get(SESSION_COOKIE)
    if cookie is None:
        return None
    return await run_in_threadpool(_cookie_actor, request, cookie)


async def authorize(request: Request) -> None:
    """Refuse the request unless its credential carries the route's permission."""
    route = request.scope.get("route")
    path = getattr(route, "path", None)
    need = required(request.method, path) if path else None
    if need is None:
        raise _refuse(403, ("path",), f"no permission is declared for {request.method} {path} "
                      "(server/auth/permissions.py)", "forbidden")
    client = request.client.host if request.client else None
    rid = getattr(request.state, "request_id", None) or uuid.uuid4().hex  # web.SiteGuard's
    if need == PUBLIC:
        audit.CONTEXT.set(audit.AuditContext(None, None, "api", rid, client))
        return
    settings = request.app.state.settings
    if not settings.auth:
        actor = tokens.Actor("no-auth", "Administrator", frozenset(PERMISSIONS), "api")
    else:
        actor = await _actor(request)
        if actor is None:
            raise _refuse(401, ("header", "authorization"), "log in: a bearer token "
                          "(pendant tokens create) or the pendant's login page", "unauthorized")
    request.state.actor = actor
    audit.CONTEXT.set(audit.AuditContext(actor.name, actor.role, actor.source, rid, client))
    if need != SIGNED_IN and not actor.can(need):
        raise _refuse(403, ("path",), f"needs permission {need}; {actor.name} acts as "
                      f"{actor.role}" + (" (idle: log in again)" if actor.idle else ""),
                      "forbidden")


def require(request: Request, permission: str) -> None:
    """A second permission a route needs for part of its input (a JSON backup, a restore)."""
    actor = getattr(request.state, "actor", None)
    if actor is not None and not actor.can(permission):
        raise _refuse(403, ("path",), f"needs permission {permission}; {actor.name} acts as "
                      f"{actor.role}", "forbidden")
