"""Touch-up through Core rows (db.rows, db.touch_up): what it writes is what the ORM reads back.

The touch-up route reads and writes with Core statements; every other route reads the same
rows through the models. These walks check that the two agree: the point, the versions (the
ETags), the emulated clock, a result made stale, and the refusals.
"""

from __future__ import annotations

import json

import pytest

from api_helpers import *  # noqa: F403
from api_helpers import C, approach, ok, open_session, walk


def _etag(r) -> int:  # noqa: ANN001
    return int(r.headers["ETag"].strip('"'))


def test_a_touch_up_reads_back_through_the_models(client):
    url = open_session(client, "tool.xyz_4point", 1)
    controller0, session0 = client.get(C), client.get(url)
    clock0 = ok(client.get(f"{C}/cell/clock"))["clock_s"]
    q = approach(client, "reference_tip", tilt_deg=0, around_deg=0, spin_deg=0)["joints_deg"]
    controller1 = client.get(C)
    r = client.post(f"{url}/touch-up", json={"step": 0, "joints_deg": q})
    taught = ok(r)["steps"][0]["point"]
    assert _etag(r) == _etag(session0) + 1
    read = client.get(url)  # the session through the ORM (crud.get_session)
    assert _etag(read) == _etag(r) and ok(read)["steps"][0]["point"] == taught
    assert taught["source"] == "joints" and taught["joints_deg"] == q
    assert _etag(client.get(C)) == _etag(controller1) + 1  # the clock ticked: a new version
    assert _etag(controller1) > _etag(controller0)  # the approach moved the arm
    assert ok(client.get(f"{C}/cell/clock"))["clock_s"] > clock0


def test_a_re_teach_overwrites_the_step_in_place(client):
    url = open_session(client, "tool.xyz_4point", 1)
    walk(client, url)
    first = ok(client.get(url))["steps"][1]["point"]
    approach(client, "reference_tip", tilt_deg=25, around_deg=100, spin_deg=0)
    s = ok(client.post(f"{url}/touch-up", json={"step": 1}))
    assert [st["filled"] for st in s["steps"]] == [True, True, True, True]
    again = ok(client.get(url))["steps"][1]["point"]
    assert again["source"] == "touch_up" and again["flange_pose"] != first["flange_pose"]
    assert again == s["steps"][1]["point"]


def test_a_touch_up_after_compute_reopens_the_session_for_the_models_too(client):
    url = open_session(client, "tool.xyz_4point", 1)
    walk(client, url)
    ok(client.post(f"{url}/compute"))
    approach(client, "reference_tip", tilt_deg=30, around_deg=240, spin_deg=-90)
    ok(client.post(f"{url}/touch-up", json={"step": 3}))
    s = ok(client.get(url))
    assert s["state"] == "open" and s["report"] is None and s["result"] is None
    assert client.post(f"{url}/save").status_code == 409


def test_touch_up_refusals_name_the_field(client):
    url = open_session(client, "tool.xyz_4point", 1)
    stale = _etag(client.get(url))
    walk(client, url)
    r = client.post(f"{url}/touch-up", json={"step": 0}, headers={"If-Match": f'"{stale}"'})
    assert r.status_code == 412 and r.json()["current"]["id"] == int(url.rsplit("/", 1)[1])
    r = client.post(f"{url}/touch-up", json={"step": 0, "joints_deg": [0, -90, 90]})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"][-1] == "joints_deg"
    r = client.post(f"{url}/touch-up", json={"step": 99})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"][-1] == "step"
    for path in (f"{C}/sessions/{2**70}/touch-up", f"/controllers/{2**70}/sessions/1/touch-up",
                 f"{C}/sessions/999999/touch-up"):
        r = client.post(path, json={})
        assert r.status_code == 404, (path, r.text)


# ------------------------------------------------------- planned before the lock, checked under it

def _between_plan_and_lock(monkeypatch, change) -> None:  # noqa: ANN001
    """Run ``change(sessionmaker)`` after the touch-up's plan (reads, checks, kinematics, done
    without the writers' lock) and before its locked part: as another writer would."""
    from server.routers import sessions

    plan = sessions.touch_up._plan

    def planned_then_changed(conn, **kwargs):  # noqa: ANN001, ANN202
        made = plan(conn, **kwargs)
        change(kwargs["db"].get_bind())
        return made

    monkeypatch.setattr(sessions.touch_up, "_plan", planned_then_changed)


def _write(bind, sql: str, **params) -> None:  # noqa: ANN001, ANN003
    from sqlalchemy import text

    with bind.connect() as conn:
        conn.execute(text(sql), params)
        conn.commit()


def test_a_session_changed_after_the_plan_is_touched_up_as_it_is_now(client, monkeypatch):
    """Another writer re-taught step 1 between the touch-up's plan and its lock: the touch-up
    of step 0 is worked out again under the lock, so its answer (and ETag) hold both."""
    url = open_session(client, "tool.xyz_4point", 1)
    q = approach(client, "reference_tip", tilt_deg=0, around_deg=0, spin_deg=0)["joints_deg"]
    ok(client.post(f"{url}/touch-up", json={"step": 1, "joints_deg": q}))
    sid = int(url.rsplit("/", 1)[1])
    _between_plan_and_lock(monkeypatch, lambda bind: _write(
        bind, "UPDATE taught_point SET x_mm = 1234.5 WHERE session_id = :s AND step = 1; ",
        s=sid) or _write(bind, "UPDATE calib_session SET version = version + 1 WHERE id = :s",
                         s=sid))
    before = _etag(client.get(url))
    r = client.post(f"{url}/touch-up", json={"step": 0, "joints_deg": q})
    monkeypatch.undo()
    steps = ok(r)["steps"]
    assert steps[0]["filled"] and steps[1]["point"]["flange_pose"]["x"] == 1234.5
    assert _etag(r) == before + 2  # the other writer's bump, then this one's
    assert ok(client.get(url)) == ok(r) and _etag(client.get(url)) == _etag(r)


def test_an_arm_moved_after_the_plan_is_touched_up_where_it_stands(client, monkeypatch):
    """The emulated robot moved (a jog by another writer) between the touch-up's plan and its
    lock: the point is the arm's joints as they are under the lock, not as planned."""
    url = open_session(client, "tool.xyz_4point", 1)
    q = approach(client, "reference_tip", tilt_deg=0, around_deg=0, spin_deg=0)["joints_deg"]
    moved = [q[0] + 1.5, *q[1:]]
    _between_plan_and_lock(monkeypatch, lambda bind: _write(
        bind, "UPDATE controller SET joints_deg = :j, version = version + 1 WHERE id = 1",
        j=json.dumps(moved)))
    r = client.post(f"{url}/touch-up", json={"step": 0})
    monkeypatch.undo()
    point = ok(r)["steps"][0]["point"]
    assert point["source"] == "touch_up" and point["joints_deg"] == pytest.approx(moved)
    assert ok(client.get(url))["steps"][0]["point"] == point


def test_a_stale_if_match_is_refused_before_the_writers_turn(client):
    """The plan checks If-Match, so a 412 comes without waiting for the writers' lock (here held
    by a thread of the test on SQLite)."""
    url = open_session(client, "tool.xyz_4point", 1)
    stale = _etag(client.get(url))
    walk(client, url)
    queue = client.app.state.writer_queue
    if queue is not None:
        queue.acquire()
    try:
        r = client.post(f"{url}/touch-up", json={"step": 0}, headers={"If-Match": f'"{stale}"'})
    finally:
        if queue is not None:
            queue.release()
    assert r.status_code == 412
