"""Sessions: the method list, re-teaching and forgetting steps, states, a stale result."""

from __future__ import annotations

import pytest

from api_helpers import C, approach, ok, open_session, walk
from server.menus import METHODS


def test_methods_lists_every_menu_with_its_prompts(client):
    methods = {m["name"]: m for m in ok(client.get("/methods"))}
    assert set(methods) == set(METHODS)
    assert methods["tool.xyz_4point"]["steps"][2]["prompt"] == \
        "Bring the TCP to the reference point from orientation 3"
    assert methods["base.3point"]["required_params"].keys() == {"tool_no"}
    assert methods["workpiece.direct"]["table"] == "tool" and methods["fixed_tool.6d"]["kind"] == "fixed_tool"


def test_forget_a_step_then_compute_names_it(client):
    url = open_session(client, "tool.xyz_4point", 1)
    walk(client, url)
    s = ok(client.delete(f"{url}/points/2"))
    assert [st["filled"] for st in s["steps"]] == [True, True, False, True]
    r = client.post(f"{url}/compute")
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "points", 2]
    assert "orientation 3" in r.json()["detail"][0]["msg"]
    assert client.delete(f"{url}/points/2").status_code == 404


def test_a_new_touch_up_makes_the_result_stale(client):
    url = open_session(client, "tool.xyz_4point", 1)
    walk(client, url)
    ok(client.post(f"{url}/compute"))
    assert ok(client.get(url))["state"] == "computed"
    approach(client, "reference_tip", tilt_deg=20, around_deg=200, spin_deg=10)
    s = ok(client.post(f"{url}/touch-up"))  # an optional fifth orientation
    assert s["state"] == "open" and s["report"] is None and len(s["steps"]) == 5
    assert s["steps"][4]["required"] is False and s["extra_steps_allowed"] == 7
    assert client.post(f"{url}/save").status_code == 409
    ok(client.post(f"{url}/compute"))
    ok(client.post(f"{url}/save"))
    assert [x["state"] for x in ok(client.get(f"{C}/sessions", params={"state": "saved"}))] == ["saved"]


@pytest.mark.parametrize("method", ["tool.xyz_4point", "base.3point"])
def test_discarded_session_writes_nothing(client, method):
    if method.startswith("base"):  # a touching tool in slot 2 (an empty one is refused at Open)
        ok(client.put(f"{C}/tools/2", json={"pose": {"x": 0, "y": 0, "z": 150, "a": 0, "b": 0, "c": 0}}, headers={"If-Match": "*"}))
    url = open_session(client, method, 1, **({"tool_no": 2} if method.startswith("base") else {}))
    ok(client.post(f"{url}/discard"))
    assert ok(client.get(f"{C}/tools/1/history")) == []
    assert client.post(f"{url}/discard").status_code == 409
