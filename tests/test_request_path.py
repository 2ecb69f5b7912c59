"""The request path's structure (issue 8, speed): one worker thread per request, SQLite writers
queued without polling, a remembered token. Behaviour only: the speed itself is measured by
``benchmarks/api.py``, not here."""

from __future__ import annotations

import gc
import sqlite3
import subprocess
import sys
import threading
import time

import anyio.to_thread

from api_helpers import *  # noqa: F403
from api_helpers import C, make_client, ok, open_session
from db.writers import WriterQueue
from server.auth import tokens
from test_writers_queue import LOCK_PROBE



def count_hops(monkeypatch) -> list[str]:  # noqa: ANN001
    """The names of the functions run in the threadpool from now on (one per hop)."""
    hops: list[str] = []
    run_sync = anyio.to_thread.run_sync

    async def counting(func, *args, **kw):  # noqa: ANN001, ANN202
        hops.append(getattr(func, "__name__", repr(func)))
        return await run_sync(func, *args, **kw)

    monkeypatch.setattr(anyio.to_thread, "run_sync", counting)
    return hops


SHORT = {"GET /controllers/1/tools/1", "GET /controllers", "POST touch-up", "GET session"}


def test_a_request_takes_one_worker_thread(client, monkeypatch):
    """Auth (a remembered token), the transaction and the answer's serialization all run
    without a second hop between the event loop and the threadpool; a short route
    (``deps.short``: a touch-up, the reads of a slot, a controller, a session) takes none on
    SQLite when it need not wait."""
    # a slow machine takes over 1 s here, so the token is trusted for 10 minutes from its next
    # verification, made now: the cache is the process's, and an entry put by an earlier test
    # (the same Administrator token) would still run out after its 1 s, mid-test
    monkeypatch.setattr(tokens.CACHE, "ttl_s", 600.0)
    tokens.CACHE.clear()
    url = open_session(client, "tool.xyz_4point", 1)
    ok(client.post(f"{url}/touch-up", json={"step": 0}))  # the token is now verified
    hops = count_hops(monkeypatch)
    sqlite = client.app.state.engine.dialect.name == "sqlite"
    for name, method, path, body in (
            ("GET /controllers/1/tools/1", "GET", f"{C}/tools/1", None),
            ("GET /controllers", "GET", "/controllers", None),
            ("POST touch-up", "POST", f"{url}/touch-up", {"step": 1}),
            ("GET session", "GET", url, None),
            ("POST touch-up", "POST", f"{url}/touch-up", {"step": 99}),
            ("GET sessions", "GET", f"{C}/sessions", None),
            ("POST jog", "POST", f"{C}/robot/jog", {"mode": "joint", "axis": "A1", "increment": 0.1})):
        hops.clear()
        r = client.request(method, path, json=body)
        assert r.status_code == (422 if body == {"step": 99} else 200), r.text
        assert len(hops) == (0 if sqlite and name in SHORT else 1), (method, path, hops)
    monkeypatch.undo()
    touched = client.post(f"{url}/touch-up", json={"step": 2})
    assert touched.status_code == 200 and touched.headers["content-type"] == "application/json"
    got = client.get(url)
    assert touched.headers["etag"] == got.headers["etag"]  # the answer carries its ETag
    assert touched.json() == got.json()
    assert [st["filled"] for st in got.json()["steps"]] == [True, True, True, False]
    created = client.post(f"{C}/sessions", json={"method": "tool.xyz_4point", "target_no": 2})
    assert created.status_code == 201 and created.headers["etag"] == '"1"'


