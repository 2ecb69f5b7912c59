"""PostgreSQL restarted under a running service: every connection the service kept open is
gone (a failover, a restart, a firewall that drops idle connections). The next requests
answer as before: each pooled connection is checked before a request takes it
(``pool_pre_ping``, ``db.session.make_engine``) and a dead one is replaced. A connection lost
after that check, during the request, is a 503 to retry (never a 500), and the requests
after it get new connections."""

from __future__ import annotations

import os

import pytest

from api_helpers import C, ok


def _end_every_other_connection(db_url: str) -> int:
    """``pg_terminate_backend`` of every connection to the test's database but this one, as a
    server restart ends them; how many were ended."""
    import psycopg

    with psycopg.connect(dbname=db_url.rsplit("/", 1)[1], autocommit=True,
                         host=os.environ.get("PGHOST"), port=os.environ.get("PGPORT")) as conn:
        return conn.execute(
            "SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity "
            "WHERE datname = current_database() AND pid <> pg_backend_pid()").fetchone()[0]


def test_reads_and_writes_go_on_after_the_database_ended_every_connection(client, db_url):  # noqa: ANN001
    if not db_url.startswith("postgresql"):
        pytest.skip("PostgreSQL's connections over the network; a SQLite file has none to lose")
    before = ok(client.get(C))
    ok(client.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A1", "increment": 1.0}))
    assert _end_every_other_connection(db_url) >= 1  # the service's pooled connections
    after = ok(client.get(C))  # a read
    assert after["joints_deg"][0] == pytest.approx(before["joints_deg"][0] + 1.0)
    moved = ok(client.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A1",
                                                   "increment": 1.0}))  # a write
    assert moved["joints_deg"][0] == pytest.approx(before["joints_deg"][0] + 2.0)
    assert _end_every_other_connection(db_url) >= 1
    assert client.get("/healthz").status_code == 200


def test_a_connection_lost_during_a_request_is_a_503_to_retry(client, db_url):  # noqa: ANN001
    if not db_url.startswith("postgresql"):
        pytest.skip("PostgreSQL's connections over the network; a SQLite file has none to lose")
    ok(client.get(C))
    pool = client.app.state.engine.pool
    pool._pre_ping = False  # the server goes away after the check, as the request begins
    try:
        assert _end_every_other_connection(db_url) >= 1
        r = client.get(C)
        assert r.status_code == 503 and r.headers["Retry-After"] == "1", r.text
        assert "connection to the database was lost" in r.json()["detail"][0]["msg"]
        assert ok(client.get(C))["name"] == "cell-1"  # the pool made new connections
    finally:
        pool._pre_ping = True
