"""External kinematics menus through HTTP, as a person walks them on the demo cell-1 (E1
turntable, E2/E3 positioner, E4 rail): jog the axes, Root point, Offset, Linear unit,
Positioner; every hidden error of the emulated machines recovered and named; degenerate
teaching refused naming the field; save, history, restore, If-Match; who may do what."""

from __future__ import annotations

import json

import numpy as np
import pytest

from api_helpers import (ADMIN_TOKEN, C, CELL, approach, calibrate, edit_slot, ok, open_session,
                        pose_matrix, restore_slot)
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
    from server.menus import METHODS
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
    targets = set(ok(client.get(f"{C}/cell"))["targets"])
    assert {"turntable_mark", "positioner_mark", "rail_mark"} <= targets
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


def bound99(bound95: float, k: int, dof: int) -> float:
    """A 95 % bound of ``k`` dof with sigma from ``dof`` residual dof, widened to 99 %: one
    walk is one trial (the >= 95 % coverage over 200 trials is tests/test_solver_external.py's),
    so a single seeded walk is held to the bound it misses 1 % of the time."""
    from scipy import stats

    return bound95 * float(np.sqrt(stats.f.ppf(0.99, k, dof) / stats.f.ppf(0.95, k, dof)))


def set_errors(client, doc: dict) -> None:  # noqa: ANN001
    ok(client.put(f"{C}/cell/external", json=doc))


@pytest.mark.parametrize("code", list(ERRORS))
def test_root_point_recovers_the_axis_and_names_the_hidden_error(client, pointer, code):
    """Root point, 3 required + 2 optional positions with a person's aim (0.05 mm): the true
    centre and axis lie inside their bounds (:func:`bound99`), and the injected error is named."""
    set_errors(client, ERRORS[code])
    url = open_session(client, "ext.root_point", 1, tool_no=1)
    s = teach(client, url, extra=2, noise_mm=0.05)
    assert [st["external_axes"] for st in s["steps"]][:3] == [
        {"E1": -135.0, "E4": 0.0}, {"E1": -45.0, "E4": 0.0}, {"E1": 45.0, "E4": 0.0}]
    assert s["steps"][0]["point"]["external_axes"]["E1"] == -135.0
    report = ok(client.post(f"{url}/compute"))
    codes = [w["code"] for w in report["warnings"]]
    assert code in codes, report["warnings"]
    table = truth(client).turntable
    T_true = table.true_root_frame(truth(client).mark_flange("turntable"))
    T = pose_matrix(report["frame"])
    # the touching TCP is the XYZ 4-point's with the ideal aim (error < 1e-3 mm)
    dof = report["extras"]["dof"]
    assert np.linalg.norm(T[:3, 3] - T_true[:3, 3]) < \
        bound99(report["position_bound95_mm"], 3, dof) + 0.001
    axis_err = np.degrees(np.arccos(np.clip(T[:3, 2] @ T_true[:3, 2], -1, 1)))
    assert axis_err < bound99(report["angle_bound95_deg"], 2, dof)
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
    """A fixed mark touched while the rail (not the table) moved: in the robot base the
    touch-ups lie on a line; with the rail not calibrated they are refused naming the rail
    (its machine data cannot put them in one frame)."""
    url = open_session(client, "ext.root_point", 1, tool_no=1)
    s = ok(client.get(url))
    for st, e4 in zip(s["steps"], (-200.0, 0.0, 200.0)):
        move_external(client, {**st["external_axes"], "E4": e4})
        approach(client, "rail_mark", tilt_deg=10.0)
        ok(client.post(f"{url}/touch-up", json={"step": st["index"]}))
    r = client.post(f"{url}/compute")
    assert r.status_code == 422
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "points", 1, "external_axes", "E4"]
    assert "rail E4 (EX_KIN 3 TRACK) is not calibrated" in d["msg"]


# ------------------------------------------------------------------------------ offset