def test_a_short_write_whose_turn_is_taken_waits_without_a_thread_or_the_loop(client,
                                                                             monkeypatch):
    """A touch-up finding the SQLite writers' queue held (here by a thread of the test) waits
    for its turn as a future on the event loop: no thread is taken, and a read answers
    meanwhile; the touch-up lands when the holder lets go."""
    if client.app.state.engine.dialect.name != "sqlite":
        return  # PostgreSQL: short routes always run in a thread (nothing to check here)
    url = open_session(client, "tool.xyz_4point", 1)
    queue = client.app.state.writer_queue
    hops = count_hops(monkeypatch)
    queue.acquire()  # as a jog in a worker thread holding its turn
    answers: dict = {}
    writer = threading.Thread(
        target=lambda: answers.update(touch=client.post(f"{url}/touch-up", json={"step": 0})))
    writer.start()
    time.sleep(0.3)  # the touch-up is waiting for its turn by now
    read = client.get(f"{C}/tools/1")
    assert read.status_code == 200 and "touch" not in answers  # answered; still waiting
    queue.release()
    writer.join(30)
    assert answers["touch"].status_code == 200 and answers["touch"].json()["steps"][0]["filled"]
    # neither waited nor ran in a thread (the token, older than its one-second cache by now on
    # a slow machine, may be verified again in one: that is auth's hop, not the writer's)
    assert [h for h in hops if "_bearer_actor" not in h] == []


def test_a_failed_write_gives_up_its_turn(client):
    """A write refused inside its transaction rolls back and lets the next writer in (the
    SQLite writers' queue is not left held)."""
    url = open_session(client, "tool.xyz_4point", 1)
    for _ in range(3):
        assert client.post(f"{url}/touch-up", json={"step": 99}).status_code == 422
        assert client.post(f"{url}/touch-up", json={"step": 0}).status_code == 200


def test_sqlite_writers_queue_in_the_process_and_across_processes(tmp_path):
    path = str(tmp_path / "pendant.db.writer.lock")
    queue = WriterQueue(path)
    queue.acquire()
    held = subprocess.run([sys.executable, "-c", LOCK_PROBE, path], capture_output=True)
    assert held.returncode != 0 and b"BlockingIOError" in held.stderr  # another process waits
    got = threading.Event()

    def second_writer() -> None:
        queue.acquire()
        got.set()
        queue.release()

    t = threading.Thread(target=second_writer)
    t.start()
    assert not got.wait(0.2)  # a second writer of this process waits its turn
    queue.release()
    assert got.wait(30)
    t.join()
    assert subprocess.run([sys.executable, "-c", LOCK_PROBE, path]).returncode == 0


def test_a_writer_outside_the_queue_does_not_stall_the_event_loop(client):
    """SQLite's write lock held by a writer that does not queue (a job worker, the CLI): a
    touch-up, a short route, does not wait for it on the event loop (it waits in a thread),
    so a read answers meanwhile, and the touch-up lands once the lock is free."""
    engine = client.app.state.engine
    if engine.dialect.name != "sqlite":
        return  # PostgreSQL: short routes always run in a thread
    url = open_session(client, "tool.xyz_4point", 1)
    other = sqlite3.connect(engine.url.database, isolation_level=None)
    other.execute("BEGIN IMMEDIATE")  # as a job worker's write transaction
    answers: dict = {}
    writer = threading.Thread(
        target=lambda: answers.update(touch=client.post(f"{url}/touch-up", json={"step": 0})))
    writer.start()
    time.sleep(0.3)  # the touch-up is waiting for the lock by now
    t0 = time.perf_counter()
    read = client.get(f"{C}/tools/1")
    waited_s = time.perf_counter() - t0
    assert "touch" not in answers  # still waiting for the lock
    other.execute("ROLLBACK")
    other.close()
    writer.join(30)
    assert read.status_code == 200 and waited_s < 2.0, waited_s
    assert answers["touch"].status_code == 200 and answers["touch"].json()["steps"][0]["filled"]


def test_a_service_process_freezes_its_start_out_of_the_garbage_collectors_walks(db_url):
    """``server.app:app`` (uvicorn's worker) and ``pendant serve`` set ``freeze_gc``: the app's
    start-up objects go to the collector's permanent generation, so a full collection does
    not walk them (80-170 ms per collection otherwise: benchmarks/README.md). An app of a
    test (no ``freeze_gc``) freezes nothing: what it leaves must stay collectable."""
    from fastapi.testclient import TestClient

    from api_helpers import app_settings
    from server.app import create_app

    gc.unfreeze()
    with make_client(db_url) as c:
        assert c.get(f"{C}/tools/1").status_code == 200 and gc.get_freeze_count() == 0
    app = create_app(app_settings(db_url))
    app.state.freeze_gc = True
    try:
        with TestClient(app):
            assert gc.get_freeze_count() > 10_000
    finally:
        gc.unfreeze()
