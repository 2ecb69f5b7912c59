"""Body limits (413 naming the limit) and a client that leaves: its request is cancelled and
nothing of it is committed. Against the real service under uvicorn on a real SQLite file."""

from __future__ import annotations

import json
import socket
import time
from urllib.parse import urlsplit

import admin_http as httpx  # httpx as the first Administrator
import pytest
from browser_helpers import serve

from server.api.limits import BODY_LIMIT_BYTES, UPLOAD_LIMIT_BYTES
from solvers.physics import Imperfections
from solvers.simulate import simulate_recording


@pytest.fixture(scope="module")
def site(tmp_path_factory):  # noqa: ANN001, ANN201
    db = tmp_path_factory.mktemp("limits") / "pendant.db"
    with serve(f"sqlite:///{db}") as url:
        yield url


def assert_413(r: httpx.Response, limit: int) -> None:
    assert r.status_code == 413, r.text
    item = r.json()["detail"][0]
    assert item["loc"] == ["body"] and f"{limit / 2**20:g} MiB" in item["msg"], item


def test_a_recording_over_the_upload_limit_is_413(site):
    body = b'{"format": "robot-recording/1", "samples": [' + b" " * UPLOAD_LIMIT_BYTES + b"]}"
    assert_413(httpx.post(f"{site}/recordings", content=body,
                          headers={"content-type": "application/json"}, timeout=60),
               UPLOAD_LIMIT_BYTES)


def test_a_command_body_over_the_body_limit_is_413_also_when_chunked(site):
    body = json.dumps({"name": "x" * BODY_LIMIT_BYTES}).encode()
    assert_413(httpx.post(f"{site}/controllers", content=body,
                          headers={"content-type": "application/json"}), BODY_LIMIT_BYTES)

    def chunks():  # no Content-Length: counted as it arrives
        for k in range(0, len(body), 65536):
            yield body[k:k + 65536]

    assert_413(httpx.post(f"{site}/controllers", content=chunks(),
                          headers={"content-type": "application/json"}), BODY_LIMIT_BYTES)
    assert httpx.post(f"{site}/controllers", json={"name": "small"}).status_code == 201


def _send_and_leave(url: str, path: str, body: bytes) -> None:
    """POST ``body`` on a raw socket and close it without reading the answer."""
    u = urlsplit(url)
    with socket.create_connection((u.hostname, u.port)) as s:
        s.sendall(f"POST {path} HTTP/1.1\r\nHost: {u.netloc}\r\nContent-Type: application/json"
                  f"\r\nContent-Length: {len(body)}\r\n\r\n".encode() + body)


def test_a_client_that_leaves_cancels_its_request(site):
    doc = simulate_recording("tracker", "ur10", Imperfections(noise_mm=0.02), 20000, seed=3)
    body = json.dumps(doc).encode()
    before = httpx.get(f"{site}/recordings/1")
    assert before.status_code == 404
    _send_and_leave(site, "/recordings", body)
    time.sleep(5.0)  # the checking of 20 000 samples has long finished
    assert httpx.get(f"{site}/recordings/1").status_code == 404  # nothing was committed
    stayed = httpx.post(f"{site}/recordings", content=body,
                        headers={"content-type": "application/json"}, timeout=60)
    assert stayed.status_code == 201, stayed.text  # the same request, waited for, is stored
    assert httpx.get(f"{site}/recordings/{stayed.json()['id']}").status_code == 200
