"""X-Forwarded-For is believed only from a configured proxy (issue 21, item 5): a request from
loopback with ``X-Forwarded-For: 6.6.6.6`` was audited as coming from 6.6.6.6."""

from __future__ import annotations

import httpx

from api_helpers import ADMIN_TOKEN, C
from test_auth_revoke_load import service


def clock_client(url: str, **headers: str) -> str:
    """PUT the clock with ``headers``; the audit record's client."""
    with httpx.Client(base_url=url, headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}) as c:
        r = c.put(f"{C}/cell/clock", json={"clock_s": 10.0},
                  headers={"If-Match": "*", **headers})
        assert r.status_code == 200, r.text
        rid = r.headers["x-request-id"]
        return [a for a in c.get("/audit").json() if a["request_id"] == rid][0]["client"]


def test_forwarded_for_ignored_unless_from_a_trusted_proxy(fresh_db, tmp_path):
    db = fresh_db()
    with service(db, PENDANT_TRUSTED_PROXIES="") as url:
        assert clock_client(url, **{"X-Forwarded-For": "6.6.6.6"}) == "127.0.0.1"
    with service(db, PENDANT_TRUSTED_PROXIES="127.0.0.1") as url:  # a proxy on this host
        assert clock_client(url, **{"X-Forwarded-For": "6.6.6.6"}) == "6.6.6.6"