def test_root_point_then_offset_puts_a_base_on_the_table(client, pointer):
    """Root point -> save EX_KIN 1; Offset: the plate on the table touched at E1 = 30 deg ->
    BASE 5, a coordinated base on TURNTABLE, in the table's flange frame; its bounds carry the
    root's uncertainty and hold the truth."""
    set_errors(client, {"turntable": {"tilt_deg": 0.7, "root_offset_mm": 2.0}})
    url = open_session(client, "ext.root_point", 1, tool_no=1)
    teach(client, url, extra=2, noise_mm=0.05)
    ok(client.post(f"{url}/compute"))
    root_slot = ok(client.post(f"{url}/save"))
    url = open_session(client, "ext.offset", 5, tool_no=1, ext_no=1)
    s = teach(client, url, noise_mm=0.05)
    assert [st["target"] for st in s["steps"]] == ["turntable_base_origin", "turntable_base_x",
                                                   "turntable_base_xy"]
    report = ok(client.post(f"{url}/compute"))
    base = ok(client.post(f"{url}/save"))
    assert base["kind"] == "coordinated_base" and base["mech_unit"] == "TURNTABLE"
    t = truth(client)
    T_root = pose_matrix(root_slot["root"])
    plate_world = t.turntable.flange([30.0])[0] @ t.T_flange_plate
    # the plate in the calibrated flange frame (the root point's frame turned by 30 deg)
    T_root_true = t.turntable.true_root_frame(t.mark_flange("turntable"))
    from solvers.external.common import rz
    expected = np.linalg.inv(T_root_true @ rz([30.0])[0]) @ plate_world
    T = pose_matrix(base["pose"])
    assert np.linalg.norm(T[:3, 3] - expected[:3, 3]) < bound99(report["position_bound95_mm"], 3, 4)
    # and the calibrated frames put the base where it is at another axis value
    at_90 = T_root @ rz([90.0])[0] @ T
    true_90 = t.turntable.flange([90.0])[0] @ t.T_flange_plate
    assert np.linalg.norm(at_90[:3, 3] - true_90[:3, 3]) < 1.0


def test_offset_touched_at_two_axis_positions_is_refused(client, pointer):
    url = open_session(client, "ext.offset", 5, tool_no=1, ext_no=1)
    s = ok(client.get(url))
    teach_step(client, url, s["steps"][0])
    teach_step(client, url, {**s["steps"][1], "external_axes": {"E1": 40.0}})
    teach_step(client, url, s["steps"][2])
    r = client.post(f"{url}/compute")
    assert r.status_code == 422
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "points", 1, "external_axes", "E1"]
    assert "one axis position" in d["msg"]


def test_offset_on_a_rail_or_an_empty_slot_is_refused_at_open(client, pointer):
    for ext_no, words in ((4, "not configured"), (3, "is a linear_unit")):
        r = client.post(f"{C}/sessions", json={"method": "ext.offset", "target_no": 5,
                                               "params": {"ext_no": ext_no, "tool_no": 1}})
        assert r.status_code == 422
        d = r.json()["detail"][0]
        assert d["loc"] == ["body", "params", "ext_no"] and words in d["msg"]


@pytest.mark.parametrize("method, target_no, words", [
    ("ext.root_point", 3, "ext.root_point calibrates a turntable or a positioner"),
    ("ext.linear_unit", 1, "ext.linear_unit calibrates a linear_unit"),
    ("ext.positioner_2axis", 1, "ext.positioner_2axis calibrates a positioner")])
def test_a_menu_on_the_wrong_kind_of_kinematic_is_refused_at_open(client, pointer, method,
                                                                  target_no, words):
    r = client.post(f"{C}/sessions", json={"method": method, "target_no": target_no,
                                           "params": {"tool_no": 1}})
    assert r.status_code == 422
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "target_no"] and words in d["msg"]


def test_root_point_of_the_positioner_turn_axis_rides_on_its_tilt(client, pointer):
    """Root point on EX_KIN 2 with ``axis: E3``, taught at tilt E2 = 30: the nominal turn axis
    it compares with is the machine data's turned by the tilt, so only the hidden turn-axis
    tilt is named."""
    set_errors(client, {"positioner": {"turn_tilt_deg": 1.0}})
    url = open_session(client, "ext.root_point", 2, tool_no=1, axis="E3")
    for k, e3 in enumerate((-135.0, -45.0, 45.0, 135.0)):
        move_external(client, {"E2": 30.0, "E3": e3})
        approach(client, "positioner_mark", tilt_deg=10.0)
        ok(client.post(f"{url}/touch-up", json={"step": k}))
    report = ok(client.post(f"{url}/compute"))
    codes = [w["code"] for w in report["warnings"]]
    assert "axis_tilted" in codes and "sign_reversed" not in codes, report["warnings"]
    assert report["extras"]["axis_tilt_deg"] == pytest.approx(1.0, abs=0.1)


