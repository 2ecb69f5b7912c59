"""Slots keep their kind and their name unless the person says otherwise: saving into a slot of
another kind, or into a named slot no menu calibrated, is a 409 naming its kind and name until
``confirm=true``; the kind changed, the name does not stay."""

from __future__ import annotations

from api_helpers import C, calibrate, edit_slot, ok, open_session, walk


def _offset_into_base5(client) -> str:  # noqa: ANN001
    """Tool 1 calibrated; ext.offset into BASE 5 walked and computed; the session URL."""
    calibrate(client, "tool.xyz_4point", 1)
    url = open_session(client, "ext.offset", 5, tool_no=1, ext_no=1)
    s = ok(client.get(url))
    for st in s["steps"]:
        ok(client.put(f"{C}/robot/external", json={"values": st["external_axes"]}))
        ok(client.post(f"{C}/robot/approach", json={"target": st["target"], "noise_mm": 0.0,
                                                   "tilt_deg": st["tilt_deg"],
                                                   "around_deg": st["around_deg"]}))
        ok(client.post(f"{url}/touch-up", json={"step": st["index"]}))
    ok(client.post(f"{url}/compute"))
    return url


def test_saving_over_a_slot_of_another_kind_asks_first(client):
    """BASE 5 holds the fixed tool "PED SEALER" (typed in): an Offset saved there is refused
    with a 409 naming its kind and name; nothing is written; confirmed, the slot becomes a
    turntable base with a name of its own (not "PED SEALER")."""
    ok(edit_slot(client, f"{C}/bases/5", {"name": "PED SEALER", "kind": "fixed_tool",
                                          "pose": {"x": 900, "y": 0, "z": 400}}))
    url = _offset_into_base5(client)
    r = client.post(f"{url}/save")
    assert r.status_code == 409, r.text
    d = r.json()["detail"][0]
    assert d["loc"] == ["query", "confirm"]
    assert "BASE 5 holds a fixed tool 'PED SEALER'" in d["msg"] and "confirm=true" in d["msg"]
    slot = ok(client.get(f"{C}/bases/5"))
    assert (slot["kind"], slot["name"], slot["pose"]["x"]) == ("fixed_tool", "PED SEALER", 900)
    assert ok(client.get(url))["state"] == "computed"
    saved = ok(client.post(f"{url}/save", params={"confirm": "true"}))
    assert saved["kind"] == "coordinated_base" and saved["name"] == "coordinated_base5"


def test_a_confirmed_save_may_name_the_slot(client):
    ok(edit_slot(client, f"{C}/bases/5", {"name": "PED SEALER", "kind": "fixed_tool"}))
    url = _offset_into_base5(client)
    saved = ok(client.post(f"{url}/save", params={"confirm": "true", "name": "TABLE PLATE"}))
    assert saved["name"] == "TABLE PLATE" and saved["kind"] == "coordinated_base"


def test_a_named_slot_typed_in_asks_and_keeps_its_name(client):
    """TOOL 2 "GRIPPER" typed in by hand: XYZ 4-point into it asks; confirmed, it keeps its
    name. Calibrated again afterwards (a menu wrote it), it is not asked again."""
    ok(edit_slot(client, f"{C}/tools/2", {"name": "GRIPPER", "pose": {"x": 1, "y": 2, "z": 150}}))
    url = open_session(client, "tool.xyz_4point", 2)
    walk(client, url)
    ok(client.post(f"{url}/compute"))
    r = client.post(f"{url}/save")
    assert r.status_code == 409 and "TOOL 2 holds the tool 'GRIPPER'" in r.json()["detail"][0]["msg"]
    assert ok(client.post(f"{url}/save", params={"confirm": "true"}))["name"] == "GRIPPER"
    _, slot = calibrate(client, "tool.abc_2point", 2)
    assert slot["name"] == "GRIPPER"


def test_an_empty_slot_and_a_recalibration_are_not_asked(client):
    calibrate(client, "tool.xyz_4point", 3)
    _, slot = calibrate(client, "tool.xyz_4point", 3)
    assert slot["name"] == "tool3"
