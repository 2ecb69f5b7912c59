"""Several processes on one database (issue 8): 4 uvicorn workers on a fresh SQLite file, and
on a real PostgreSQL server when one is reachable (``tests/run``'s pg_virtualenv pass).

- 4 workers starting on an empty database migrate it once and create the demo cell once;
- 200 concurrent +0.1 deg jogs of A1 move it exactly +20.0 deg; 200 concurrent touch-ups
  advance the emulated clock by exactly 200 x 2 s; 200 read-modify-write slot edits by 8
  clients (If-Match, retry on 412) add up exactly; 8 concurrent light-barrier cycles add
  exactly 8 cycles' emulated time (the controller's state loaded and saved under the lock);
- the lost-update trials: two writers with one ETag, one gets 412 (with the current slot);
  no If-Match gets 428; never a silent overwrite;
- Idempotency-Key: one jog however often it is retried, on whichever worker;
- SIGKILL of a worker at random moments (x10), then of the whole service: no acknowledged
  jog is lost.
"""

from __future__ import annotations

import asyncio
import os
import random
import signal
import time

import admin_http as httpx  # httpx as the first Administrator
import pytest

from db_backends import backends
from workers_helpers import concurrently, kill, service, start, wait_healthy

from db.session import alembic_config as _alembic_config
from alembic.script import ScriptDirectory as _Scripts

HEAD = _Scripts.from_config(_alembic_config("sqlite://")).get_current_head()  # the code's schema

C = "/controllers/1"
JOG = {"mode": "joint", "axis": "A1", "increment": 0.1}
WORKERS = 4


@pytest.fixture(scope="module", params=backends())
def svc(request, tmp_path_factory, fresh_db):  # noqa: ANN001, ANN201
    """4 workers on a fresh, *unmigrated* database of each backend."""
    tmp = tmp_path_factory.mktemp(f"workers-{request.param}")
    url = fresh_db(f"workers-db-{request.param}", backend=request.param, migrated=False)
    with service(url, WORKERS, tmp / "service.log") as s:
        s.db_url = url  # type: ignore[attr-defined]
        yield s


def a1(url: str) -> float:
    # 30 s: right after kill -9 bursts, under the whole suite, a worker may still be restarting
    return httpx.get(f"{url}{C}/robot", timeout=30.0).json()["joints_deg"][0]


def test_four_workers_migrate_a_fresh_database_once(svc):  # noqa: ANN001
    log = svc.log_text()
    assert log.count("Application startup complete") == WORKERS, log
    assert "Traceback" not in log and "already exists" not in log, log
    names = [c["name"] for c in httpx.get(f"{svc.url}/controllers").json()]
    assert names == ["cell-1"]  # the demo cell, created once
    assert httpx.get(f"{svc.url}/healthz").json()["schema"] == HEAD


def test_200_concurrent_jogs_add_up_exactly(svc):  # noqa: ANN001
    before = a1(svc.url)
    answers = concurrently(svc.url, [("POST", f"{C}/robot/jog", JOG, {})] * 200)
    assert [getattr(r, "status_code", r) for r in answers] == [200] * 200
    assert a1(svc.url) - before == pytest.approx(20.0, abs=1e-9)


def test_200_concurrent_touch_ups_lose_no_clock_tick(svc):  # noqa: ANN001
    s = httpx.post(f"{svc.url}{C}/sessions",
                   json={"method": "tool.xyz_4point", "target_no": 9}).json()
    clock0 = httpx.get(f"{svc.url}{C}/cell/clock").json()["clock_s"]
    path = f"{C}/sessions/{s['id']}/touch-up"
    answers = concurrently(svc.url, [("POST", path, {"step": k % 4}, {}) for k in range(200)])
    assert [getattr(r, "status_code", r) for r in answers] == [200] * 200
    clock1 = httpx.get(f"{svc.url}{C}/cell/clock").json()["clock_s"]
    assert clock1 - clock0 == pytest.approx(200 * 2.0, abs=1e-9)  # TOUCH_UP_S each
    steps = httpx.get(f"{svc.url}{path[:-len('/touch-up')]}").json()["steps"]
    assert [st["filled"] for st in steps[:4]] == [True] * 4