def test_numeric_root_point_and_offset(client):
    url = open_session(client, "ext.root_point_numeric", 1,
                       pose={"x": 520, "y": 380, "z": 80, "a": 0, "b": 0, "c": 0})
    ok(client.post(f"{url}/compute"))
    slot = ok(client.post(f"{url}/save"))
    assert slot["root"]["x"] == pytest.approx(520.0) and slot["kind"] == "turntable"
    url = open_session(client, "ext.offset_numeric", 6, ext_no=1,
                       pose={"x": 10, "y": 20, "z": 0, "a": 45, "b": 0, "c": 0})
    ok(client.post(f"{url}/compute"))
    base = ok(client.post(f"{url}/save"))
    assert base["kind"] == "coordinated_base" and base["pose"]["a"] == pytest.approx(45.0)


# ------------------------------------------------------------------------- linear unit

@pytest.mark.parametrize("errors, code", [
    ({"rail": {"direction_tilt_deg": 1.0}}, "direction_wrong"),
    ({"rail": {"sign": -1}}, "sign_reversed"),
    ({"rail": {"scale": 1.005}}, "scale_off"),
])
def test_linear_unit_recovers_direction_and_scale(client, pointer, errors, code):
    """The robot rides the rail to 5 positions and touches one fixed mark each time."""
    set_errors(client, errors)
    url = open_session(client, "ext.linear_unit", 3, tool_no=1)
    teach(client, url, extra=2, noise_mm=0.05)
    report = ok(client.post(f"{url}/compute"))
    assert code in [w["code"] for w in report["warnings"]], report["warnings"]
    rail = truth(client).rail
    d = np.array(report["extras"]["travel_direction"])
    assert np.degrees(np.arccos(np.clip(d @ rail.travel_in_base, -1, 1))) < \
        bound99(report["angle_bound95_deg"], 2, 9)
    scale_b = bound99(report["extras"]["scale_bound95"], 1, 9)
    assert abs(report["extras"]["scale"] - rail.scale) < scale_b
    slot = ok(client.post(f"{url}/save"))
    assert pose_matrix(slot["root"])[:3, 2] == pytest.approx(d, abs=1e-6)
    assert slot["scale"] == pytest.approx(report["extras"]["scale"])


# -------------------------------------------------------------------------- positioner

def test_positioner_axis_by_axis_names_axes_that_miss_each_other(client, pointer):
    set_errors(client, {"positioner": {"axis_offset_mm": 3.0, "turn_tilt_deg": 0.0}})
    url = open_session(client, "ext.positioner_2axis", 2, tool_no=1)
    s = teach(client, url, noise_mm=0.05)
    assert len(s["steps"]) == 8 and s["steps"][4]["external_axes"] == {"E2": 0.0, "E3": -135.0,
                                                                       "E4": 0.0}
    report = ok(client.post(f"{url}/compute"))
    assert "axes_do_not_intersect" in [w["code"] for w in report["warnings"]]
    L_true, angle_true = truth(client).positioner.true_axes()
    ex = report["extras"]
    assert abs(ex["common_normal_mm"] - L_true) < bound99(ex["common_normal_bound95_mm"], 1, 2)
    assert abs(ex["axes_angle_deg"] - angle_true) < bound99(ex["axes_angle_bound95_deg"], 1, 2)
    slot = ok(client.post(f"{url}/save"))
    assert slot["kind"] == "positioner" and slot["axes"] == ["E2", "E3"]
    assert pose_matrix(slot["flange"])[:3, 3] == pytest.approx(
        pose_matrix(report["frame"])[:3, 3], abs=1e-3)


def test_positioner_names_a_reversed_tilt_axis(client, pointer):
    set_errors(client, {"positioner": {"sign": -1}})
    url = open_session(client, "ext.positioner_2axis", 2, tool_no=1)
    teach(client, url)
    report = ok(client.post(f"{url}/compute"))
    assert any(w["code"] == "sign_reversed" and w["message"].startswith("tilt axis")
               for w in report["warnings"]), report["warnings"]


# -------------------------------------------------------------- save, history, If-Match

