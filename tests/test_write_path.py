"""The write path (issue 22): one transaction per request, in the route's worker thread.

Behaviour only, nothing a refactor of the internals would change: a writer waiting for
SQLite's write lock waits in a thread, never on the event loop, so reads and health checks go
on; writers take turns (a lock within a process, an flock across processes) rather than poll
in SQLite's busy handler; the service process freezes its start-up objects out of the garbage
collector's walks."""

from __future__ import annotations

import gc
import os
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from fastapi import APIRouter, FastAPI
from sqlalchemy import text
from sqlalchemy.exc import TimeoutError as PoolTimeout
from api_helpers import C, make_client, open_session

from db import session as db_session
from server.api import deps
from server.service import transaction


def test_a_writer_waiting_for_sqlites_lock_leaves_the_event_loop_free(client):
    """SQLite's write lock held by another process's writer (a job worker, the CLI): a
    touch-up waits for it in its thread, a read and the health check answer meanwhile, and
    the touch-up lands once the lock is free."""
    engine = client.app.state.engine
    if engine.dialect.name != "sqlite":
        pytest.skip("SQLite's database-wide write lock; PostgreSQL locks the controller's row")
    url = open_session(client, "tool.xyz_4point", 1)
    other = sqlite3.connect(engine.url.database, isolation_level=None)
    other.execute("BEGIN IMMEDIATE")  # as another process's write transaction
    answers: dict = {}
    writer = threading.Thread(
        target=lambda: answers.update(touch=client.post(f"{url}/touch-up", json={"step": 0})))
    writer.start()
    try:
        t0 = time.perf_counter()
        read = client.get(f"{C}/tools/1")
        health = client.get("/healthz")
        waited_s = time.perf_counter() - t0
        assert read.status_code == 200 and health.status_code == 200 and waited_s < 2.0, waited_s
        assert "touch" not in answers and writer.is_alive()  # the lock is still held
    finally:
        other.execute("ROLLBACK")
        other.close()
    writer.join(30)
    assert answers["touch"].status_code == 200 and answers["touch"].json()["steps"][0]["filled"]


def test_a_process_writers_take_turns_rather_than_poll_sqlites_lock(db_url, monkeypatch):
    """Touch-ups from many threads of one service process: each waits for its turn to write
    (one lock per process), not in SQLite's busy handler, which sleeps up to 100 ms between
    tries. With the busy handler off (a busy timeout of 0), not one of them meets the
    database locked."""
    if not db_url.startswith("sqlite"):
        pytest.skip("SQLite's database-wide write lock; PostgreSQL locks the controller's row")
    monkeypatch.setattr(db_session, "BUSY_TIMEOUT_MS", 0)
    with make_client(db_url) as client:
        urls = [open_session(client, "tool.xyz_4point", n) for n in range(1, 7)]
        codes: list[int] = []

        def teach(url: str) -> None:
            for k in range(12):
                codes.append(client.post(f"{url}/touch-up", json={"step": k % 4}).status_code)
        threads = [threading.Thread(target=teach, args=(u,)) for u in urls]
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
    assert codes == [200] * 72, sorted(set(codes))


def test_reads_answer_while_more_writers_wait_than_a_pool_has_threads(client):
    """50 touch-ups wait for a lock another process holds (SQLite's write lock; on PostgreSQL
    the controller's row), more than the 40 threads a route pool has and more than the
    process's 10 PostgreSQL connections: a read still answers at once, as it does at 100
    touch-ups/s beside the MES reads (writers hold threads of their own, not the readers', and
    on PostgreSQL at most 7 of them hold a connection)."""
    engine = client.app.state.engine
    url = open_session(client, "tool.xyz_4point", 1)
    if engine.dialect.name == "sqlite":
        other = sqlite3.connect(engine.url.database, isolation_level=None)
        other.execute("BEGIN IMMEDIATE")
        release = lambda: (other.execute("ROLLBACK"), other.close())  # noqa: E731
    else:
        other = engine.connect()
        other.execute(text("SELECT id FROM controller WHERE id = 1 FOR UPDATE"))
        release = lambda: (other.rollback(), other.close())  # noqa: E731
    codes: list[int] = []
    writers = [threading.Thread(target=lambda k=k: codes.append(
        client.post(f"{url}/touch-up", json={"step": k % 4}).status_code)) for k in range(50)]
    try:
        for t in writers:
            t.start()
        time.sleep(0.5)  # the writers are queued (none can answer while the lock is held)
        assert codes == []
        t0 = time.perf_counter()
        read = client.get(f"{C}/tools/1")
        waited_s = time.perf_counter() - t0
        assert read.status_code == 200 and waited_s < 2.0, waited_s
    finally:
        release()
        for t in writers:
            t.join(60)
    assert codes == [200] * 50, sorted(set(codes))


