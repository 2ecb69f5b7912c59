"""Request bodies: size limits (413) and a client that leaves cancels its request.

An ASGI middleware on every request that has a body (not GET, HEAD, OPTIONS):

- **Size.** A body larger than its limit is refused with 413 naming the limit, from
  ``Content-Length`` before any byte is read, or as soon as a chunked body passes it.
  Recordings and beam recordings may be ``UPLOAD_LIMIT_BYTES``, imports (a JSON backup with
  its whole history) ``IMPORT_LIMIT_BYTES``; every other body ``BODY_LIMIT_BYTES``
  (docs/api.md, "Limits").
- **Idle body.** A body that stops arriving (shorter than its ``Content-Length``, or a client
  that stalls) is given up after ``BODY_IDLE_S`` without a byte: **408**, and the request is
  cancelled before it changed anything. Between chunks only: a slow upload that keeps sending
  goes on.
- **Disconnect.** While the request runs, the middleware listens for the client leaving
  (``http.disconnect`` before the answer was sent) and cancels the request. A request whose
  route has not started (its body still arriving or being parsed) changes nothing; a route
  already working in its thread finishes and commits (``server.api.deps.one_thread``), as if
  the answer had been read; its Idempotency-Key keeps no answer (a retry with it gets 409
  "still being processed"), so a client that left reads the resource to see what happened.
"""

from __future__ import annotations

import asyncio
import json

import anyio
from starlette.types import ASGIApp, Message, Receive, Scope, Send

BODY_LIMIT_BYTES = 1 * 2**20  # 1 MiB: any JSON command of the pendant is far below
UPLOAD_LIMIT_BYTES = 16 * 2**20  # 16 MiB: ~70 000 tracker samples
UPLOAD_SUFFIXES = ("/recordings", "/beam-recording")
# 64 MiB: a JSON backup sent as POST .../import {"format": "json", "text": ...} with about
# 39 000 history rows (~1.7 kB each once escaped into the string; tests/test_backup_restore.py).
# The import's ``text`` may be as long (server.api.schemas.ImportIn): the body, never the string,
# is the limit a backup meets first. A longer history restores with ``pendant restore``.
IMPORT_LIMIT_BYTES = 64 * 2**20
IMPORT_SUFFIX = "/import"
NO_BODY = ("GET", "HEAD", "OPTIONS")
BODY_IDLE_S = 20.0  # seconds a request body may pause between two chunks (then 408)


def limit_for(path: str) -> int:
    """The body limit of ``path`` in bytes."""
    path = path.rstrip("/")
    if path.endswith(IMPORT_SUFFIX):
        return IMPORT_LIMIT_BYTES
    return UPLOAD_LIMIT_BYTES if path.endswith(UPLOAD_SUFFIXES) else BODY_LIMIT_BYTES


def _mib(n: int) -> str:
    return f"{n / 2**20:g} MiB"


async def _too_large(send: Send, limit: int, path: str) -> None:
    await _refuse(send, 413, "too_large",
                  f"is larger than the {_mib(limit)} limit of {path} (docs/api.md, Limits)")


async def _refuse(send: Send, status: int, kind: str, msg: str) -> None:
    body = json.dumps({"detail": [{"loc": ["body"], "type": kind, "msg": msg}]})
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode()),
                            (b"connection", b"close")]})
    await send({"type": "http.response.body", "body": body.encode()})


class BodyLimits:
    """The middleware (``app.add_middleware(BodyLimits)``).

    A plain asyncio task reads the request's messages into a queue the app reads from, and
    cancels the app's :class:`anyio.CancelScope` when the body passes its limit or the client
    leaves. (An anyio task group with a memory stream did the same for 0.2 ms more per POST:
    a third of what a POST that does nothing costs; benchmarks/README.md.)
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] in NO_BODY:
            await self.app(scope, receive, send)
            return
        path = scope["path"]
        limit = limit_for(path)
        for name, value in scope["headers"]:
            if name == b"content-length":
                try:
                    declared = int(value)
                except ValueError:
                    declared = 0
                if declared > limit:
                    await _too_large(send, limit, path)
                    return
        state = {"started": False, "done": False, "too_large": False, "idle": False}
        messages: asyncio.Queue[Message] = asyncio.Queue()
        cancel = anyio.CancelScope()

        async def app_send(message: Message) -> None:
            if message["type"] == "http.response.start":
                state["started"] = True
            elif message["type"] == "http.response.body" and not message.get("more_body"):
                state["done"] = True
            await send(message)

        async def pump() -> None:
            total, body_done = 0, False
            while True:
                if body_done:
                    message = await receive()
                else:
                    try:
                        message = await asyncio.wait_for(receive(), BODY_IDLE_S)
                    except asyncio.TimeoutError:
                        state["idle"] = True  # the rest of the body never came
                        cancel.cancel()
                        return
                if message["type"] == "http.request":
                    total += len(message.get("body", b""))
                    body_done = not message.get("more_body", False)
                    if total > limit:
                        state["too_large"] = True
                        cancel.cancel()
                        return
                elif message["type"] == "http.disconnect":
                    if not state["done"]:
                        cancel.cancel()  # the client left: cancel the request
                    messages.put_nowait(message)
                    return
                messages.put_nowait(message)

        reader = asyncio.get_running_loop().create_task(pump())
        try:
            with cancel:
                await self.app(scope, messages.get, app_send)
        finally:
            reader.cancel()  # the answer is out: stop listening
        if state["too_large"] and not state["started"]:
            await _too_large(send, limit, path)
        elif state["idle"] and not state["started"]:
            await _refuse(send, 408, "timeout", f"no byte of the request body came for "
                          f"{BODY_IDLE_S:g} s (shorter than its Content-Length?); nothing "
                          "was changed")