def test_save_history_and_restore_of_an_external_kinematic(client):
    before = ok(client.get(f"{EXT}/1"))
    url = open_session(client, "ext.root_point_numeric", 1,
                       pose={"x": 500, "y": 400, "z": 90, "a": 10, "b": 0, "c": 0})
    ok(client.post(f"{url}/compute"))
    ok(client.post(f"{url}/save"))
    hist = ok(client.get(f"{EXT}/1/history"))
    assert hist[-1]["reason"] == "calibration" and hist[-1]["table"] == "extkin"
    assert hist[-1]["after"]["x_mm"] == 500.0
    r = client.post(f"{EXT}/1/restore/{hist[-1]['id']}")
    assert r.status_code == 428
    r = client.post(f"{EXT}/1/restore/{hist[-1]['id']}", headers={"If-Match": '"999"'})
    assert r.status_code == 412 and r.json()["current"]["root"]["x"] == 500.0
    restored = ok(restore_slot(client, f"{EXT}/1", hist[-1]["id"]))
    assert restored["root"] == before["root"]
    assert ok(client.get(f"{EXT}/1/history"))[-1]["reason"] == "restore"
    audit = ok(client.get("/audit", params={"controller_id": 1}))
    actions = [a["action"] for a in (audit["records"] if isinstance(audit, dict) else audit)]
    assert "frame.calibration" in actions and "frame.restore" in actions


def test_edit_by_hand_needs_if_match(client):
    r = client.put(f"{EXT}/4", json={"kind": "turntable", "axes": ["E5"]})
    assert r.status_code == 428
    slot = ok(edit_slot(client, f"{EXT}/4", {"kind": "turntable", "axes": ["E5"], "name": "TT2",
                                             "root": {"x": 100}}))
    assert slot["kind"] == "turntable" and slot["axes"] == ["E5"] and slot["name"] == "TT2"
    assert slot["root"]["x"] == 100.0 and slot["provenance"]["method"] == "numeric"


@pytest.mark.parametrize("body, words", [
    ({"kind": "positioner", "axes": ["E5"]}, "a positioner moves 2 distinct external axes"),
    ({"kind": "turntable", "axes": ["E1"]}, "E1 already moves external kinematic 1"),
])
def test_edit_refuses_axes_that_do_not_fit(client, body, words):
    r = edit_slot(client, f"{EXT}/4", body)
    assert r.status_code == 422
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "axes"] and words in d["msg"]


def test_save_refuses_a_slot_changed_after_compute(client):
    url = open_session(client, "ext.root_point_numeric", 1, pose={"x": 500})
    ok(client.post(f"{url}/compute"))
    ok(edit_slot(client, f"{EXT}/1", {"name": "TABLE"}))
    r = client.post(f"{url}/save")
    assert r.status_code == 409 and "changed after" in r.json()["detail"][0]["msg"]


def test_frame_committed_event_for_an_external_kinematic(client):
    url = open_session(client, "ext.root_point_numeric", 1, pose={"x": 510})
    ok(client.post(f"{url}/compute"))
    ok(client.post(f"{url}/save"))
    from db.models import Event
    from sqlalchemy import select
    with client.app.state.sessionmaker() as db:
        ev = db.scalars(select(Event).where(Event.kind == "frame-committed")).all()[-1]
        assert ev.payload["table"] == "extkin" and ev.payload["x_mm"] == 510.0


# ------------------------------------------------------------------------- permissions

def test_operator_may_jog_e_axes_but_not_calibrate_or_save(client):
    tokens = {}
    for role in ("Operator", "Programmer", "Expert"):
        ok(client.post("/users", json={"name": role.lower(), "role": role}))
        tokens[role] = ok(client.post(f"/users/{role.lower()}/tokens", json={}))["token"]

    def as_(role: str) -> dict:
        return {"Authorization": f"Bearer {tokens[role]}"}

    jog = {"mode": "joint", "axis": "E1", "increment": 5.0}
    assert client.post(f"{C}/robot/jog", json=jog, headers=as_("Operator")).status_code == 200
    body = {"method": "ext.root_point_numeric", "target_no": 1, "params": {"pose": {"x": 1}}}
    assert client.post(f"{C}/sessions", json=body, headers=as_("Operator")).status_code == 403
    s = client.post(f"{C}/sessions", json=body, headers=as_("Programmer")).json()
    url = f"{C}/sessions/{s['id']}"
    assert client.post(f"{url}/compute", headers=as_("Programmer")).status_code == 200
    assert client.post(f"{url}/save", headers=as_("Programmer")).status_code == 403
    assert client.post(f"{url}/save", headers=as_("Expert")).status_code == 200
    etag = client.get(f"{EXT}/2").headers["ETag"]
    r = client.put(f"{EXT}/2", json={"name": "P"}, headers={**as_("Operator"), "If-Match": etag})
    assert r.status_code == 403
    r = client.put(f"{EXT}/2", json={"name": "P"}, headers={**as_("Expert"), "If-Match": etag})
    assert r.status_code == 200 and r.json()["provenance"]["updated_by"] == "expert"
    assert client.put(f"{C}/cell/external", json={},
                      headers=as_("Expert")).status_code == 403  # the truth: emulator:physics


