"""The API's credentials in its OpenAPI description, so ``/docs`` works as a client.

Two ways in, as ``server.auth.guard`` takes them: an API token as ``Authorization: Bearer``
(scripts, MES, Swagger UI's *Authorize* button), or the browser login's cookie with its CSRF
token in ``X-CSRF-Token`` (a command sent with the cookie alone is refused, 403 ``csrf``).
Every operation names the permission it needs (``server.auth.permissions``) in its
description; a public one (the login, the health check) declares no security.
"""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI

from server.auth.guard import CSRF_HEADER, SESSION_COOKIE
from server.auth.permissions import PUBLIC, required

SCHEMES = {
    "bearer": {"type": "http", "scheme": "bearer", "bearerFormat": "pendant API token (pdt_...)",
               "description": "An API token: `pendant tokens create NAME`, or "
                              "POST /users/{name}/tokens."},
    "session": {"type": "apiKey", "in": "cookie", "name": SESSION_COOKIE,
                "description": "The browser login's cookie (POST /auth/login); a command needs "
                               "the CSRF token too."},
    "csrf": {"type": "apiKey", "in": "header", "name": CSRF_HEADER,
             "description": "The login's CSRF token (the pendant_csrf cookie's value), sent with "
                            "every command made with the login's cookie."},
}
SECURITY = [{"bearer": []}, {"session": [], "csrf": []}]


def install(app: FastAPI) -> None:
    """Have ``app.openapi()`` (as built so far: ``server.api.errors`` adds the error answers)
    declare :data:`SCHEMES`: every operation needs one of them, but the public ones, and says
    which permission it needs."""
    built = app.openapi

    def openapi() -> dict[str, Any]:
        doc = built()
        if "securitySchemes" not in doc.get("components", {}):
            doc.setdefault("components", {})["securitySchemes"] = SCHEMES
            doc["security"] = SECURITY
            for path, ops in doc.get("paths", {}).items():
                for method, op in ops.items():
                    need = required(method.upper(), path)
                    if need == PUBLIC:
                        op["security"] = []
                    elif need is not None:
                        op["description"] = (op.get("description", "") +
                                             f"\n\nPermission: `{need}`.").lstrip()
        return doc

    app.openapi = openapi  # type: ignore[method-assign]