def test_concurrent_light_barrier_cycles_each_start_where_the_last_stopped(svc):  # noqa: ANN001
    """The emulated controller's state (joints, clock, flanks) is loaded and saved under the
    row lock in the run-cycle route too: once the robot rests at the tip, every cycle adds the
    same time, and 8 cycles at once on 4 workers add exactly 8 of them."""
    s = httpx.post(f"{svc.url}{C}/sessions",
                   json={"method": "tool.light_barrier", "target_no": 7,
                         "params": {"nominal_tool": {"x": 0.0, "y": 0.0, "z": 180.0}}}).json()
    path = f"{C}/sessions/{s['id']}/run-cycle"

    def clock() -> float:
        return httpx.get(f"{svc.url}{C}/cell/clock").json()["clock_s"]

    assert httpx.post(f"{svc.url}{path}").status_code == 200  # from wherever: ends at the tip
    clock0 = clock()
    assert httpx.post(f"{svc.url}{path}").status_code == 200
    one = clock() - clock0
    assert one > 10.0  # 9 passes at 20 mm/s and 2 s between them
    clock1 = clock()
    answers = concurrently(svc.url, [("POST", path, None, {})] * 8)
    assert [getattr(r, "status_code", r) for r in answers] == [200] * 8
    assert clock() - clock1 == pytest.approx(8 * one, abs=1e-6)


async def _increment(url: str, path: str, n: int) -> int:
    """One person: ``n`` times read the slot, add 0.1 mm to x, write with If-Match; a 412
    brings the current slot and ETag, and the edit is made again on that. Returns the 412s."""
    stale = 0
    async with httpx.AsyncClient(base_url=url, timeout=60) as client:
        r = await client.get(path)
        etag, x = r.headers["ETag"], r.json()["pose"]["x"]
        for _ in range(n):
            while True:
                r = await client.put(path, json={"pose": {"x": round(x + 0.1, 9)}},
                                     headers={"If-Match": etag})
                if r.status_code == 200:
                    etag, x = r.headers["ETag"], r.json()["pose"]["x"]
                    break
                assert r.status_code == 412, r.text
                stale += 1
                etag, x = r.headers["ETag"], r.json()["current"]["pose"]["x"]
    return stale


def test_concurrent_slot_edits_with_if_match_add_up_exactly(svc):  # noqa: ANN001
    path = f"{C}/tools/5"

    async def everyone() -> list[int]:
        return await asyncio.gather(*(_increment(svc.url, path, 25) for _ in range(8)))

    stale = asyncio.run(everyone())
    assert httpx.get(f"{svc.url}{path}").json()["pose"]["x"] == pytest.approx(20.0, abs=1e-6)
    assert sum(stale) > 0  # they did collide, and each collision was a 412, not an overwrite
    history = httpx.get(f"{svc.url}{path}/history").json()
    assert len(history) == 200


async def _trials(url: str, path: str, n: int) -> list[tuple[list[httpx.Response], list[str]]]:
    """``n`` times: two people read the slot (one ETag), then both write it at once."""
    out = []
    async with httpx.AsyncClient(base_url=url, timeout=60) as a, \
            httpx.AsyncClient(base_url=url, timeout=60) as b:
        for trial in range(n):
            etag = (await a.get(path)).headers["ETag"]
            names = [f"alice{trial}", f"bob{trial}"]
            answers = await asyncio.gather(
                *(who.put(path, json={"name": name}, headers={"If-Match": etag})
                  for who, name in zip((a, b), names)))
            out.append((list(answers), names))
    return out