# --------------------------------------------------------------------------------- CLI

def test_cli_calibrates_the_root_point_from_a_csv_with_e1(capsys):
    """docs/examples/turntable.csv: the demo table's mark at five E1 values (benchmarks/
    examples.py); the report names the table's seeded tilt."""
    from pathlib import Path

    from server.cli.main import main

    f = Path(__file__).resolve().parent.parent / "docs" / "examples" / "turntable.csv"
    tcp = ",".join(f"{v:.4f}" for v in CELL.T_flange_tool[:3, 3])
    assert main(["calibrate", "ext.root_point", str(f), "--tcp", tcp, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    table = ext_emu.external_cell(REACH, None, 1).turntable
    T_true = table.true_root_frame(ext_emu.external_cell(REACH, None, 1).mark_flange("turntable"))
    # one seeded sample (the 95 % coverage is the solver tests' 200 trials): within 0.1 mm
    assert np.linalg.norm(pose_matrix(report["frame"])[:3, 3] - T_true[:3, 3]) < 0.1
    tilt_true = np.degrees(np.arccos(table.axis[2]))
    assert abs(report["extras"]["axis_tilt_deg"] - tilt_true) < report["angle_bound95_deg"]
    assert [w["code"] for w in report["warnings"]] == ["axis_tilted"]


def test_cli_reads_a_point_without_its_axis_value_as_a_named_error(tmp_path, capsys):
    from server.cli.main import main

    f = tmp_path / "t.json"
    f.write_text(json.dumps({"points": [{"x": 0, "y": 0, "z": 0, "a": 0, "b": 0, "c": 0}] * 3,
                             "inputs": {"tcp_mm": [0, 0, 100]}}))
    assert main(["calibrate", "ext.root_point", str(f)]) == 2
    assert "points.0.external_axes.E1" in capsys.readouterr().err


def test_cli_slot_edits_an_external_kinematic_with_if_match(db_url, capsys, monkeypatch):
    import httpx

    from browser_helpers import serve
    from server.cli.main import main

    monkeypatch.setenv("PENDANT_TOKEN", ADMIN_TOKEN)
    auth = {"Authorization": f"Bearer {ADMIN_TOKEN}"}
    with serve(db_url) as url:
        first = httpx.get(f"{url}{EXT}/1", headers=auth).headers["ETag"]
        assert main(["slot", "ext", "1", "--url", url, "--pose", "521,380,80,0,0,0"]) == 0
        assert "ext 1 'TURNTABLE' (turntable: E1)" in capsys.readouterr().out
        assert main(["slot", "ext", "1", "--url", url, "--name", "late", "--etag", first]) == 3
        assert "changed since it was read" in capsys.readouterr().err
        assert httpx.get(f"{url}{EXT}/1", headers=auth).json()["root"]["x"] == 521.0


# ------------------------------------------------------------------------------ export

def test_root_point_and_offset_are_exported_for_kuka_and_abb(client, pointer):
    """After Root point -> EX_KIN 1 and Offset -> BASE 5: the KUKA machine data carry the
    calibrated root as $ET1_TA1KR's chain (read back to 1e-6 mm) and the base on it with its
    MACHINE_FRAME_DAT; the ABB MOC.cfg carries the unit's base frame."""
    from server.formats.external import read_abb_external, read_kuka_external

    url = open_session(client, "ext.root_point", 1, tool_no=1)
    teach(client, url, extra=1)
    ok(client.post(f"{url}/compute"))
    root = pose_matrix(ok(client.post(f"{url}/save"))["root"])
    url = open_session(client, "ext.offset", 5, tool_no=1, ext_no=1)
    teach(client, url)
    ok(client.post(f"{url}/compute"))
    base = ok(client.post(f"{url}/save"))
    r = client.get(f"{C}/export", params={"format": "kuka_machine"})
    assert r.status_code == 200 and "external-kinematics.dat" in r.headers["content-disposition"]
    machine, config = r.text.split("; ---- KRC:\\R1\\System\\$config.dat ----")
    setup = read_kuka_external(machine, config)
    table = next(k for k in setup.kinematics if k.name == "TURNTABLE")
    assert table.kind == "turntable" and table.axes == ("E1",)
    assert table.root.as_matrix()[:3, 3] == pytest.approx(root[:3, 3], abs=1e-6)
    (b,) = [b for b in setup.bases if b.number == 5]
    assert b.mech_unit == "TURNTABLE"
    assert b.pose.as_array()[:3] == pytest.approx([base["pose"][k] for k in "xyz"], abs=1e-6)
    assert "POSITIONER" in r.text and "#ERSYS" in r.text  # EX_KIN 2 and the rail, machine data
    moc = client.get(f"{C}/export", params={"format": "abb_moc"}).text
    units = read_abb_external(moc).kinematics
    assert any(k.root.as_matrix()[:3, 3] == pytest.approx(root[:3, 3], abs=1e-3) for k in units)
    from server.cli.main import main  # the CLI exports the same text
    assert main(["export", "cell-1", "--format", "kuka_machine", "--db",
                 str(client.app.state.settings.db_url)]) == 0


def test_a_json_backup_keeps_the_external_kinematics_and_restores_them(client, pointer):
    """Root point saved into EX_KIN 1 (its history, the touch-ups' E1 values), then a backup,
    a change, and the restore: everything comes back."""
    from api_helpers import finish_job

    url = open_session(client, "ext.root_point", 1, tool_no=1)
    teach(client, url)
    ok(client.post(f"{url}/compute"))
    saved = ok(client.post(f"{url}/save"))
    backup = client.get(f"{C}/export", params={"format": "json"}).text
    assert '"external_kinematics"' in backup
    ok(edit_slot(client, f"{EXT}/1", {"root": {"x": 1}}))
    job = finish_job(client, client.post(f"{C}/import", json={"format": "json", "text": backup}))
    assert job["state"] == "done", job
    slot = ok(client.get(f"{EXT}/1"))
    assert slot["root"] == saved["root"] and slot["provenance"]["method"] == "ext.root_point"
    assert [h["reason"] for h in ok(client.get(f"{EXT}/1/history"))] == ["calibration"]
    session = ok(client.get(f"{C}/sessions"))[-1]
    assert session["method"] == "ext.root_point"
    assert session["steps"][0]["point"]["external_axes"]["E1"] == -135.0


# ----------------------------------------------- coverage on the demo cell's own machines

def _menu_solve(method: str, ext: ext_emu.ExternalCell, number: int, touches, values: list[dict]):
    """Solve ``method`` as the session does (the menu's adapter, the slot's nominal machine
    data), from touch-ups made with external_sim's pointer (TCP 150 mm on z)."""
    from server.menus import METHODS
    from server.menus.methods import MethodInputs, TaughtData
    from server.menus.external import ExtInputs

    nominal = ext_emu.nominal_kinematics(ext)[number]
    inputs = MethodInputs(tcp_mm=touches.tool[:3, 3], external=ExtInputs(
        number, nominal["kind"], tuple(nominal["axes"]), nominal["root"], nominal["flange"]))
    points = [TaughtData(F, external_axes=v) for F, v in zip(touches.flange_poses, values)]
    return METHODS[method].solve(points, inputs, {})


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b),
                                              -1.0, 1.0))))