def test_a_mes_poll_answers_on_sqlite_while_every_reader_thread_is_busy(client):
    """The reads a MES polls every second (a controller, a slot, a session, the robot, a job)
    are quick reads: on SQLite they are answered on the event loop, so they answer while
    every thread of the readers' pool works on something long (40 exports at once); a read
    that may take long waits for a thread."""
    if client.app.state.engine.dialect.name != "sqlite":
        pytest.skip("on PostgreSQL every read waits for the network, in a thread")
    url = open_session(client, "tool.xyz_4point", 1)
    release = threading.Event()
    busy = [deps.READERS.submit(release.wait, 30) for _ in range(deps.READER_THREADS)]
    try:
        for path in (C, f"{C}/tools/1", f"{C}/bases/1", f"{C}/robot", url):
            answers: list = []
            reader = threading.Thread(target=lambda p=path: answers.append(client.get(p)))
            reader.start()
            reader.join(10)
            assert answers and answers[0].status_code == 200, path
            assert answers[0].headers["ETag"], path
        slow: list = []
        reader = threading.Thread(target=lambda: slow.append(client.get(f"{C}/tools")))
        reader.start()
        reader.join(0.5)
        assert slow == []  # a list of slots is not a quick read: it waits for a thread
    finally:
        release.set()
    reader.join(10)
    assert slow[0].status_code == 200
    for f in busy:
        f.result(10)


def test_only_a_read_can_be_a_quick_read():
    """A route that writes cannot be marked a quick read: it would write on the event loop."""
    router = APIRouter()

    @router.post("/x")
    @deps.quick_read
    def write_something() -> dict:
        return {}

    with pytest.raises(TypeError, match="quick_read is for reads"):
        deps.add_routes(FastAPI(), router)


BACK_TO_BACK = """
import sys, threading, time
from sqlalchemy import text
from db.session import make_engine, make_sessionmaker
from server.service import transaction

maker = make_sessionmaker(make_engine(sys.argv[1]))
stop, writes = threading.Event(), []

def write():
    while not stop.is_set():
        db = transaction.writer(maker)
        with db, transaction.writers_turn(db):
            db.execute(text("UPDATE controller SET name = name"))
            time.sleep(0.01)  # the lock held as a touch-up on a busy worker holds it
            db.commit()
        writes.append(time.monotonic())

threads = [threading.Thread(target=write) for _ in range(3)]
for t in threads:
    t.start()
print("writing", flush=True)
sys.stdin.read()  # until the test closes it
stop.set()
for t in threads:
    t.join()
print(len(writes), flush=True)
"""


def test_another_process_gets_its_turn_between_a_busy_processs_writes(db_url):
    """A service process whose writers follow each other without a gap, and the CLI (here:
    this process) writes now and then: each of its writes waits for about one of the
    service's, not until the service falls idle. (With SQLite's busy handler alone, which
    looks again only every 100 ms, it found the lock free by chance: a ``pendant users
    revoke`` under jog load took seconds.)"""
    if not db_url.startswith("sqlite"):
        pytest.skip("SQLite's database-wide write lock; PostgreSQL locks the controller's row")
    root = Path(__file__).resolve().parent.parent
    busy = subprocess.Popen([sys.executable, "-c", BACK_TO_BACK, db_url], text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            env={**os.environ, "PYTHONPATH": str(root)})
    maker = db_session.make_sessionmaker(db_session.make_engine(db_url))
    waits = []
    try:
        assert busy.stdout.readline().strip() == "writing"
        for _ in range(5):
            time.sleep(0.2)  # the service's writers have the lock in turn again
            t0 = time.monotonic()
            db = transaction.writer(maker)
            with db, transaction.writers_turn(db):
                db.execute(text("UPDATE controller SET name = name"))
                db.commit()
            waits.append(time.monotonic() - t0)
        out, _ = busy.communicate("", timeout=60)
    finally:
        busy.kill()
    assert int(out) > 50, "the busy process did not write all along"
    assert max(waits) < 1.0, waits


