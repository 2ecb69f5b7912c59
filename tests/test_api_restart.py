"""Sessions and their taught points live in the DB: a restart mid-session loses nothing."""

from __future__ import annotations

import pytest

from api_helpers import C, TRUE_TCP_MM, approach, make_client, ok, open_session, pose_array

ORIENTATION = ("tilt_deg", "around_deg", "spin_deg")


def test_restart_mid_session_keeps_every_touch_up(db_url):
    with make_client(db_url) as first:
        url = open_session(first, "tool.xyz_4point", 2)
        steps = ok(first.get(url))["steps"]
        for st in steps[:2]:
            approach(first, st["target"], **{k: st[k] for k in ORIENTATION})
            ok(first.post(f"{url}/touch-up"))
        before = ok(first.get(url))
        joints = ok(first.get(f"{C}/robot"))["joints_deg"]
        first.app.state.engine.dispose()

    with make_client(db_url) as second:  # a new process on the same SQLite file
        assert ok(second.get(url)) == before
        assert ok(second.get(f"{C}/robot"))["joints_deg"] == pytest.approx(joints)
        assert len(ok(second.get("/controllers"))) == 1  # the demo controller is not made twice
        for st in steps[2:]:
            approach(second, st["target"], **{k: st[k] for k in ORIENTATION})
            ok(second.post(f"{url}/touch-up"))
        report = ok(second.post(f"{url}/compute"))
        second.app.state.engine.dispose()

    with make_client(db_url) as third:  # the computed report survives too
        s = ok(third.get(url))
        assert s["state"] == "computed" and s["report"] == report
        slot = ok(third.post(f"{url}/save"))
        assert pose_array(slot["pose"])[:3] == pytest.approx(TRUE_TCP_MM, abs=1e-3)
