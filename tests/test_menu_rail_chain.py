"""The robot on its rail (E4) in every menu's chain: world -> rail -> robot base -> flange -> tool.

The same hidden cell calibrated with the rail at 0 and at 100 or 250 mm gives the same frame
within the bound once the rail is calibrated (External kinematics > Linear unit); with the
rail not calibrated, touch-ups at different rail positions are refused naming the rail, and at
one position the report says what it assumed."""

from __future__ import annotations

import numpy as np
import pytest

from api_helpers import C, approach, calibrate, ok, open_session, pose_matrix

EXT = f"{C}/external-kinematics"


def move_external(client, values: dict) -> dict:  # noqa: ANN001
    return ok(client.put(f"{C}/robot/external", json={"values": values}))


def teach(client, url: str, rail_mm: float | None = None, noise_mm: float = 0.0,  # noqa: ANN001
          rails: dict | None = None) -> dict:
    """Every required step as its prompt says (its external axes, approach, touch up), with the
    rail E4 at ``rail_mm`` (or ``rails[step]``) instead of where the step would put it."""
    s = ok(client.get(url))
    for st in s["steps"]:
        axes = dict(st.get("external_axes") or {})
        e4 = (rails or {}).get(st["index"], rail_mm)
        if e4 is not None:
            axes["E4"] = e4
        if axes:
            move_external(client, axes)
        if st["target"]:
            kw = {k: st[k] for k in ("tilt_deg", "around_deg", "spin_deg")}
            if st["tool_point_mm"]:
                kw["tool_point_mm"] = st["tool_point_mm"]
            approach(client, st["target"], noise_mm=noise_mm, **kw)
        s = ok(client.post(f"{url}/touch-up", json={"step": st["index"]}))
    return s


def run(client, method: str, target_no: int, rail_mm: float | None = None,  # noqa: ANN001
        rails: dict | None = None, save: bool = False, **params) -> dict:
    url = open_session(client, method, target_no, **params)
    teach(client, url, rail_mm, rails=rails)
    report = ok(client.post(f"{url}/compute"))
    if save:
        ok(client.post(f"{url}/save"))
    return report


@pytest.fixture
def cell(client):  # noqa: ANN001
    """Tool 1 calibrated at E4 = 0 and the rail calibrated into EX_KIN 3 (ideal aim)."""
    move_external(client, {"E4": 0.0})
    calibrate(client, "tool.xyz_4point", 1)
    run(client, "ext.linear_unit", 3, save=True, tool_no=1)
    return client


#: menu -> (target slot, params); the menus that need a slot calibrated first get it at E4 = 0
MENUS = {
    "base.3point": (2, {"tool_no": 1}),
    "fixed_tool.6d": (6, {"tool_no": 1}),
    "workpiece.direct": (9, {"fixed_tool_no": 4}),
    "ext.root_point": (1, {"tool_no": 1}),
    "ext.offset": (5, {"tool_no": 1, "ext_no": 1}),
    "ext.positioner_2axis": (2, {"tool_no": 1}),
}


def _pos_err(a: dict, b: dict) -> float:
    return float(np.linalg.norm(pose_matrix(a["frame"])[:3, 3] - pose_matrix(b["frame"])[:3, 3]))


def _prepare(client, method: str) -> None:  # noqa: ANN001
    if method == "workpiece.direct":
        move_external(client, {"E4": 0.0})
        calibrate(client, "fixed_tool.6d", 4, tool_no=1)


@pytest.mark.parametrize("method", sorted(MENUS))
@pytest.mark.parametrize("rail_mm", [100.0, 250.0])
def test_the_same_frame_with_the_rail_anywhere(cell, method, rail_mm):
    """Taught at E4 = 0 and again at E4 = rail_mm: the same frame within the bound, and the
    report names the rail it went through and the terms of its bound."""
    target, params = MENUS[method]
    _prepare(cell, method)
    at0 = run(cell, method, target, 0.0, **params)
    moved = run(cell, method, target, rail_mm, **params)
    bound = max(moved["position_bound95_mm"] or 0.0, 0.05)
    assert _pos_err(at0, moved) < bound, (at0["frame"], moved["frame"], bound)
    assert "rail_chain" in [w["code"] for w in moved["warnings"]]
    assert moved["extras"]["chain"]["rail"]["values_mm"][0] == rail_mm
    terms = moved["extras"]["bound_terms"]
    assert terms["rail EX_KIN 3"]["position_bound95_mm"] > 0
    touching = "fixed tool (base 4)" if method == "workpiece.direct" else "tool 1 TCP"
    assert terms[touching]["position_bound95_mm"] > 0


def test_tool_4point_touched_at_four_rail_positions(cell):
    """XYZ 4-point with the rail moved between the touch-ups: the TCP of the rail at 0."""
    at0 = run(cell, "tool.xyz_4point", 3, 0.0)
    mixed = run(cell, "tool.xyz_4point", 3, rails={0: 0.0, 1: 100.0, 2: -100.0, 3: 150.0})
    assert _pos_err(at0, mixed) < max(mixed["position_bound95_mm"], 0.05)
    assert mixed["extras"]["bound_terms"]["rail EX_KIN 3"]["position_bound95_mm"] > 0


def test_an_uncalibrated_rail_with_mixed_positions_is_refused_naming_the_rail(client):
    """The rail has its machine data only: touch-ups at E4 = 0 and 100 mm are refused at
    Compute, naming the point, E4 and the rail; nothing is computed."""
    calibrate(client, "tool.xyz_4point", 1)
    url = open_session(client, "base.3point", 2, tool_no=1)
    teach(client, url, rails={0: 0.0, 1: 100.0, 2: 100.0})
    r = client.post(f"{url}/compute")
    assert r.status_code == 422, r.text
    d = r.json()["detail"][0]
    assert d["loc"] == ["body", "points", 1, "external_axes", "E4"]
    assert "rail E4 (EX_KIN 3 TRACK) is not calibrated" in d["msg"]
    assert ok(client.get(url))["state"] == "open"


