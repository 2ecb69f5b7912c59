"""httpx as the service's first Administrator: every request carries ``api_helpers.ADMIN_TOKEN``.

The multi-process tests talk to a real ``pendant serve`` (or uvicorn workers) over loopback;
``import admin_http as httpx`` gives them httpx whose requests log in, as a person's client
would, so they go through the real authentication.
"""

from __future__ import annotations

from typing import Any

import httpx as _httpx
from httpx import HTTPError, Limits, Response  # noqa: F401  (re-exported for the tests)

from api_helpers import ADMIN_TOKEN

AUTH = {"Authorization": f"Bearer {ADMIN_TOKEN}"}


def _logged_in(kw: dict[str, Any]) -> dict[str, Any]:
    return {**kw, "headers": {**AUTH, **(kw.get("headers") or {})}}


def get(url: str, **kw: Any) -> Response:
    return _httpx.get(url, **_logged_in(kw))


def post(url: str, **kw: Any) -> Response:
    return _httpx.post(url, **_logged_in(kw))


def put(url: str, **kw: Any) -> Response:
    return _httpx.put(url, **_logged_in(kw))


class Client(_httpx.Client):
    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **_logged_in(kw))


class AsyncClient(_httpx.AsyncClient):
    def __init__(self, *args: Any, **kw: Any) -> None:
        super().__init__(*args, **_logged_in(kw))