def test_lost_update_trials_give_412_to_one_writer(svc):  # noqa: ANN001
    path = f"{C}/tools/6"
    for answers, names in asyncio.run(_trials(svc.url, path, 50)):
        codes = sorted(r.status_code for r in answers)
        assert codes == [200, 412], [r.text for r in answers]
        winner = next(n for n, r in zip(names, answers) if r.status_code == 200)
        loser = next(r for r in answers if r.status_code == 412)
        assert loser.json()["current"]["name"] == winner  # what they would have overwritten
    assert httpx.get(f"{svc.url}{path}").json()["name"] == winner
    blind = httpx.put(f"{svc.url}{path}", json={"name": "blind"})
    assert blind.status_code == 428
    assert blind.json()["detail"][0]["loc"] == ["header", "If-Match"]
    assert httpx.get(f"{svc.url}{path}").json()["name"] == winner


def test_idempotency_key_jogs_once_on_any_worker(svc):  # noqa: ANN001
    before = a1(svc.url)
    key = {"Idempotency-Key": f"jog-{time.time_ns()}"}
    first = httpx.post(f"{svc.url}{C}/robot/jog", json=JOG, headers=key)
    assert first.status_code == 200
    answers = concurrently(svc.url, [("POST", f"{C}/robot/jog", JOG, key)] * 40)
    assert {r.status_code for r in answers} == {200}
    assert {r.text for r in answers} == {first.text}  # the stored answer, from any worker
    assert a1(svc.url) - before == pytest.approx(0.1, abs=1e-9)
    other = httpx.post(f"{svc.url}{C}/robot/jog", json={**JOG, "increment": 0.2}, headers=key)
    assert other.status_code == 422
    assert other.json()["detail"][0]["loc"] == ["header", "Idempotency-Key"]


def test_kill_9_at_random_moments_loses_no_acknowledged_jog(svc, tmp_path):  # noqa: ANN001
    rnd = random.Random(8)
    before = a1(svc.url)
    acked = failed = 0
    for _ in range(10):  # uvicorn restarts each killed worker meanwhile; no wait for it
        while len(svc.workers()) < 2:
            time.sleep(0.05)
        victim = rnd.choice(svc.workers())

        async def burst() -> list:
            async def killer() -> None:
                await asyncio.sleep(rnd.uniform(0.0, 0.3))
                os.kill(victim, signal.SIGKILL)
            from workers_helpers import _send
            answers, _ = await asyncio.gather(
                _send(svc.url, [("POST", f"{C}/robot/jog", JOG, {})] * 40, 40), killer())
            return answers

        answers = asyncio.run(burst())
        acked += sum(getattr(r, "status_code", 0) == 200 for r in answers)
        failed += sum(getattr(r, "status_code", 0) != 200 for r in answers)
        svc.restarts += 1
    moved = a1(svc.url) - before
    assert acked * 0.1 - 1e-6 <= moved <= (acked + failed) * 0.1 + 1e-6, (acked, failed, moved)
    # and a crash of the whole service (every process) in the middle of a burst
    acked2 = 0

    async def burst_and_crash() -> list:
        async def crasher() -> None:
            await asyncio.sleep(0.2)
            os.killpg(svc.proc.pid, signal.SIGKILL)
        from workers_helpers import _send
        answers, _ = await asyncio.gather(
            _send(svc.url, [("POST", f"{C}/robot/jog", JOG, {})] * 60, 60), crasher())
        return answers

    answers = asyncio.run(burst_and_crash())
    acked2 = sum(getattr(r, "status_code", 0) == 200 for r in answers)
    kill(svc.proc)
    again = start(svc.db_url, 1, tmp_path / "restart.log")
    try:
        wait_healthy(again.url, again.proc, again.log)
        moved2 = a1(again.url) - before - moved
        assert acked2 * 0.1 - 1e-6 <= moved2 <= 60 * 0.1 + 1e-6, (acked2, moved2)
    finally:
        kill(again.proc)
