"""External kinematics menus through HTTP, as a person walks them on the demo cell-1 (E1
turntable, E2/E3 positioner, E4 rail): jog the axes, Root point, Offset, Linear unit,
Positioner; every hidden error of the emulated machines recovered and named; degenerate
teaching refused naming the field; save, history, restore, If-Match; who may do what."""

from __future__ import annotations

import numpy as np
import pytest

from api_helpers import *  # noqa: F403
from api_helpers import (ADMIN_TOKEN, C, CELL, approach, calibrate, edit_slot, make_client, ok,
                         open_session, pose_matrix, restore_slot)
from emulator import external as ext_emu
from solvers.robots import ROBOTS

REACH = ROBOTS["kuka_kr6_r900_sixx"].reach_mm
EXT = f"{C}/external-kinematics"


def truth(client) -> ext_emu.ExternalCell:  # noqa: ANN001
    """The emulated machines as they really are (for the asserts only)."""
    return ext_emu.external_cell(REACH, ok(client.get(f"{C}/cell/external")), 1)


def move_external(client, values: dict) -> dict:  # noqa: ANN001
    return ok(client.put(f"{C}/robot/external", json={"values": values}))


def teach(client, url: str, extra: int = 0, noise_mm: float = 0.0,  # noqa: ANN001
          miss: dict | None = None) -> dict:
    """Every required step (and ``extra`` optional ones) as the prompt says: move the external
    axes, approach the mark, touch up. ``miss`` = {step: miss vector} for sloppy touch-ups."""
    s = ok(client.get(url))
    n = len(s["steps"]) + extra
    for k in range(n):
        st = s["steps"][k] if k < len(s["steps"]) else None
        if st is None:  # the next optional step: touch up once to learn its prompt
            break
        teach_step(client, url, st, noise_mm, (miss or {}).get(k))
        s = ok(client.get(url))
    for k in range(extra):
        nxt = _optional_step(client, url, len(s["steps"]))
        teach_step(client, url, nxt, noise_mm, (miss or {}).get(len(s["steps"])))
        s = ok(client.get(url))
    return s


def _optional_step(client, url: str, index: int) -> dict:  # noqa: ANN001
    """Optional step ``index``'s prompt and axis values (from the menu's own list)."""
    method = ok(client.get(url))["method"]
    spec = next(m for m in ok(client.get("/methods")) if m["name"] == method)
    from server.methods import METHODS
    st = METHODS[method].extra_step(index - len(spec["steps"]))
    return {"index": index, "target": st.target, "tilt_deg": st.tilt_deg,
            "around_deg": st.around_deg, "spin_deg": 0.0, "tool_point_mm": None,
            "external_axes": dict(st.external_axes or ())}


def teach_step(client, url: str, st: dict, noise_mm: float = 0.0,  # noqa: ANN001
               miss: list | None = None) -> dict:
    if st.get("external_axes"):
        move_external(client, st["external_axes"])
    kw = {"tilt_deg": st["tilt_deg"], "around_deg": st["around_deg"], "noise_mm": noise_mm}
    if miss is not None:
        kw["miss_mm"] = miss
    approach(client, st["target"], **kw)
    return ok(client.post(f"{url}/touch-up", json={"step": st["index"]}))


@pytest.fixture
def pointer(client):  # noqa: ANN001
    """Tool 1: the mounted pointer, XYZ 4-point calibrated (the touching tool)."""
    calibrate(client, "tool.xyz_4point", 1)
    return 1


# ----------------------------------------------------------------------------- jogging

def test_the_demo_cell_has_four_external_axes_jogged_in_joint_mode(client):
    robot = ok(client.get(f"{C}/robot"))
    assert robot["external_axes"] == {"E1": 0.0, "E2": 0.0, "E3": 0.0, "E4": 0.0}
    after = ok(client.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "E1",
                                                   "increment": 10.0}))
    assert after["external_axes"]["E1"] == 10.0 and after["joints_deg"] == robot["joints_deg"]
    r = client.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "E2", "increment": 100.0})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "increment"]
    assert "E2" in r.json()["detail"][0]["msg"] and "limit" in r.json()["detail"][0]["msg"]
    r = client.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "E5", "increment": 1.0})
    assert r.status_code == 422 and "E5" in r.json()["detail"][0]["msg"]
    slots = ok(client.get(EXT))
    assert [(s["kind"], s["axes"]) for s in slots[:4]] == [
        ("turntable", ["E1"]), ("positioner", ["E2", "E3"]), ("linear_unit", ["E4"]), ("none", [])]


def test_a_controller_without_external_axes_refuses_an_e_jog(client):
    ok(client.post("/controllers", json={"name": "plain"}))
    r = client.post("/controllers/2/robot/jog", json={"mode": "joint", "axis": "E1",
                                                      "increment": 1.0})
    assert r.status_code == 422 and "no external axes" in r.json()["detail"][0]["msg"]


def test_the_mark_turns_with_e1_and_the_rail_carries_the_robot(client, pointer):
    """Move to the table's mark at E1 = 0 and 90: the TCP (robot base) is 90 deg around."""
    ok(client.put(f"{C}/robot/active", json={"tool_no": 1}))
    approach(client, "turntable_mark", tilt_deg=10.0)
    p0 = np.array([ok(client.get(f"{C}/robot"))["tcp_pose"][k] for k in "xyz"])
    move_external(client, {"E1": 90.0})
    approach(client, "turntable_mark", tilt_deg=10.0)
    p1 = np.array([ok(client.get(f"{C}/robot"))["tcp_pose"][k] for k in "xyz"])
    c = truth(client).turntable.true_root_frame(truth(client).mark_flange("turntable"))[:3, 3]
    a, b = p0 - c, p1 - c
    assert np.degrees(np.arccos(a @ b / np.linalg.norm(a) / np.linalg.norm(b))) == \
        pytest.approx(90.0, abs=0.3)
    move_external(client, {"E1": 0.0, "E4": 200.0})
    approach(client, "turntable_mark", tilt_deg=10.0)
    p2 = np.array([ok(client.get(f"{C}/robot"))["tcp_pose"][k] for k in "xyz"])
    assert (p2 - p0)[0] == pytest.approx(-200.0, abs=5.0)  # the robot rode +x: the mark is -x