def test_a_job_workers_claims_get_their_turn_between_a_busy_processs_writes(db_url):
    """The job worker's writes (a claim here; progress, lease, result) take the same turn: beside
    a service whose writers follow each other, a claim waits for about one write (in SQLite's
    busy handler it waited seconds, and could wait out the busy timeout)."""
    if not db_url.startswith("sqlite"):
        pytest.skip("SQLite's database-wide write lock; PostgreSQL locks the controller's row")
    from db import jobs
    from server.jobs.worker import job_write

    maker = db_session.make_sessionmaker(db_session.make_engine(db_url))
    with maker() as db:
        for _ in range(5):
            jobs.enqueue(db, "analysis", {"recording_id": 1})
        db.commit()
    root = Path(__file__).resolve().parent.parent
    busy = subprocess.Popen([sys.executable, "-c", BACK_TO_BACK, db_url], text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            env={**os.environ, "PYTHONPATH": str(root)})
    waits, claimed = [], []
    try:
        assert busy.stdout.readline().strip() == "writing"
        for _ in range(5):
            time.sleep(0.2)  # the service's writers have the lock in turn again
            t0 = time.monotonic()
            with job_write(maker) as db:
                claimed.append(jobs.claim(db, "worker-1").id)
            waits.append(time.monotonic() - t0)
        out, _ = busy.communicate("", timeout=60)
    finally:
        busy.kill()
    assert int(out) > 50 and len(set(claimed)) == 5
    assert max(waits) < 1.0, waits


