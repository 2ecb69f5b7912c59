"""A body shorter than its Content-Length (issue 21, item 9): it waited forever; now 408 after
``BODY_IDLE_S`` without a byte, and nothing is changed. Under uvicorn, on a real socket."""

from __future__ import annotations

import json
import socket
import time
from urllib.parse import urlsplit

from api_helpers import ADMIN_TOKEN, C
from browser_helpers import serve
from server.api import limits


def raw_request(url: str, head: str, body: bytes, wait_s: float) -> bytes:
    """Send ``head`` + ``body`` on a socket and read the answer (or b"" after ``wait_s``)."""
    parts = urlsplit(url)
    with socket.create_connection((parts.hostname, parts.port), timeout=wait_s) as s:
        s.sendall(head.encode() + body)
        chunks = []
        try:
            while True:
                chunk = s.recv(65536)
                if not chunk:
                    break
                chunks.append(chunk)
        except socket.timeout:
            pass
        return b"".join(chunks)


def test_a_body_shorter_than_its_content_length_is_408(fresh_db, tmp_path, monkeypatch):
    monkeypatch.setattr(limits, "BODY_IDLE_S", 1.0)
    with serve(fresh_db()) as url:
        import httpx

        auth = {"Authorization": f"Bearer {ADMIN_TOKEN}"}
        before = httpx.get(f"{url}{C}/robot", headers=auth).json()["joints_deg"]
        body = json.dumps({"mode": "joint", "axis": "A1", "increment": 5.0}).encode()
        head = (f"POST {C}/robot/jog HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                f"Authorization: Bearer {ADMIN_TOKEN}\r\nContent-Type: application/json\r\n"
                f"Content-Length: {len(body) + 40}\r\n\r\n")
        t0 = time.monotonic()
        answer = raw_request(url, head, body, wait_s=15.0)
        took = time.monotonic() - t0
        assert answer.startswith(b"HTTP/1.1 408"), answer[:200]
        assert b"Content-Length" in answer and b'"loc": ["body"]' in answer
        assert took < 10.0
        assert httpx.get(f"{url}{C}/robot", headers=auth).json()["joints_deg"] == before
        # a whole body still goes through
        r = httpx.post(f"{url}{C}/robot/jog", headers={**auth, "content-type":
                       "application/json"}, content=body, timeout=30)
        assert r.status_code == 200, r.text
