"""What every response and request passes before any route: Host allow-list, Origin check of
commands, security headers of pages. CORS stays closed unless ``Settings.cors_origins`` names
origins (then Starlette's ``CORSMiddleware`` answers for those only).

- ``Host`` must be one of ``Settings.allowed_hosts`` (port ignored; ``*`` allows any): a DNS
  rebinding page reaches the service under its own name and is refused (400).
- A command (not GET/HEAD/OPTIONS) whose ``Origin`` is neither this service nor a configured
  CORS origin is refused (403), whatever its credential: a page of another origin never
  changes anything, even where the browser would send the login cookie (same site, another port).
- Every request gets an id (the client's ``X-Request-ID`` if it sent a short one, else a new
  UUID), answered in ``X-Request-ID`` and written into the audit records of its changes.
- Every response gets ``X-Content-Type-Options: nosniff``, ``X-Frame-Options: DENY`` and
  ``Referrer-Policy: same-origin``; pages get a ``Content-Security-Policy`` allowing only this
  origin (FastAPI's /docs and /redoc, served from the installed fastapi-offline package with inline
  scripts, are left without one).
- A response that sets no ``Cache-Control`` of its own (every API answer) gets ``no-store``: the
  browser keeps no copy of a user's tool table or ``/auth/me`` once they log out (a shared
  pendant PC). The page's own files say ``no-cache`` (server.api.app).
"""

from __future__ import annotations

import json
import re
import uuid
from collections.abc import Iterable
from urllib.parse import urlsplit

from starlette.types import ASGIApp, Message, Receive, Scope, Send

CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
       "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; "
       "frame-ancestors 'none'")
HEADERS = [(b"x-content-type-options", b"nosniff"), (b"x-frame-options", b"DENY"),
           (b"referrer-policy", b"same-origin")]
NO_CSP = ("/docs", "/redoc")
SAFE_METHODS = ("GET", "HEAD", "OPTIONS")
REQUEST_ID = re.compile(r"[A-Za-z0-9._:-]{1,64}")


def host_name(host: str) -> str:
    """``host`` without its port (``[::1]:8000`` -> ``::1``)."""
    host = host.strip().lower()
    if host.startswith("["):
        return host[1:host.find("]")] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


class SiteGuard:
    def __init__(self, app: ASGIApp, allowed_hosts: Iterable[str],
                 cors_origins: Iterable[str] = ()) -> None:
        self.app = app
        self.hosts = {host_name(h) for h in allowed_hosts}
        self.origins = {o.rstrip("/").lower() for o in cors_origins}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1")
                   for k, v in scope.get("headers", [])}
        host = headers.get("host", "")
        origin = headers.get("origin")
        if scope["type"] == "websocket":
            # a browser opens another site's WebSocket with this site's cookies (RWS's ABBCX
            # login) and lets its page read the answers: a socket opened from another
            # site's page is refused (the handshake answers 403), as a command is
            if not self._host_allowed(host) or (
                    origin is not None and not self._own_or_allowed(origin, scope, host)):
                await send({"type": "websocket.close", "code": 1008})
                return
            await self.app(scope, receive, send)
            return
        if not self._host_allowed(host):
            await _deny(send, 400, ["header", "host"], f"host {host!r} is not served here; "
                        "allowed: " + ", ".join(sorted(self.hosts)) + " (--allow-host)")
            return
        if (scope["method"] not in SAFE_METHODS and origin is not None
                and not self._own_or_allowed(origin, scope, host)):
            await _deny(send, 403, ["header", "origin"], f"a command from {origin} is "
                        "refused: another site's page may not change anything here")
            return
        path = scope.get("path", "")
        csp = not path.startswith(NO_CSP)
        rid = headers.get("x-request-id", "")
        rid = rid if REQUEST_ID.fullmatch(rid) else uuid.uuid4().hex
        scope.setdefault("state", {})["request_id"] = rid  # request.state.request_id

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                extra = list(HEADERS) + [(b"x-request-id", rid.encode())]
                if not any(k.lower() == b"cache-control" for k, _ in message.get("headers", [])):
                    extra.append((b"cache-control", b"no-store"))
                if csp:
                    extra.append((b"content-security-policy", CSP.encode()))
                message["headers"] = list(message.get("headers", [])) + extra
            await send(message)

        await self.app(scope, receive, send_with_headers)

    def _host_allowed(self, host: str) -> bool:
        return "*" in self.hosts or host_name(host) in self.hosts

    def _own_or_allowed(self, origin: str, scope: Scope, host: str) -> bool:
        """Whether ``origin`` is this site (scheme and Host) or one --cors-origin allows."""
        o = origin.rstrip("/").lower()
        scheme = scope.get("scheme", "http")
        scheme = {"ws": "http", "wss": "https"}.get(scheme, scheme)  # a WebSocket's handshake
        own = {f"{scheme}://{host.lower()}"}
        return (o in own or o in self.origins) and urlsplit(o).scheme in ("http", "https")


async def _deny(send: Send, status: int, loc: list[str], msg: str) -> None:
    kind = "bad_host" if status == 400 else "cross_site"
    body = json.dumps({"detail": [{"loc": loc, "msg": msg, "type": kind}]}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode()), *HEADERS]})
    await send({"type": "http.response.body", "body": body})
