"""Every write leaves an audit record (issue 22): a person walks the pendant's operations
through REST, and after each the trail has grown by its record, naming the operation (or the
change a row hook records in detail: a frame, a controller, the physics...), the user and the
controller. A refused operation changes nothing and records nothing."""

from __future__ import annotations

import pytest

from api_helpers import C, approach, edit_slot, ok, open_session, walk


def _trail(client) -> list[dict]:  # noqa: ANN001
    return ok(client.get("/audit", params={"limit": 100000}))


class Trail:
    """The audit trail as a person reads it after each operation."""

    def __init__(self, client) -> None:  # noqa: ANN001
        self.client, self.seen = client, len(_trail(client))

    def added(self) -> list[dict]:
        rows = _trail(self.client)
        new, self.seen = rows[self.seen:], len(rows)
        return new


@pytest.fixture
def trail(client) -> Trail:  # noqa: ANN001
    approach(client, "reference_tip")  # the arm somewhere sensible; audited, not counted
    return Trail(client)


def _one(trail: Trail, action: str, **fields) -> dict:  # noqa: ANN003
    new = trail.added()
    assert [r["action"] for r in new] == [action], new
    (rec,) = new
    assert rec["user"] == "admin" and rec["source"] == "api", rec
    for k, v in fields.items():
        assert rec[k] == v, (k, rec)
    return rec


def test_every_operation_of_a_menu_run_is_audited(client, trail):  # noqa: ANN001
    url = open_session(client, "tool.xyz_4point", 1)
    sid = int(url.rsplit("/", 1)[1])
    _one(trail, "op.open_session", controller_id=1)
    ok(client.post(f"{url}/touch-up", json={"step": 0}))
    _one(trail, "op.touch_up", controller_id=1, session_id=sid)
    ok(client.delete(f"{url}/points/0"))
    _one(trail, "op.delete_point", controller_id=1, session_id=sid)
    walk(client, url)  # approach + touch up, four times
    assert [r["action"] for r in trail.added()] == ["op.approach", "op.touch_up"] * 4
    ok(client.post(f"{url}/compute"))
    _one(trail, "op.compute", controller_id=1, session_id=sid)
    ok(client.post(f"{url}/save"))
    _one(trail, "frame.calibration", controller_id=1, table="tool", number=1)
    other = open_session(client, "base.3point", 2, tool_no=1)
    trail.added()
    ok(client.post(f"{other}/discard"))
    _one(trail, "op.discard", controller_id=1)


def test_every_motion_setting_and_slot_edit_is_audited(client, trail):  # noqa: ANN001
    ok(client.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A1", "increment": 1.0}))
    _one(trail, "op.jog", controller_id=1)
    ok(client.post(f"{C}/robot/home"))
    _one(trail, "op.home", controller_id=1)
    ok(client.put(f"{C}/robot/active", json={"tool_no": 1}))
    _one(trail, "op.set_active", controller_id=1)
    ok(client.put(f"{C}/robot/external", json={"values": {"E1": 10.0}}))
    _one(trail, "op.set_external", controller_id=1)
    ok(client.put(f"{C}/cell/clock", json={"clock_s": 1000.0}))
    _one(trail, "emulator.clock", controller_id=1)
    ok(client.put(f"{C}/cell/physics", json={"compliance_deg_per_Nm": [0, 0.001, 0, 0, 0, 0]}))
    _one(trail, "emulator.physics", controller_id=1)
    edit_slot(client, f"{C}/tools/3", {"name": "gripper", "pose": {"x": 1, "y": 2, "z": 150,
                                                                    "a": 0, "b": 0, "c": 0}})
    _one(trail, "frame.edit", controller_id=1, table="tool", number=3)


def test_a_refused_operation_records_nothing(client, trail):  # noqa: ANN001
    r = client.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A5", "increment": 100.0})
    assert r.status_code in (409, 422), r.text
    url = open_session(client, "tool.xyz_4point", 2)
    trail.added()
    assert client.post(f"{url}/compute").status_code in (409, 422)  # no touch-up yet
    assert trail.added() == []


def test_every_recording_job_and_webhook_write_is_audited(client, trail):  # noqa: ANN001
    poses = [[0, -90, 90, 0, 90, 0], [30, -80, 80, 10, 80, 20], [-30, -100, 100, -10, 100, -20],
             [60, -70, 60, 20, 70, 40]]
    rec = ok(client.post("/plan/recording", json={"robot": "ur10", "joints_deg": poses}))
    _one(trail, "op.record_from_plan")  # computed outside the request, stored in its own write
    r = client.post(f"/recordings/{rec['id']}/analyze")
    assert r.status_code == 202, r.text
    _one(trail, "op.analyze_recording")
    ok(client.post(f"/jobs/{r.json()['id']}/cancel"))
    _one(trail, "op.cancel_job")
    hook = ok(client.post("/webhooks", json={"url": "http://127.0.0.1:9/pendant"}))
    _one(trail, "webhook.create")
    ok(client.post(f"/webhooks/{hook['id']}/test"))
    _one(trail, "op.test_webhook")
    assert client.delete(f"/webhooks/{hook['id']}").status_code == 204
    _one(trail, "webhook.delete")