# -------------------------------------------------------------------------- root point

ERRORS = {
    "axis_tilted": {"turntable": {"tilt_deg": 1.0}},
    "root_offset": {"turntable": {"root_offset_mm": 3.0}},
    "sign_reversed": {"turntable": {"sign": -1}},
    "scale_off": {"turntable": {"scale": 1.01}},
}


def set_errors(client, doc: dict) -> None:  # noqa: ANN001
    ok(client.put(f"{C}/cell/external", json=doc))


@pytest.mark.parametrize("code", list(ERRORS))
def test_root_point_recovers_the_axis_and_names_the_hidden_error(client, pointer, code):
    """Root point, 3 required + 2 optional positions with a person's aim (0.05 mm): the true
    centre and axis lie inside the 95 % bounds, and the injected error is named."""
    set_errors(client, ERRORS[code])
    url = open_session(client, "ext.root_point", 1, tool_no=1)
    s = teach(client, url, extra=2, noise_mm=0.05)
    assert [st["external_axes"] for st in s["steps"]][:3] == [{"E1": -135.0}, {"E1": -45.0},
                                                              {"E1": 45.0}]
    assert s["steps"][0]["point"]["external_axes"]["E1"] == -135.0
    report = ok(client.post(f"{url}/compute"))
    codes = [w["code"] for w in report["warnings"]]
    assert code in codes, report["warnings"]
    table = truth(client).turntable
    T_true = table.true_root_frame(truth(client).mark_flange("turntable"))
    T = pose_matrix(report["frame"])
    # the tool's TCP is the XYZ 4-point's (sub-0.1 mm), so allow its error on top of the bound
    assert np.linalg.norm(T[:3, 3] - T_true[:3, 3]) < report["position_bound95_mm"] + 0.3
    axis_err = np.degrees(np.arccos(np.clip(T[:3, 2] @ T_true[:3, 2], -1, 1)))
    assert axis_err < report["angle_bound95_deg"] + 0.05
    assert len(report["extras"]["top_view"]["points_mm"]) == 5
    slot = ok(client.post(f"{url}/save"))
    assert slot["provenance"]["method"] == "ext.root_point" and slot["number"] == 1


def test_root_point_with_no_error_names_nothing(client, pointer):
    set_errors(client, {})
    url = open_session(client, "ext.root_point", 1, tool_no=1)
    teach(client, url, extra=1)
    report = ok(client.post(f"{url}/compute"))
    assert [w["code"] for w in report["warnings"]] == []
    assert "touch the mark at axis value" in report["guidance"]


# --------------------------------------------------------------------- degenerate teaching

def test_fewer_than_three_positions_are_refused(client, pointer):
    url = open_session(client, "ext.root_point", 1, tool_no=1)
    s = ok(client.get(url))
    for st in s["steps"][:2]:
        teach_step(client, url, st)
    r = client.post(f"{url}/compute")
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "points", 2]
    assert "step 3 is not taught yet" in r.json()["detail"][0]["msg"]


def test_axis_positions_closer_than_10_deg_are_refused(client, pointer):
    url = open_session(client, "ext.root_point", 1, tool_no=1)
    s = ok(client.get(url))
    teach_step(client, url, s["steps"][0])
    teach_step(client, url, {**s["steps"][1], "external_axes": {"E1": -130.0}})
    teach_step(client, url, s["steps"][2])
    r = client.post(f"{url}/compute")
    assert r.status_code == 422
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "points", 1, "external_axes", "E1"]
    assert "at least 10 deg apart" in d["msg"]


def test_a_mark_on_the_axis_is_refused(client, pointer):
    """Touch one spot that does not move (the table's centre, roughly): the mark is on the axis."""
    url = open_session(client, "ext.root_point", 1, tool_no=1)
    s = ok(client.get(url))
    table = truth(client).turntable
    centre = table.root[:3, 3]
    for st in s["steps"]:
        move_external(client, st["external_axes"])
        approach(client, "reference_tip", tilt_deg=10.0,
                 miss_mm=(centre - CELL.reference_tip_mm).tolist())
        ok(client.post(f"{url}/touch-up", json={"step": st["index"]}))
    r = client.post(f"{url}/compute")
    assert r.status_code == 422
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "points"] and "on the axis" in d["msg"]


def test_collinear_marks_are_refused(client, pointer):
    """A fixed mark touched while the rail (not the table) moved: the touch-ups lie on a line."""
    url = open_session(client, "ext.root_point", 1, tool_no=1)
    s = ok(client.get(url))
    for st, e4 in zip(s["steps"], (-200.0, 0.0, 200.0)):
        move_external(client, {**st["external_axes"], "E4": e4})
        approach(client, "rail_mark", tilt_deg=10.0)
        ok(client.post(f"{url}/touch-up", json={"step": st["index"]}))
    r = client.post(f"{url}/compute")
    assert r.status_code == 422
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "points"] and "lie on one line" in d["msg"]