ROOT_VALUES = [-135.0, -45.0, 45.0, 135.0, 0.0]  # the menu's 3 steps and its first 2 optional


@pytest.mark.parametrize("errors, code", [
    ({}, None), ({"turntable": {"tilt_deg": 1.0}}, "axis_tilted"),
    ({"turntable": {"root_offset_mm": 3.0}}, "root_offset"),
    ({"turntable": {"sign": -1}}, "sign_reversed"), ({"turntable": {"scale": 1.01}}, "scale_off")])
def test_root_point_on_the_demo_turntable_covers_the_truth_in_200_trials(errors, code):
    """The acceptance of issue 13 on the emulated cell's own turntable (150 mm mark, 5 axis
    values of the menu, touch noise 0.05 mm): the true centre and axis inside the 95 % bounds
    in >= 93 % of 200 seeded trials, the injected error named in all of them, no other in more
    than 5 %."""
    from solvers.external_sim import touch

    ext = ext_emu.external_cell(REACH, errors, 1)
    table, mark = ext.turntable, ext.mark_flange("turntable")
    T_true = table.true_root_frame(mark)
    rng = np.random.default_rng(13)
    inside_c = inside_a = named = other = 0
    for _ in range(200):
        t = touch(table.mark(mark, ROOT_VALUES), ROOT_VALUES, 0.05, rng)
        res = _menu_solve("ext.root_point", ext, 1, t, [{"E1": v} for v in ROOT_VALUES])
        r = res.report
        inside_c += np.linalg.norm(res.frame[:3, 3] - T_true[:3, 3]) <= r.position_bound95_mm
        inside_a += _angle_deg(res.frame[:3, 2], T_true[:3, 2]) <= r.angle_bound95_deg
        codes = {w.code for w in r.warnings} - {"bad_point"}
        named += code is None or code in codes
        other += bool(codes - {code})
    assert inside_c >= 186 and inside_a >= 186, (inside_c, inside_a)
    assert named == 200 and other <= 10, (named, other)