def test_a_writer_whose_turn_another_process_keeps_gives_up_with_503(db_url, monkeypatch):
    """Another pendant process holds the writers' turn and does not let go (a command stopped
    with Ctrl-Z mid-write): a touch-up waits for it as long as for SQLite's lock, then
    answers 503 'busy', and is not left hanging; once the turn is free, it lands."""
    if not db_url.startswith("sqlite"):
        pytest.skip("the turn across processes is SQLite's (PostgreSQL locks the controller's row)")
    monkeypatch.setattr(transaction, "TURN_TIMEOUT_S", 0.5)
    with make_client(db_url) as client:
        url = open_session(client, "tool.xyz_4point", 1)
        holder = subprocess.Popen([sys.executable, "-c", (
            "import fcntl, os, sys, time\n"
            "fd = os.open(sys.argv[1], os.O_RDONLY | os.O_CREAT)\n"
            "fcntl.flock(fd, fcntl.LOCK_EX)\n"
            "print('holding', flush=True)\n"
            "sys.stdin.read()\n"), client.app.state.engine.url.database + "-writers"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        try:
            assert holder.stdout.readline().strip() == "holding"
            t0 = time.monotonic()
            r = client.post(f"{url}/touch-up", json={"step": 0})
            waited_s = time.monotonic() - t0
            assert r.status_code == 503 and r.json()["detail"][0]["type"] == "busy", r.text
            assert waited_s < 3.0, waited_s
        finally:
            holder.communicate("", timeout=30)
        assert client.post(f"{url}/touch-up", json={"step": 0}).status_code == 200


def test_writers_queued_behind_a_locked_database_give_up_with_503(db_url, monkeypatch):
    """Another process holds SQLite's write lock past the busy timeout (a long restore): the
    writer waiting for it and those queued behind it for their turn each answer 503 'busy'
    with Retry-After, naming the wait, instead of holding their threads for good."""
    if not db_url.startswith("sqlite"):
        pytest.skip("SQLite's database-wide write lock; PostgreSQL locks the controller's row")
    monkeypatch.setattr(db_session, "BUSY_TIMEOUT_MS", 300)
    monkeypatch.setattr(transaction, "TURN_TIMEOUT_S", 0.3)
    with make_client(db_url) as client:
        urls = [open_session(client, "tool.xyz_4point", n) for n in range(1, 4)]
        other = sqlite3.connect(client.app.state.engine.url.database, isolation_level=None)
        other.execute("BEGIN IMMEDIATE")
        answers: list = []
        try:
            threads = [threading.Thread(target=lambda u=u: answers.append(
                client.post(f"{u}/touch-up", json={"step": 0}))) for u in urls]
            for t in threads:
                t.start()
            for t in threads:
                t.join(20)
        finally:
            other.execute("ROLLBACK")
            other.close()
        assert [r.status_code for r in answers] == [503] * 3
        for r in answers:
            assert r.headers["Retry-After"] == "1"
            assert r.json()["detail"][0]["type"] == "busy"
            assert "locked by another writer for 0.3 s" in r.json()["detail"][0]["msg"]
        assert client.post(f"{urls[0]}/touch-up", json={"step": 0}).status_code == 200


def test_a_request_that_finds_no_connection_free_answers_503(db_url, monkeypatch):
    """Every database connection of the worker stays busy (PostgreSQL keeps 10 per process):
    a request waits the pool's timeout, then answers 503 'busy' with Retry-After, not a 500."""
    monkeypatch.setattr(db_session, "POOL_TIMEOUT_S", 0.3)
    with make_client(db_url) as client:
        engine = client.app.state.engine
        if not hasattr(engine.pool, "timeout"):
            pytest.skip("an in-memory SQLite database has one connection per thread, no queue")
        held = []
        try:
            with pytest.raises(PoolTimeout):
                while len(held) < 200:
                    held.append(engine.raw_connection())
            r = client.get(f"{C}/tools/1")
        finally:
            for conn in held:
                conn.close()
        assert r.status_code == 503 and r.headers["Retry-After"] == "1", r.text
        assert "every database connection of this process stayed busy for 0.3 s" in r.text
        assert client.get(f"{C}/tools/1").status_code == 200


def test_a_touch_up_is_one_transaction_with_its_clock(client):
    """The point, the session's version and the emulated clock change together: a touch-up
    refused after the point is built (a closed session) leaves the clock where it was."""
    url = open_session(client, "tool.xyz_4point", 1)
    clock0 = client.get(f"{C}/cell/clock").json()["clock_s"]
    first = client.post(f"{url}/touch-up", json={"step": 0})
    assert first.status_code == 200
    clock1 = client.get(f"{C}/cell/clock").json()["clock_s"]
    assert clock1 > clock0
    assert client.post(f"{url}/discard", headers={"If-Match": first.headers["ETag"]}).status_code == 200
    assert client.post(f"{url}/touch-up", json={"step": 1}).status_code == 409
    assert client.get(f"{C}/cell/clock").json()["clock_s"] == clock1


def test_a_service_process_freezes_its_start_out_of_the_garbage_collectors_walks(db_url):
    """``server.api.app:app`` (uvicorn's worker) and ``pendant serve`` set ``service_process``: the app's
    start-up objects go to the collector's permanent generation, so a full collection does
    not walk them (80-170 ms per collection otherwise). An app of a test (no ``service_process``)
    freezes nothing: what it leaves must stay collectable."""
    from api_helpers import app_settings
    from fastapi.testclient import TestClient

    from server.api.app import create_app

    gc.unfreeze()
    with make_client(db_url) as c:
        assert c.get(f"{C}/tools/1").status_code == 200 and gc.get_freeze_count() == 0
    app = create_app(app_settings(db_url))
    app.state.service_process = True
    try:
        with TestClient(app):
            assert gc.get_freeze_count() > 10_000
    finally:
        gc.unfreeze()


def test_a_service_process_on_postgresql_starts_with_its_connections_open(db_url):
    """A service process opens its PostgreSQL connections as it starts, not in its first busy
    second (each a backend forked and a login while requests wait); an app of a test opens
    none it does not use."""
    if not db_url.startswith("postgresql"):
        pytest.skip("a SQLite connection is a file opened")
    from api_helpers import app_settings
    from fastapi.testclient import TestClient

    from server.api.app import create_app

    def opened(app) -> int:  # noqa: ANN001
        pool = app.state.engine.pool
        return pool.checkedin() + pool.checkedout()

    app = create_app(app_settings(db_url))
    with TestClient(app):
        assert opened(app) < db_session.PG_POOL_SIZE
    app = create_app(app_settings(db_url))
    app.state.service_process = True
    try:
        with TestClient(app):
            assert opened(app) == db_session.PG_POOL_SIZE
    finally:
        gc.unfreeze()
