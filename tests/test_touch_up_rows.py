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


# ------------------------------------------- planned before the lock, checked under it

def _between_plan_and_lock(monkeypatch, change) -> None:  # noqa: ANN001
    """Run ``change(bind)`` after the touch-up's plan (done before the writers' lock) and before
    its locked part: as another writer would."""
    from server.routers import sessions

    plan = sessions.touch_up._plan

    def planned_then_changed(**kwargs):  # noqa: ANN003, ANN202
        made = plan(**kwargs)
        change(kwargs["db"].get_bind())
        return made

    monkeypatch.setattr(sessions.touch_up, "_plan", planned_then_changed)


def test_an_arm_moved_after_the_plan_is_touched_up_where_it_stands(client, monkeypatch):
    """The emulated robot moved (a jog by another writer) after the touch-up was planned and
    before its lock: the point is the arm's joints as they are under the lock."""
    from sqlalchemy import text

    url = open_session(client, "tool.xyz_4point", 1)
    q = approach(client, "reference_tip", tilt_deg=0, around_deg=0, spin_deg=0)["joints_deg"]
    moved = [q[0] + 1.5, *q[1:]]

    def jog(bind) -> None:  # noqa: ANN001
        with bind.connect() as conn:
            conn.execute(text("UPDATE controller SET joints_deg = :j, version = version + 1 "
                              "WHERE id = 1"), {"j": json.dumps(moved)})
            conn.commit()

    _between_plan_and_lock(monkeypatch, jog)
    r = client.post(f"{url}/touch-up", json={"step": 0})
    monkeypatch.undo()
    point = ok(r)["steps"][0]["point"]
    assert point["source"] == "touch_up" and point["joints_deg"] == pytest.approx(moved)
    assert ok(client.get(url))["steps"][0]["point"] == point


def test_recorded_joints_planned_on_another_arm_are_worked_out_on_the_controllers(client):
    """The plan works the flange pose out on the arm this process last saw on the controller;
    under the lock the touch-up checks that arm is still the controller's, and if not, works
    the pose out again on the controller's arm (here the arm seen was a UR10's)."""
    from server.routers import sessions
    from solvers.robots import ROBOTS

    url = open_session(client, "tool.xyz_4point", 1)
    q = approach(client, "reference_tip", tilt_deg=0, around_deg=0, spin_deg=0)["joints_deg"]
    right = ok(client.post(f"{url}/touch-up", json={"step": 0, "joints_deg": q}))
    assert sessions.ARMS[1][0] == ("kuka_kr6_r900_sixx", None)  # seen under the lock
    sessions.ARMS[1] = ("ur10", None), ROBOTS["ur10"]
    again = ok(client.post(f"{url}/touch-up", json={"step": 0, "joints_deg": q}))
    assert again["steps"][0]["point"]["flange_pose"] == right["steps"][0]["point"]["flange_pose"]
    assert sessions.ARMS[1][0] == ("kuka_kr6_r900_sixx", None)


def test_a_touch_up_with_an_idempotency_key_runs_once_and_replays(client):
    """The key is claimed in the touch-up's own transaction (taken, with the writers' turn,
    before the route): the touch-up still runs, and a retry gets the stored answer."""
    url = open_session(client, "tool.xyz_4point", 1)
    headers = {"Idempotency-Key": "touch-up-step-0-take-1"}
    first = client.post(f"{url}/touch-up", json={"step": 0}, headers=headers)
    assert first.status_code == 200 and first.json()["steps"][0]["filled"]
    again = client.post(f"{url}/touch-up", json={"step": 0}, headers=headers)
    assert again.status_code == 200 and again.json() == first.json()
    assert again.headers["etag"] == first.headers["etag"] == client.get(url).headers["etag"]