@pytest.mark.parametrize("errors, code", [
    ({"rail": {"direction_tilt_deg": 1.0}}, "direction_wrong"),
    ({"rail": {"sign": -1}}, "sign_reversed"),
    ({"rail": {"scale": 1.005}}, "scale_off")])
def test_linear_unit_on_the_demo_rail_covers_the_truth_in_200_trials(errors, code):
    from solvers.external_sim import touch

    ext = ext_emu.external_cell(REACH, errors, 1)
    values = [-250.0, 0.0, 250.0, -125.0, 125.0]
    mark = np.asarray(ext_emu.RAIL_MARK_MM) * ext.scale
    truth_d, rng = ext.rail.travel_in_base, np.random.default_rng(17)
    inside_d = inside_k = named = 0
    for _ in range(200):
        t = touch(ext.rail.mark_in_base(mark, values), values, 0.05, rng)
        r = _menu_solve("ext.linear_unit", ext, 3, t, [{"E4": v} for v in values]).report
        inside_d += _angle_deg(r.extras["travel_direction"], truth_d) <= r.angle_bound95_deg
        inside_k += abs(r.extras["scale"] - ext.rail.scale) <= r.extras["scale_bound95"]
        named += code in {w.code for w in r.warnings}
    assert inside_d >= 186 and inside_k >= 186 and named == 200, (inside_d, inside_k, named)


@pytest.mark.parametrize("errors, code", [
    ({"positioner": {"axis_offset_mm": 3.0}}, "axes_do_not_intersect"),
    ({"positioner": {"tilt_deg": 1.0}}, "axis_tilted"),
    ({"positioner": {"turn_tilt_deg": 1.0}}, "axes_angle")])
def test_positioner_on_the_demo_positioner_covers_the_truth_in_200_trials(errors, code):
    """The demo positioner (4 + 4 positions) through the menu's adapter: the common normal and
    the angle between the axes inside their 95 % bounds within 3 binomial standard errors of
    95 % (>= 181 of 200), the error named in all 200. The bounds are the plain covariance's
    with the Welch-Satterthwaite dof (docs/methods/external.md); over 1000 trials (seed 5) the
    common normal's held 93.1 / 93.3 / 93.5 % and the angle's 95.7 % on this geometry, so
    >= 186 (93 %) of 200 would fail about half the seeds. (The old bounds, each root's share
    widened for its own dof, held 98-99.5 % and passed 186 easily.)"""
    from solvers.external_sim import touch

    ext = ext_emu.external_cell(REACH, errors, 1)
    pos, mark = ext.positioner, ext.mark_flange("positioner")
    tilt_v, turn_v = [-75.0, -25.0, 25.0, 75.0], [-135.0, -45.0, 45.0, 135.0]
    tilts, turns = tilt_v + [0.0] * 4, [0.0] * 4 + turn_v
    L_true, angle_true = pos.true_axes()
    rng = np.random.default_rng(19)
    inside_l = inside_a = named = 0
    for _ in range(200):
        t = touch(pos.mark(mark, tilts, turns), tilts, 0.05, rng)
        r = _menu_solve("ext.positioner_2axis", ext, 2, t,
                        [{"E2": a, "E3": b} for a, b in zip(tilts, turns)]).report
        ex = r.extras
        inside_l += abs(ex["common_normal_mm"] - L_true) <= ex["common_normal_bound95_mm"]
        inside_a += abs(ex["axes_angle_deg"] - angle_true) <= ex["axes_angle_bound95_deg"]
        named += code in {w.code for w in r.warnings}
    assert inside_l >= 181 and inside_a >= 181 and named == 200, (inside_l, inside_a, named)