def test_an_uncalibrated_rail_at_one_position_says_what_it_assumed(client):
    """Every point at E4 = 100 mm with the rail not calibrated: computed through the rail's
    machine data, and the report says so (and that the rail's error is not in the bound)."""
    calibrate(client, "tool.xyz_4point", 1)
    rep = run(client, "ext.root_point", 1, 100.0, tool_no=1)
    w = next(w for w in rep["warnings"] if w["code"] == "rail_assumed")
    assert "EX_KIN 3" in w["message"] and "machine data" in w["message"]
    assert "not calibrated" in rep["extras"]["bound_terms"]["rail EX_KIN 3"]["source"]
    # the root is where it is at rail 0 up to the rail's hidden error (the 100 mm is gone)
    at0 = run(client, "ext.root_point", 1, 0.0, tool_no=1)
    assert _pos_err(at0, rep) < 2.0


def test_move_to_sets_the_rail_of_the_chain(client):
    """The external-axis menus' steps set every axis of their chain: the rail at 0 with the
    turntable or the positioner, so Move to does not inherit where the Linear unit left it."""
    methods = {m["name"]: m for m in ok(client.get("/methods"))}
    for name in ("ext.root_point", "ext.offset", "ext.positioner_2axis"):
        for st in methods[name]["steps"]:
            assert st["external_axes"]["E4"] == 0.0, (name, st)
    assert all(set(st["external_axes"]) == {"E4"}
               for st in methods["ext.linear_unit"]["steps"])


def test_an_offset_on_an_uncalibrated_turntable_says_what_it_assumed(client):
    """The Offset on EX_KIN 1 still holding the machine data: the report names the assumption
    (and that the root's error is not in the bound); after a root point it does not."""
    calibrate(client, "tool.xyz_4point", 1)
    rep = run(client, "ext.offset", 5, tool_no=1, ext_no=1)
    w = next(w for w in rep["warnings"] if w["code"] == "kinematic_assumed")
    assert "EX_KIN 1 (TURNTABLE) is not calibrated" in w["message"]
    assert "not calibrated" in rep["extras"]["bound_terms"]["EX_KIN 1 root"]["source"]
    run(client, "ext.root_point", 1, save=True, tool_no=1)
    rep = run(client, "ext.offset", 5, tool_no=1, ext_no=1)
    assert "kinematic_assumed" not in [w["code"] for w in rep["warnings"]]


def test_pendant_calibrate_puts_a_file_touched_on_the_rail_in_the_world(cell, tmp_path, capsys):
    """The plate's touch-ups taken on the rail (E4 at 250, 0 and 100 mm), exported and solved
    by ``pendant calibrate``: given the rail (``inputs.rail``, as EX_KIN 3 holds it), the
    frame taught at E4 = 0 within its bound; without it, the frame is off by the travel and the
    report says which axis it did not place."""
    import json

    from server.cli.main import main

    at0 = run(cell, "base.3point", 2, 0.0, tool_no=1)
    url = open_session(cell, "base.3point", 2, tool_no=1)
    taught = teach(cell, url, rails={0: 250.0, 1: 0.0, 2: 100.0})
    moved = ok(cell.post(f"{url}/compute"))
    rail = moved["extras"]["chain"]["rail"]
    tool = ok(cell.get(f"{C}/tools/1"))
    points = [{"flange_pose": st["point"]["flange_pose"],
               "external_axes": st["point"]["external_axes"]}
              for st in taught["steps"] if st["point"]]
    assert sorted(p["external_axes"]["E4"] for p in points) == [0.0, 100.0, 250.0]

    def solve(inputs: dict) -> dict:
        f = tmp_path / "plate.json"
        f.write_text(json.dumps({"points": points, "inputs": {
            "tcp_mm": [tool["pose"][k] for k in "xyz"], **inputs}}))
        assert main(["calibrate", "base.3point", str(f), "--json"]) == 0, capsys.readouterr()
        return json.loads(capsys.readouterr().out)

    on_rail = solve({"rail": {"axis": "E4", "direction": rail["direction"],
                              "scale": rail["scale"], "calibrated": True}})
    assert _pos_err(on_rail, moved) < 1e-6  # the service's own chain
    assert _pos_err(on_rail, at0) < max(moved["position_bound95_mm"], 0.05)
    assert "rail_chain" in [w["code"] for w in on_rail["warnings"]]
    assert on_rail["extras"]["chain"]["rail"]["values_mm"] == [250.0, 0.0, 100.0]

    unplaced = solve({})
    assert _pos_err(unplaced, at0) > 5.0  # the travel, not placed
    warning = next(w for w in unplaced["warnings"] if w["code"] == "external_axes_ignored")
    assert "E4 = 0, 100, 250" in warning["message"] and "--rail E4:" in warning["message"]

    # machine data only: points at different rail positions are refused, naming the point
    f = tmp_path / "plate.json"
    assert main(["calibrate", "base.3point", str(f), "--rail",
                 "E4:" + ",".join(f"{v:.6f}" for v in rail["direction"])]) == 2
    err = capsys.readouterr().err
    assert err.startswith("pendant: points.1.external_axes.E4: ") and "not calibrated" in err
    assert main(["calibrate", "base.3point", str(f), "--rail",
                 "E4:" + ",".join(f"{v:.9f}" for v in rail["direction"]) + ":calibrated"]) == 0
    assert "touched at E4 = 0, 100, 250 mm: put in the world" in capsys.readouterr().out
