"""The pendant page's import preview in Debian's Chromium: a person picks a controller file,
sees per slot before -> after, kind changes and skipped declarations, and nothing is written
until they confirm."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from browser_helpers import browser_page, idle, open_pendant

DATA = Path(__file__).parent / "data"


@pytest.fixture
def page(chromium, site: str):  # noqa: ANN001, ANN201
    with browser_page(chromium, site, timeout_ms=15_000) as p:  # logged in as the Administrator
        yield p


def slot(page, site: str, path: str) -> dict:  # noqa: ANN001
    r = page.request.get(site + "/controllers/1" + path)
    assert r.ok, r.text()
    return r.json()


def test_import_preview_then_confirm(page, site):
    open_pendant(page, site)
    form = page.locator("#import-form")
    form.locator("#import-file").set_input_files(str(DATA / "kuka_cell7_config.dat"))
    form.get_by_role("button", name="Preview").click()
    preview = form.locator("#import-preview")
    preview.wait_for(state="visible")
    assert "9 slot(s) would change" in preview.locator("#import-summary").inner_text()
    rows = preview.locator("#import-diff tbody tr")
    assert rows.count() == 9
    assert "Door panel LH [workpiece]" in rows.nth(2).inner_text()
    assert slot(page, site, "/tools/3")["name"] == ""  # a preview writes nothing

    form.get_by_role("button", name="Import these changes").click()
    page.wait_for_function(
        "() => document.querySelector('#import-summary').textContent.startsWith('Imported')")
    idle(page)
    assert slot(page, site, "/tools/3")["kind"] == "workpiece"
    assert "Door panel LH" in page.locator("#tool-table").inner_text()

    # the ABB module over it: tool 3 becomes tPen, a tool; three declarations are skipped
    form.locator("#import-file").set_input_files(str(DATA / "abb_cell7.mod"))
    form.get_by_role("button", name="Preview").click()
    page.wait_for_function("() => document.querySelector('#import-skipped').children.length === 3")
    changed = preview.locator("#import-diff tbody tr.kind-change")
    assert "workpiece -> tool" in changed.first.inner_text()
    assert "line 39: tCopy" in preview.locator("#import-skipped").inner_text()
    form.get_by_role("button", name="Cancel").click()
    assert preview.is_hidden()
    assert slot(page, site, "/tools/3")["name"] == "Door panel LH"

    # a file cut short: refused with its line, nothing written
    cut = DATA / "abb_cell7.mod"
    text = cut.read_text()
    form.locator("#import-file").set_input_files(files=[{
        "name": "cut.mod", "mimeType": "text/plain",
        "buffer": text[:text.index("ENDMODULE")].encode()}])
    form.get_by_role("button", name="Preview").click()
    err = form.locator("#import-err")
    page.wait_for_function("() => document.querySelector('#import-err').textContent.length > 0")
    assert "ENDMODULE" in err.inner_text() and "cut short" in err.inner_text()


def test_partial_import_keeps_the_calibrated_slots(page, site):
    """Issue 24 (3): the preview's tick boxes choose the slots; an unticked TOOL 1 keeps its
    calibration. The Windows-1252 file shows its names right and comes back byte for byte."""
    r = page.request.put(site + "/controllers/1/tools/1", headers={"If-Match": "*"},
                         data={"name": "calibrated", "pose": {"x": 1.25, "z": 201.5}})
    assert r.ok, r.text()
    open_pendant(page, site)
    form = page.locator("#import-form")
    path = DATA / "controller-files" / "kuka_krc4_crlf_cp1252.dat"
    form.locator("#import-file").set_input_files(str(path))
    form.get_by_role("button", name="Preview").click()
    preview = form.locator("#import-preview")
    preview.wait_for(state="visible")
    assert "Greifer Öl" in preview.locator("#import-diff").inner_text()
    preview.get_by_label("apply tool 1").uncheck()
    commit = form.get_by_role("button", name=re.compile(r"Import \d+ ticked slot"))
    commit.click()
    page.wait_for_function(
        "() => document.querySelector('#import-summary').textContent.startsWith('Imported')")
    idle(page)
    tool1 = slot(page, site, "/tools/1")
    assert tool1["name"] == "calibrated" and tool1["pose"]["x"] == 1.25
    assert slot(page, site, "/tools/3")["name"] == "Tür links"
    out = page.request.get(site + "/controllers/1/export?format=kuka").body()
    assert b'TOOL_NAME[3,]="T\xfcr links"' in out and b'TOOL_NAME[1,]="calibrated"' in out