def test_offset_on_the_demo_turntable_covers_the_truth_in_200_trials():
    """Root point (5 positions) then Offset (the plate on the table at E1 = 30), both through
    the menus' adapters on the emulated table tilted 1 deg and 3 mm off its root: the true
    T_flange_base (in the calibrated root's flange frame) inside both 95 % bounds in >= 93 %.
    The root's covariance, dof and sigma reach the Offset as the service passes them
    (``server.service.external.ext_inputs``: ``extras["dof"]`` or 0, ``sigma_mm``, which
    weighs the root's share at the touch sigma for the Welch-Satterthwaite dof), with the
    touch sigma the cell assumes (``assumed_sigma_mm``: here the 0.05 mm the touches have)."""
    from server.menus import METHODS
    from server.menus.methods import MethodInputs, TaughtData
    from server.menus.external import ExtInputs
    from solvers.external.common import rz
    from solvers.external_sim import touch
    from solvers.base import pose_difference

    ext = ext_emu.external_cell(REACH, {"turntable": {"tilt_deg": 1.0, "root_offset_mm": 3.0}}, 1)
    table, mark = ext.turntable, ext.mark_flange("turntable")
    plate = table.flange([30.0])[0] @ ext.T_flange_plate
    truth = np.linalg.inv(table.true_root_frame(mark) @ rz([30.0])[0]) @ plate
    corners = np.array([plate[:3, :3] @ (np.asarray(ext_emu.TABLE_PLATE_POINTS[k]) * ext.scale)
                        + plate[:3, 3] for k in ("origin", "x", "xy")])
    rng = np.random.default_rng(23)
    inside_p = inside_a = 0
    for _ in range(200):
        t = touch(table.mark(mark, ROOT_VALUES), ROOT_VALUES, 0.05, rng)
        rp = _menu_solve("ext.root_point", ext, 1, t, [{"E1": v} for v in ROOT_VALUES])
        tp = touch(corners, [30.0] * 3, 0.05, rng)
        inputs = MethodInputs(tcp_mm=tp.tool[:3, 3], touch_sigma_mm=0.05, external=ExtInputs(
            1, "turntable", ("E1",), rp.frame, root_covariance=rp.report.covariance,
            root_dof=int(rp.report.extras["dof"] or 0), root_sigma_mm=float(rp.report.sigma_mm)))
        res = METHODS["ext.offset"].solve([TaughtData(F, external_axes={"E1": 30.0})
                                           for F in tp.flange_poses], inputs, {})
        d = pose_difference(truth, res.frame)
        inside_p += np.linalg.norm(d[:3]) <= res.report.position_bound95_mm
        inside_a += np.linalg.norm(d[3:]) <= res.report.angle_bound95_deg
    assert inside_p >= 186 and inside_a >= 186, (inside_p, inside_a)


def test_docs_emulator_md_seed_1_hidden_errors():
    """docs/emulator.md, "External axes": cell seed 1's hidden errors as the page gives them
    (``pytest -s`` prints them)."""
    e = ext_emu.default_errors(1)
    print(f"\ndocs/emulator.md: {e}")
    assert e["turntable"]["tilt_deg"] == pytest.approx(0.773)
    assert e["turntable"]["root_offset_mm"] == pytest.approx(2.875)
    assert e["positioner"]["turn_tilt_deg"] == pytest.approx(0.212)
    assert e["positioner"]["axis_offset_mm"] == pytest.approx(1.111)
    assert e["rail"]["direction_tilt_deg"] == pytest.approx(0.387)
    assert e["rail"]["scale"] == pytest.approx(1.0024)
    assert ext_emu.default_errors(2) != e  # seeded by the cell
