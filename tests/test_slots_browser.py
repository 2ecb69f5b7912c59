"""Slots keep their kind and name in the pendant page: saving over a slot of another kind asks
first (a no saves nothing and says why), and each menu proposes its own slot instead of the
number the previous menu left in the field."""

from __future__ import annotations

import pytest

from browser_helpers import browser_page, compute, idle, open_menu, open_pendant, save, walk_steps, wizard


@pytest.fixture
def page(chromium, site: str):  # noqa: ANN001, ANN201
    with browser_page(chromium, site) as p:
        yield p


def _put_slot(page, site: str, path: str, body: dict) -> dict:  # noqa: ANN001
    etag = page.request.get(site + path).headers["etag"]
    r = page.request.put(site + path, data=body, headers={"If-Match": etag})
    assert r.ok, r.text()
    return r.json()


def test_saving_over_a_slot_of_another_kind_asks_first(page, site):
    """TOOL 5 holds the workpiece "PED SEALER" (typed in). XYZ 4-point into it: Save asks,
    naming the slot's kind and name; No leaves the slot as it was and says so; Yes saves a
    tool with its own name."""
    _put_slot(page, site, "/controllers/1/tools/5", {"name": "PED SEALER", "kind": "workpiece",
                                                     "pose": {"x": 10, "y": 0, "z": 90}})
    open_pendant(page, site)
    open_menu(page, "tool.xyz_4point", 5)
    walk_steps(page, 4)
    compute(page)
    asked: list[str] = []
    page.once("dialog", lambda d: (asked.append(d.message), d.dismiss()))
    save(page)
    assert asked and "TOOL 5 holds a robot-held workpiece 'PED SEALER'" in asked[0]
    err = page.locator("#report").get_by_text("not saved:")
    assert "not saved: TOOL 5 holds a robot-held workpiece 'PED SEALER'" in err.inner_text()
    slot = page.request.get(site + "/controllers/1/tools/5").json()
    assert (slot["kind"], slot["name"], slot["pose"]["x"]) == ("workpiece", "PED SEALER", 10)

    page.once("dialog", lambda d: (asked.append(d.message), d.accept()))
    save(page)
    assert len(asked) == 2
    assert "Saved into TOOL 5 (tool5)" in wizard(page).get_by_role("status").inner_text()
    slot = page.request.get(site + "/controllers/1/tools/5").json()
    assert (slot["kind"], slot["name"]) == ("tool", "tool5")


def test_each_menu_proposes_its_own_slot(page, site):
    """After a base menu opened on BASE 6, Linear unit proposes EX_KIN 3 (the rail), the
    positioner EX_KIN 2, and a base menu BASE 6 again; a tool menu its own last tool."""
    open_pendant(page, site)
    w = wizard(page)
    open_menu(page, "base.numeric", 6)
    page.once("dialog", lambda d: d.accept())  # Discard asks
    w.get_by_role("button", name="Discard").first.click()
    idle(page)
    menu, target = w.get_by_label("Menu"), w.get_by_label("Target number")
    menu.select_option("ext.linear_unit")
    assert target.input_value() == "3"
    menu.select_option("ext.positioner_2axis")
    assert target.input_value() == "2"
    menu.select_option("ext.root_point")
    assert target.input_value() == "1"
    menu.select_option("base.3point")
    assert target.input_value() == "6"
    menu.select_option("tool.xyz_4point")
    assert target.input_value() == "1"
    idle(page)


def _R(p: dict):  # noqa: ANN202
    from solvers.frames import Pose

    return Pose(p["x"], p["y"], p["z"], p["a"], p["b"], p["c"]).as_matrix()[:3, :3]


def test_reteaching_an_optional_step_moves_where_it_was_taught(page, site):
    """XYZ 4-point, then the optional step at the orientation the report suggests. Picked
    again to re-teach it, Move to goes to that orientation (not the service's default cone
    for an optional step)."""
    import re

    import numpy as np

    open_pendant(page, site)
    w = wizard(page)
    open_menu(page, "tool.xyz_4point", 7)
    walk_steps(page, 4)
    compute(page)
    w.get_by_role("button", name="Move to", exact=True).click()  # the suggested orientation
    idle(page)
    w.get_by_role("button", name="Touch up", exact=True).click()
    idle(page)
    sid = page.evaluate("window.pendant.state.session.id")
    s = page.request.get(f"{site}/controllers/1/sessions/{sid}").json()
    taught = next(st for st in s["steps"] if st["index"] == 4)
    assert taught["filled"] and not taught["required"]
    w.get_by_role("button", name=re.compile(r"^Step 1: ")).click()
    w.get_by_role("button", name="Move to", exact=True).click()
    idle(page)
    w.get_by_role("button", name=re.compile(r"^Step 5: ")).click()
    w.get_by_role("button", name="Move to", exact=True).click()
    idle(page)
    robot = page.request.get(f"{site}/controllers/1/robot").json()
    R_now, R_taught = _R(robot["flange_pose"]), _R(taught["point"]["flange_pose"])
    angle = np.degrees(np.arccos(np.clip((np.trace(R_now.T @ R_taught) - 1) / 2, -1, 1)))
    assert angle < 0.05, angle
