"""The database going away under a running service. PostgreSQL restarted: every connection the service kept open is
gone (a failover, a restart, a firewall that drops idle connections). The next requests
answer as before: each pooled connection is checked before a request takes it
(``pool_pre_ping``, ``db.session.make_engine``) and a dead one is replaced. A connection lost
after that check, during the request, is a 503 to retry (never a 500), and the requests
after it get new connections."""

from __future__ import annotations

import os

import pytest

from sqlalchemy import create_engine, event
from sqlalchemy.exc import OperationalError

from api_helpers import C, make_client, ok
from browser_helpers import free_port
from server.service import transaction


def _end_every_other_connection(db_url: str, pid: int | None = None) -> int:
    """``pg_terminate_backend`` of every connection to the test's database but this one, as a
    server restart ends them (or of the one server process ``pid``); how many were ended."""
    import psycopg

    only = "" if pid is None else f" AND pid = {int(pid)}"
    with psycopg.connect(dbname=db_url.rsplit("/", 1)[1], autocommit=True,
                         host=os.environ.get("PGHOST"), port=os.environ.get("PGPORT")) as conn:
        return conn.execute(
            "SELECT count(pg_terminate_backend(pid, 5000)) FROM pg_stat_activity "
            f"WHERE datname = current_database() AND pid <> pg_backend_pid(){only}").fetchone()[0]


def test_reads_and_writes_go_on_after_the_database_ended_every_connection(db_url):  # noqa: ANN001
    if not db_url.startswith("postgresql"):
        pytest.skip("PostgreSQL's connections over the network; a SQLite file has none to lose")
    # no event dispatcher polling beside: the requests are the first to meet the dead ones
    with make_client(db_url, dispatch_events=False) as client:
        before = ok(client.get(C))
        jog = {"mode": "joint", "axis": "A1", "increment": 1.0}
        ok(client.post(f"{C}/robot/jog", json=jog))
        assert _end_every_other_connection(db_url) >= 1  # the service's pooled connections
        after = ok(client.get(C))  # a read
        assert after["joints_deg"][0] == pytest.approx(before["joints_deg"][0] + 1.0)
        moved = ok(client.post(f"{C}/robot/jog", json=jog))  # a write
        assert moved["joints_deg"][0] == pytest.approx(before["joints_deg"][0] + 2.0)
        assert _end_every_other_connection(db_url) >= 1
        assert client.get("/healthz").status_code == 200


def test_a_connection_lost_during_a_request_is_a_503_to_retry(db_url):  # noqa: ANN001
    if not db_url.startswith("postgresql"):
        pytest.skip("PostgreSQL's connections over the network; a SQLite file has none to lose")
    # no event dispatcher polling beside: the request is the first to meet the lost connection
    with make_client(db_url, dispatch_events=False) as client:
        ok(client.get(C))
        pool = client.app.state.engine.pool
        ended = []

        def end_it_after_the_check(dbapi_conn, record, proxy):  # noqa: ANN001, ANN202
            # the pool's "checkout" event comes after its ping: the server goes away there,
            # as the request begins
            if not ended:
                ended.append(_end_every_other_connection(db_url, dbapi_conn.info.backend_pid))

        event.listen(pool, "checkout", end_it_after_the_check)
        try:
            r = client.get(C)
        finally:
            event.remove(pool, "checkout", end_it_after_the_check)
        assert ended == [1]
        assert r.status_code == 503 and r.headers["Retry-After"] == "1", r.text
        assert "connection to the database was lost" in r.json()["detail"][0]["msg"]
        assert ok(client.get(C))["name"] == "cell-1"  # the pool made new connections


def test_a_commit_whose_answer_was_lost_is_not_replayed_as_its_503(client, monkeypatch):  # noqa: ANN001
    """The connection lost just after COMMIT landed (the server went away before its answer):
    the 503 says the write may have been made, and the same Idempotency-Key then gets the 409
    of a command applied whose answer was lost, not that 503 again for 24 h (it was stored and
    replayed), and the jog is not made twice."""
    commit = transaction.commit

    def commit_then_lose_the_connection(db, operation, **ids):  # noqa: ANN001, ANN003
        commit(db, operation, **ids)
        raise OperationalError("COMMIT", {}, Exception("server closed the connection"),
                               connection_invalidated=True)

    before = ok(client.get(C))["joints_deg"][0]
    key = {"Idempotency-Key": "jog-when-the-connection-went"}
    jog = {"mode": "joint", "axis": "A1", "increment": 0.5}
    monkeypatch.setattr(transaction, "commit", commit_then_lose_the_connection)
    first = client.post(f"{C}/robot/jog", json=jog, headers=key)
    monkeypatch.setattr(transaction, "commit", commit)
    assert first.status_code == 503 and first.headers["Retry-After"] == "1", first.text
    assert first.json()["detail"][0]["type"] == "connection_lost"
    assert "may or may not have been" in first.json()["detail"][0]["msg"]
    again = client.post(f"{C}/robot/jog", json=jog, headers=key)
    assert again.status_code == 409 and "answer lost" in again.text, again.text
    assert ok(client.get(C))["joints_deg"][0] == pytest.approx(before + 0.5)  # once


def test_a_database_that_cannot_be_reached_is_a_retry_that_wrote_nothing():
    """No connection to begin with (PostgreSQL down or starting up): the error the driver
    gives is one of "cannot answer now", nothing written; a programming error is not."""
    pytest.importorskip("psycopg")
    engine = create_engine(f"postgresql+psycopg://robot@127.0.0.1:{free_port()}/pendant")
    with pytest.raises(OperationalError) as refused:
        engine.connect()
    why = transaction.unavailable(refused.value)
    assert why is not None and why.startswith("the database cannot be reached now (")
    assert why.endswith("nothing was written: retry") and "refused" in why, why
    assert transaction.unavailable(OperationalError("SELECT x FROM nowhere", {},
                                                    Exception("no such table: nowhere"))) is None
