"""The pendant page in Debian's Chromium: a person calibrates a tool and a base by clicking,
downloads the KUKA file, and sees a refused input's reason beside the input.

The service runs for real (uvicorn, a temporary SQLite file, the emulated KR 6 R900 sixx of
the demo controller "cell-1"). The README's screenshot comes from
``tests/test_readme_walkthrough_browser.py``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from browser_helpers import (browser_page, compute, idle, kuka_frame, open_menu, open_pendant, save, walk_steps,
                             wizard)
from emulator import cell_for
from solvers.robots import ROBOTS

CELL = cell_for(ROBOTS["kuka_kr6_r900_sixx"], 1)  # the demo cell's hidden truth, for the asserts only


@pytest.fixture
def page(chromium, site: str):  # noqa: ANN001, ANN201
    with browser_page(chromium, site, accept_downloads=True) as p:
        yield p


def api(page, site: str, path: str) -> dict:  # noqa: ANN001
    r = page.request.get(site + path)
    assert r.ok, f"GET {path} -> {r.status}: {r.text()}"
    return r.json()


def test_tool_4point_and_base_3point_by_clicking_then_kuka_export_matches(page, site, tmp_path):
    """Tool > XYZ 4-point into TOOL 1, Base > 3-point into BASE 1, then the $config.dat."""
    open_pendant(page, site)
    assert "cell-1" in page.get_by_label("Controller").inner_text()
    w = wizard(page)

    # ---------------------------------------------------------------- tool, XYZ 4-point
    open_menu(page, "tool.xyz_4point", 1)
    assert float(w.get_by_label("Aim error (mm per axis)").input_value()) > 0  # a person's aim by default
    assert w.locator("#session-title").inner_text() == "Tool > XYZ 4-point → TOOL 1"
    assert w.locator("#prompt").inner_text() == "Bring the TCP to the reference point from orientation 1"
    walk_steps(page, 4)
    report = compute(page)
    assert report.is_visible()
    stats = report.locator(".stats").inner_text()
    for word in ("Max", "Mean", "RMS", "95% position"):
        assert word in stats
    assert report.locator("svg.chart rect.bar").count() == 4
    assert report.get_by_role("img", name=re.compile("Residual per touch-up")).count() == 1
    assert w.locator("#session-state").inner_text().lower() == "computed"
    shot = tmp_path / "pendant.png"  # the README's screenshot comes from test_readme_walkthrough_browser
    page.evaluate("window.scrollTo(0, 0)")
    page.screenshot(path=str(shot))
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    save(page)
    assert "Saved into TOOL 1" in w.get_by_role("status").inner_text()
    row = page.locator("#tool-table tr[data-number='1']")
    assert "tool1" in row.inner_text() and "tool.xyz_4point" in row.inner_text()
    tool = api(page, site, "/controllers/1/tools/1")
    assert tool["provenance"]["method"] == "tool.xyz_4point"
    tcp = np.array([tool["pose"][k] for k in "xyz"])
    assert np.linalg.norm(tcp - CELL.T_flange_tool[:3, 3]) < 1.5  # the default aim on 4 touch-ups

    # ---------------------------------------------------------------- base, 3-point with tool 1
    open_menu(page, "base.3point", 1, tool_no=1)
    assert "tool_no = 1" in w.locator("#session-params").inner_text()
    assert w.locator("#prompt").inner_text() == "Bring the TCP to the origin of the new base"
    walk_steps(page, 3)
    report = compute(page)
    assert "95% angle" in report.locator(".stats").inner_text()
    assert report.locator("svg.chart rect.bar").count() == 3
    save(page)
    assert page.get_by_role("tab", name="Bases (32)").get_attribute("aria-selected") == "true"
    assert "base1" in page.locator("#base-table tr[data-number='1']").inner_text()
    base = api(page, site, "/controllers/1/bases/1")
    assert base["provenance"]["method"] == "base.3point"
    origin = np.array([base["pose"][k] for k in "xyz"])
    assert np.linalg.norm(origin - CELL.T_world_plate[:3, 3]) < 3.0

    # ---------------------------------------------------------------- KUKA export
    with page.expect_download() as info:
        page.get_by_role("link", name="KUKA $config.dat").click()
    download = info.value
    assert download.suggested_filename == "cell-1-$config.dat"
    text = Path(download.path()).read_text()
    assert kuka_frame(text, "TOOL_DATA", 1) == pytest.approx([tool["pose"][k] for k in "xyzabc"], abs=1e-6)
    assert kuka_frame(text, "BASE_DATA", 1) == pytest.approx([base["pose"][k] for k in "xyzabc"], abs=1e-6)
    assert 'TOOL_NAME[1,]="tool1"' in text and 'BASE_NAME[1,]="base1"' in text
    for fmt in ("abb", "fanuc", "ur", "json"):
        assert page.locator(f".exports a[data-format='{fmt}']").get_attribute("href") == \
            f"/controllers/1/export?format={fmt}"


def test_refused_inputs_show_the_reason_beside_the_field(page, site):
    """An out-of-limit joint jog, a too-large increment and recorded joints of the wrong
    length: each 422's msg appears beside the input its loc names; nothing moves."""
    r = page.request.post(site + "/controllers", data={"name": "jog-cell"})
    assert r.status == 201, r.text()
    cid = r.json()["id"]
    open_pendant(page, site)
    page.get_by_label("Controller").select_option(str(cid))
    idle(page)
    before = api(page, site, f"/controllers/{cid}/robot")["joints_deg"]
    jog = page.locator("#jog-panel")

    jog.get_by_label("Increment").fill("100")  # A5 is at 90 deg, its limit 120 deg
    jog.get_by_role("button", name="Jog A5 plus").click()
    idle(page)
    a5 = jog.locator(".jog-row[data-loc='joints_deg.4']")
    assert re.search(r"A5 \(joint 5\) at 190(\.0+)? deg is outside its software limit \[-120, 120\] deg",
                     a5.locator(".err").inner_text())
    assert a5.get_by_label("A5 (deg)").get_attribute("aria-invalid") == "true"
    assert jog.locator(".jog-row[data-loc='joints_deg.1'] .err").inner_text() == ""

    jog.get_by_label("Increment").fill("1000")
    jog.get_by_role("button", name="Jog A1 plus").click()
    idle(page)
    assert "less than or equal to 100" in jog.locator(".inc-field .err").inner_text()
    assert a5.locator(".err").inner_text() == ""  # the old error is gone

    open_menu(page, "tool.xyz_4point", 2)
    w = wizard(page)
    w.get_by_text("Paste recorded joints").click()
    w.get_by_label("Recorded joints").fill("0, -90, 90")
    w.get_by_role("button", name="Touch up with these joints").click()
    idle(page)
    assert "has 3 values; the robot has 6 joints" in w.locator(".field[data-loc='joints_deg'] .err").inner_text()
    page.once("dialog", lambda d: d.accept())  # "Discard ...? This drops 0 touch-ups"
    w.get_by_role("button", name="Discard session").click()
    idle(page)
    assert api(page, site, f"/controllers/{cid}/robot")["joints_deg"] == before


def test_optional_touch_up_after_the_required_steps_is_labelled_once(page, site):
    """Tool > XYZ 4-point: after the four orientations a fifth touch-up is optional; the
    wizard counts it and says "optional" once, not twice."""
    open_pendant(page, site)
    w = wizard(page)
    open_menu(page, "tool.xyz_4point", 3)
    walk_steps(page, 4)
    assert w.locator("#step-label").text_content() == "All 4 steps taught"
    w.get_by_role("button", name="Touch up", exact=True).click()
    idle(page)
    assert w.locator("#step-label").text_content() == "All 4 steps taught, 1 optional"
    steps = w.locator("#steps").text_content()
    assert "(optional) (optional)" not in steps and "optional) (optional" not in steps
    assert steps.count("optional") == 1, steps
