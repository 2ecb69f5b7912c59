"""The pendant page in Debian's Chromium: a person jogs the turntable E1, calibrates its root
point and a base on it (Root point -> Offset) by clicking, sees the fitted circle from above,
and downloads both exports (KUKA machine data, ABB MOC.cfg).

The service runs for real (uvicorn, a temporary SQLite file, the demo controller cell-1 with
its external axes E1..E4); see tests/test_pendant_browser.py for the pattern.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from browser_helpers import compute, idle, open_menu, open_pendant, save, walk_steps, wizard
from test_pendant_browser import api, page  # noqa: F401  (the page fixture: downloads allowed)
from emulator import external as ext_emu
from server.formats.external import read_abb_external, read_kuka_external
from solvers.robots import ROBOTS


def download(page, name: str) -> str:  # noqa: ANN001
    with page.expect_download() as info:
        page.locator("#export").get_by_role("link", name=name).click()
    return Path(info.value.path()).read_text()


def test_root_point_then_offset_by_clicking_then_both_exports(page, site):
    open_pendant(page, site)
    w = wizard(page)

    # ------------------------------------------------------------------- jog E1 like a joint
    jog = page.locator("#jog-panel")
    assert jog.get_by_label("E1 (deg)").inner_text() == "0.000"
    jog.get_by_label("Increment").fill("10")
    jog.get_by_role("button", name="Jog E1 plus").click()
    idle(page)
    assert jog.get_by_label("E1 (deg)").inner_text() == "10.000"
    assert jog.get_by_label("E4 (mm)").inner_text() == "0.000"  # the rail, in mm
    assert jog.locator("#inc-unit").inner_text() == "deg; E4: mm"  # the increment's unit says so
    assert "6 axes + E1–E4" in page.locator("#robot-name").inner_text()  # not "6 axes"

    # ------------------------------------------------ the touching tool: XYZ 4-point, ideal aim
    open_menu(page, "tool.xyz_4point", 1)
    w.get_by_label("Ideal aim").check()
    walk_steps(page, 4)
    compute(page)
    save(page)

    # --------------------------------------------------- External kinematics > Root point
    open_menu(page, "ext.root_point", 1, tool_no=1)
    assert w.locator("#session-title").inner_text() == \
        "External kinematics > Root point → EX_KIN 1"
    assert w.locator("#prompt").inner_text() == "Touch the mark on the table with E1 at -135 deg"
    walk_steps(page, 3)  # Move to turns E1 to the step's value first
    assert jog.get_by_label("E1 (deg)").inner_text() == "45.000"
    report = compute(page)
    assert report.locator("svg.chart rect.bar").count() == 3
    top = report.get_by_role("img", name=re.compile("Top view along the axis: 3 marks"))
    assert top.count() == 1 and top.locator("circle.mark").count() == 3
    assert top.locator("circle.fit-circle").count() == 1
    # the report suggests a 4th axis value: Move to goes there, Touch up, Compute again
    assert w.locator("#prompt").inner_text().startswith("Optional: touch the mark with E1 at")
    guidance = report.locator(".guidance")  # an axis value, not an "orientation"
    assert guidance.count() == 1 and guidance.inner_text().endswith("it goes to that axis value."), guidance.all_inner_texts()
    w.get_by_role("button", name="Move to", exact=True).click()
    idle(page)
    w.get_by_role("button", name="Touch up", exact=True).click()
    idle(page)
    report = compute(page)
    assert report.get_by_role("img", name=re.compile("4 marks")).count() == 1
    assert "axis tilted" in report.locator(".notes").inner_text()  # the demo table's hidden tilt
    save(page)
    assert "Saved into EX_KIN 1 (TURNTABLE)" in w.get_by_role("status").inner_text()
    assert page.get_by_role("tab", name="External (6)").get_attribute("aria-selected") == "true"
    assert "ext.root_point" in page.locator("#ext-table tr[data-number='1']").inner_text()
    # its history on the page: the calibration, with its quality figures and a Restore
    page.locator("#ext-table tr[data-number='1']").click()
    page.locator("#history-view").wait_for(state="visible")
    idle(page)
    assert page.locator("#history-title").inner_text().startswith("EX_KIN 1")
    entry = page.locator("#history-rows tbody tr").first
    assert "calibration (session" in entry.inner_text() and "ext.root_point · max" in entry.inner_text()
    assert "[turntable E1]" in entry.inner_text() and entry.get_by_role("button", name="Restore").is_visible()

    # ------------------------------------------------------- External kinematics > Offset
    open_menu(page, "ext.offset", 5, tool_no=1, ext_no=1)
    assert w.locator("#prompt").inner_text() == \
        "With E1 at 30 deg, bring the TCP to the origin of the base on the table"
    # a touch-up written down on a real controller: its joints and its E1 value, pasted
    w.get_by_role("button", name="Move to", exact=True).click()
    idle(page)
    joints = ", ".join(f"{q:.9f}" for q in api(page, site, "/controllers/1/robot")["joints_deg"])
    w.locator("summary", has_text="Paste recorded joints").click()
    w.get_by_label("Recorded joints").fill(joints)
    w.get_by_label("Recorded external axes").fill("30")
    w.get_by_role("button", name="Touch up with these joints").click()
    idle(page)
    step = api(page, site, f"/controllers/1/sessions/{page.evaluate('window.pendant.state.session.id')}")
    assert step["steps"][0]["point"]["source"] == "joints"
    assert step["steps"][0]["point"]["external_axes"] == {"E1": 30.0}
    w.get_by_role("button", name=re.compile(r"^Step 2: ")).click()
    idle(page)
    for k in (1, 2):
        w.get_by_role("button", name="Move to", exact=True).click()
        idle(page)
        w.get_by_role("button", name="Touch up", exact=True).click()
        idle(page)
    report = compute(page)
    assert "95% angle" in report.locator(".stats").inner_text()
    save(page)
    assert "Saved into BASE 5" in w.get_by_role("status").inner_text()
    base = api(page, site, "/controllers/1/bases/5")
    assert base["kind"] == "coordinated_base" and base["mech_unit"] == "TURNTABLE"

    # the base rides the table: calibrated root · Rz(90) · offset = where the plate is at 90 deg
    reach = ROBOTS["kuka_kr6_r900_sixx"].reach_mm
    truth = ext_emu.external_cell(reach, None, 1)
    root = api(page, site, "/controllers/1/external-kinematics/1")
    from solvers.external.common import rz
    from solvers.frames import Pose
    T = (Pose(**root["root"]).as_matrix() @ rz([90.0])[0] @ Pose(**base["pose"]).as_matrix())
    true_90 = truth.turntable.flange([90.0])[0] @ truth.T_flange_plate
    assert np.linalg.norm(T[:3, 3] - true_90[:3, 3]) < 0.5

    # ---------------------------------------------------------------------- both exports
    kuka = download(page, "KUKA external kinematics")
    machine, config = kuka.split("; ---- KRC:\\R1\\System\\$config.dat ----")
    setup = read_kuka_external(machine, config)
    table = next(k for k in setup.kinematics if k.name == "TURNTABLE")
    assert table.root.as_array()[:3] == pytest.approx([root["root"][k] for k in "xyz"], abs=1e-6)
    (b,) = [b for b in setup.bases if b.number == 5]
    assert b.mech_unit == "TURNTABLE"
    abb = download(page, "ABB MOC.cfg units")
    units = read_abb_external(abb).kinematics
    assert any(np.linalg.norm(k.root.as_array()[:3] - [root["root"][c] for c in "xyz"]) < 1e-3
               for k in units)
