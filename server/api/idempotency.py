"""``Idempotency-Key`` on POST commands (IETF httpapi draft "The Idempotency-Key HTTP Header
Field", draft-ietf-httpapi-idempotency-key-header).

- The first POST with a key runs; the key, a fingerprint of the request (SHA-256 of method,
  path, query and body) and, once sent, the response are stored for 24 h.
- The same key with the same request again: the stored response (status, body, ETag),
  whether the first came to this process or another.
- The same key with another request: **422** (the draft's answer to a reused key).
- The same key while the first is still running, or after a crash between the commit and
  storing its response: **409**.
- A refused request (4xx/5xx) stores nothing: its transaction, with the key, is rolled back,
  so retrying it runs it again. A 5xx whose transaction may have committed (the connection
  lost during the commit) leaves the key claimed but unanswered: a retry then gets the 409 of
  a command applied whose answer was lost, never the 5xx again.
- Keys belong to the user who sent them: the stored key is the SHA-256 of the user's name and
  the key, so another user's request with the same key runs as a request of its own and never
  gets the first user's answer.
- A route whose answer holds a secret (``POST /users/{user_name}/tokens``: the new token;
  ``POST /webhooks``: the signing secret) refuses the header (**400**): the store keeps answers for 24 h, and a secret is never stored.

The key is claimed inside the command's own transaction (:func:`claim`, called from
``server.api.deps``), so it exists exactly when the command's changes were committed.
"""

from __future__ import annotations

import hashlib
from datetime import timedelta
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse, Response
from sqlalchemy import delete, update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from db.models import IdempotencyKey, utcnow
from server.service import transaction

HEADER = "idempotency-key"
KEEP = timedelta(hours=24)
MAX_KEY = 255
STORED_HEADERS = ("content-type", "etag", "location")
SECRET_ROUTES = frozenset({("POST", "/users/{user_name}/tokens"),  # answers hold a secret
                           ("POST", "/webhooks")})


class IdempotencyError(Exception):
    def __init__(self, status: int, msg: str):
        super().__init__(msg)
        self.status, self.msg = status, msg


class Replay(Exception):
    """The stored response of an earlier request with this key and this fingerprint."""

    def __init__(self, row: IdempotencyKey):
        super().__init__(row.method)
        self.status, self.headers, self.body = row.status, dict(row.headers or {}), row.body


def _key(request: Request) -> str | None:
    if request.method != "POST":
        return None
    raw = request.headers.get(HEADER)
    if raw is None:
        return None
    key = raw.strip()
    if len(key) >= 2 and key[0] == key[-1] == '"':  # the draft's sf-string form
        key = key[1:-1]
    if not key or len(key) > MAX_KEY or not key.isprintable():
        raise IdempotencyError(400, f"Idempotency-Key must be 1..{MAX_KEY} printable "
                                    "characters (a UUID, say)")
    path = getattr(request.scope.get("route"), "path", None)
    if (request.method, path) in SECRET_ROUTES:
        raise IdempotencyError(400, f"{request.method} {path} answers with a secret, which is "
                                    "never stored: send it without Idempotency-Key")
    return key


def _stored_key(request: Request, key: str) -> str:
    """The key as stored: SHA-256 of the acting user's name and the key (keys are per user)."""
    actor = getattr(request.state, "actor", None)
    user = getattr(actor, "name", None) or ""
    return hashlib.sha256(f"{user}\0{key}".encode()).hexdigest()


def has_key(request: Request) -> bool:
    """Whether the request is a POST that sent an Idempotency-Key (valid or not)."""
    return request.method == "POST" and HEADER in request.headers


async def read_body(request: Request) -> None:
    """Read (and cache) the body before the threadpool needs it for the fingerprint."""
    if _key(request) is not None:
        await request.body()


def _fingerprint(request: Request) -> str:
    h = hashlib.sha256()
    for part in (request.method, request.url.path, request.url.query):
        h.update(part.encode() + b"\0")
    h.update(getattr(request, "_body", b""))
    return h.hexdigest()


def claim(db: Session, request: Request) -> None:
    """Claim the request's key in its transaction, or raise Replay / IdempotencyError."""
    key = _key(request)
    if key is None:
        return
    fp = _fingerprint(request)
    now = utcnow()
    stored = _stored_key(request, key)
    db.execute(delete(IdempotencyKey).where(IdempotencyKey.created_at < now - KEEP))
    row = db.get(IdempotencyKey, stored)
    if row is None:
        try:
            with db.begin_nested():
                db.add(IdempotencyKey(key=stored, fingerprint=fp, method=request.method,
                                      path=request.url.path[:512], created_at=now))
        except IntegrityError:  # another process claimed it first (PostgreSQL)
            row = db.get(IdempotencyKey, stored, populate_existing=True)
        if row is None:
            request.state.idempotency_key = stored
            return
    if row.fingerprint != fp:
        raise IdempotencyError(422, f"Idempotency-Key {key!r} was used for another request "
                                    f"({row.method} {row.path} with another body); use a new key")
    if row.status is None:
        raise IdempotencyError(409, f"the request with Idempotency-Key {key!r} is still being "
                                    "processed (or was applied and its answer lost); retry later "
                                    "or read the resource")
    raise Replay(row)


def _store(maker: Any, key: str, status: int, headers: dict[str, str], body: bytes) -> None:
    """Keep the answer of the request that claimed ``key``: a write of its own, after the
    answer was sent, in the writers' turn as every write."""
    with transaction.writer_in_turn(maker) as db:
        db.execute(update(IdempotencyKey).where(IdempotencyKey.key == key)
                   .values(status=status, headers=headers, body=body))
        db.commit()


class IdempotencyMiddleware:
    """Stores the response of a POST whose key :func:`claim` took (pure ASGI)."""

    def __init__(self, app: ASGIApp, fastapi_app: FastAPI):
        self.app, self.fastapi_app = app, fastapi_app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "POST" or not any(
                k == b"idempotency-key" for k, _ in scope["headers"]):
            await self.app(scope, receive, send)
            return
        state = scope.setdefault("state", {})
        start: dict[str, Any] = {}
        chunks: list[bytes] = []

        async def capture(message: Message) -> None:
            if message["type"] == "http.response.start":
                start.update(message)
            elif message["type"] == "http.response.body":
                chunks.append(message.get("body", b""))
            await send(message)

        await self.app(scope, receive, capture)
        key = state.get("idempotency_key")
        if key is None or not start or int(start["status"]) >= 500:
            # a 5xx is no answer to keep: after a connection lost during the commit (which may
            # have landed), the key left unanswered tells a retry "applied, answer lost: read
            # the resource" (409) if it did, and runs the request again if it did not
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1")
                   for k, v in start.get("headers", [])}
        kept = {k: v for k, v in headers.items() if k in STORED_HEADERS}
        await run_in_threadpool(_store, self.fastapi_app.state.sessionmaker, key,
                                int(start["status"]), kept, b"".join(chunks))


def install(app: FastAPI) -> None:
    @app.exception_handler(Replay)
    async def _replay(_: Request, exc: Replay) -> Response:
        return Response(exc.body or b"", status_code=exc.status or 200, headers=exc.headers)

    @app.exception_handler(IdempotencyError)
    async def _error(_: Request, exc: IdempotencyError) -> JSONResponse:
        return JSONResponse(status_code=exc.status, content={"detail": [{
            "loc": ["header", "Idempotency-Key"], "msg": exc.msg, "type": "idempotency"}]})

    app.add_middleware(IdempotencyMiddleware, fastapi_app=app)
