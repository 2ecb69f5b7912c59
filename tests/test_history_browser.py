"""The pendant page's second hour in Debian's Chromium (issue 27): a slot's history with a
Restore that asks first, a JSON backup restored from its preview with its progress in words,
the open sessions listed to pick one from (whose each is; none taken over unasked), and the
Frames table readable at 1280 px."""

from __future__ import annotations

import re

import pytest

from browser_helpers import browser_page, compute, idle, open_menu, open_pendant, save, walk_steps

@pytest.fixture
def page(chromium, site: str):  # noqa: ANN001, ANN201
    with browser_page(chromium, site, timeout_ms=20_000) as p:  # logged in as the Administrator
        yield p


def api(page, site: str, method: str, path: str, **kw) -> dict:  # noqa: ANN001
    r = page.request.fetch(site + "/controllers/1" + path, method=method, **kw)
    assert r.ok, f"{method} {path}: {r.status} {r.text()}"
    return r.json()


def edit(page, site: str, number: int, **body) -> dict:  # noqa: ANN001
    return api(page, site, "PUT", f"/tools/{number}", headers={"If-Match": "*"}, data=body)


def test_history_lists_each_change_and_restore_asks_then_restores(page, site):
    edit(page, site, 7, name="gripper", pose={"x": 10.0, "z": 150.0})
    edit(page, site, 7, name="gripper", pose={"x": 12.5, "z": 151.0})
    open_pendant(page, site)
    page.locator("#tool-table tr[data-number='7']").click()  # a row of Frames shows its history
    view = page.locator("#history-view")
    view.wait_for(state="visible")
    idle(page)
    assert page.locator("#history-title").inner_text() == "TOOL 7 (gripper): 2 changes"
    rows = page.locator("#history-rows tbody tr")
    assert rows.count() == 2
    newest = rows.nth(0).inner_text()
    assert "admin" in newest and "edit by hand" in newest
    assert "gripper [tool] 10.000 0.000 150.000" in newest and "→ gripper [tool] 12.500 0.000 151.000" in newest
    assert "(unused)" in rows.nth(1).inner_text()  # the first change: from the empty slot

    # Restore asks first; dismissed, nothing changes
    dialogs: list[str] = []
    page.once("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
    rows.nth(0).get_by_role("button", name="Restore").click()
    page.wait_for_function("() => true")
    assert dialogs and "Restore TOOL 7" in dialogs[0] and "gripper [tool] 10.000" in dialogs[0]
    assert api(page, site, "GET", "/tools/7")["pose"]["x"] == 12.5

    # accepted: the slot is as it was before that change, recorded as a change of its own
    page.once("dialog", lambda d: d.accept())
    rows.nth(0).get_by_role("button", name="Restore").click()
    page.wait_for_function("() => document.querySelector('#history-note').textContent.startsWith('Restored')")
    idle(page)
    assert api(page, site, "GET", "/tools/7")["pose"]["x"] == 10.0
    assert page.locator("#history-title").inner_text() == "TOOL 7 (gripper): 3 changes"
    assert "restore" in rows.nth(0).inner_text()
    assert "10.000" in page.locator("#tool-table tr[data-number='7']").inner_text()  # Frames reloaded

    # someone else changes the slot meanwhile: the Restore is refused (412), nothing overwritten
    edit(page, site, 7, pose={"x": 99.0})
    page.once("dialog", lambda d: d.accept())
    rows.nth(1).get_by_role("button", name="Restore").click()
    page.wait_for_function("() => document.querySelector('#history-err').textContent.length > 0")
    assert api(page, site, "GET", "/tools/7")["pose"]["x"] == 99.0


def test_json_backup_restore_previews_then_restores_with_progress(page, site):
    edit(page, site, 9, name="probe", pose={"x": 1.5, "y": 2.5, "z": 100.0})
    r = page.request.get(site + "/controllers/1/export?format=json")
    assert r.ok, r.text()
    backup = r.text()
    edit(page, site, 9, name="probe2", pose={"x": 7.0})  # after the backup
    open_pendant(page, site)
    page.evaluate("""() => { window.progressSeen = [];
        new MutationObserver(() => window.progressSeen.push(document.querySelector('#import-progress').textContent))
          .observe(document.querySelector('#import-progress'), { childList: true, characterData: true, subtree: true }); }""")
    form = page.locator("#import-form")
    form.locator("#import-file").set_input_files(files=[{
        "name": "cell-1-backup.json", "mimeType": "application/json", "buffer": backup.encode()}])
    form.get_by_role("button", name="Preview").click()
    preview = form.locator("#import-preview")
    preview.wait_for(state="visible")
    summary = preview.locator("#import-summary").inner_text()
    assert summary.startswith("Restoring this backup replaces the whole controller: 1 slot(s) change"), summary
    row = preview.locator("#import-diff tbody tr")
    assert row.count() == 1
    assert "probe2 [tool] 7.000" in row.inner_text() and "probe [tool] 1.500 2.500 100.000" in row.inner_text()
    assert api(page, site, "GET", "/tools/9")["name"] == "probe2"  # a preview writes nothing

    page.once("dialog", lambda d: d.accept())
    form.get_by_role("button", name="Restore this backup").click()
    page.wait_for_function("() => document.querySelector('#import-summary').textContent.startsWith('Restored')")
    idle(page)
    assert api(page, site, "GET", "/tools/9")["name"] == "probe"
    seen = page.evaluate("window.progressSeen")
    assert any(t.startswith("Checking cell-1-backup.json") for t in seen), seen
    assert any(re.fullmatch(r"Restore job \d+: (waiting for a worker|restoring the backup: \d+ %)", t)
               for t in seen), seen
    assert page.locator("#import-progress").inner_text() == ""
    assert "probe" in page.locator("#tool-table tr[data-number='9']").inner_text()


def test_open_sessions_are_listed_and_the_person_picks_one(page, site):
    """A session opened by a script is listed, not taken over; the person resumes the older."""
    first = api(page, site, "POST", "/sessions", data={"method": "tool.xyz_4point", "target_no": 4})
    api(page, site, "POST", f"/sessions/{first['id']}/touch-up", data={})
    second = api(page, site, "POST", "/sessions", data={"method": "tool.xyz_4point", "target_no": 5})
    open_pendant(page, site)
    assert page.locator("#session").is_hidden()  # nothing resumed unasked
    listed = page.locator("#open-sessions li")
    texts = listed.all_inner_texts()
    mine = [t for t in texts if f"(session {first['id']})" in t]
    assert mine and "TOOL 4: 1 of 4 points taught, open" in mine[0], texts
    assert any("TOOL 5: 0 of 4 points taught, open" in t and f"(session {second['id']})" in t for t in texts)
    page.get_by_role("button", name=f"Resume session {first['id']}").click()
    idle(page)
    assert re.search(r"→ TOOL 4$", page.locator("#session-title").inner_text())
    assert page.locator("#step-label").text_content().startswith("Step 2 of 4")
    for s in (first, second):  # leave the module's database as it was
        api(page, site, "POST", f"/sessions/{s['id']}/discard", data={})


def test_open_sessions_say_whose_they_are(page, site):
    """Another user's session is listed with their name; the viewer's own is marked theirs."""
    r = page.request.post(site + "/users", data={"name": "olga", "role": "Programmer"})
    assert r.ok, r.text()
    r = page.request.post(site + "/users/olga/tokens", data={})
    assert r.ok, r.text()
    olga = {"Authorization": "Bearer " + r.json()["token"]}
    menu = {"method": "tool.xyz_4point"}
    hers = api(page, site, "POST", "/sessions", headers=olga, data={**menu, "target_no": 6})
    mine = api(page, site, "POST", "/sessions", data={**menu, "target_no": 8})
    open_pendant(page, site)
    listed = page.locator("#open-sessions li")
    by_id = {s["id"]: listed.filter(has_text=f"(session {s['id']})") for s in (hers, mine)}
    her_line = by_id[hers["id"]].inner_text()
    assert "TOOL 6: 0 of 4 points taught, open" in her_line and " by olga (session" in her_line, her_line
    assert "yours" not in her_line
    assert " by admin (yours) (session" in by_id[mine["id"]].inner_text()
    assert by_id[mine["id"]].get_attribute("class") == "mine"
    assert by_id[hers["id"]].get_attribute("class") is None
    for s in (hers, mine):  # leave the module's database as it was
        api(page, site, "POST", f"/sessions/{s['id']}/discard", data={})


def test_frames_table_fits_at_1280_px_with_whole_words(page, site):
    edit(page, site, 11, name="Door panel gripper LH", pose={"x": -1234.567, "y": 123.456, "z": 1500.0,
                                                             "a": -179.999, "b": 89.5, "c": -45.25})
    open_pendant(page, site)
    fit = page.evaluate("""() => {
        const wrap = document.querySelector('#tool-wrap');
        const broken = [];
        for (const td of document.querySelectorAll('#tool-table td.name')) {
          const text = td.firstChild;
          if (!text) continue;
          let at = 0;
          for (const word of text.textContent.split(' ')) {
            const r = document.createRange();
            r.setStart(text, at); r.setEnd(text, at + word.length);
            if (r.getClientRects().length > 1) broken.push(word);
            at += word.length + 1;
          }
        }
        const prov = document.querySelector('#tool-table thead th:last-child').getBoundingClientRect();
        return { broken, overflow: wrap.scrollWidth - wrap.clientWidth,
                 provRight: prov.right, wrapRight: wrap.getBoundingClientRect().right };
    }""")
    assert fit["broken"] == [], f"names broken mid-word: {fit['broken']}"
    assert fit["overflow"] <= 0 and fit["provRight"] <= fit["wrapRight"] + 0.5, fit


def test_the_saved_note_goes_with_the_next_action_an_import(page, site):
    """"Saved into TOOL 13" does not stay on screen after an import renamed the slot."""
    from pathlib import Path

    open_pendant(page, site)
    open_menu(page, "tool.xyz_4point", 13)
    page.locator("#wizard").get_by_label("Ideal aim").check()
    walk_steps(page, 4)
    compute(page)
    save(page)
    assert page.locator("#saved-note").inner_text().startswith("Saved into TOOL 13")
    form = page.locator("#import-form")
    form.locator("#import-file").set_input_files(str(Path(__file__).parent / "data" / "kuka_cell7_config.dat"))
    form.get_by_role("button", name="Preview").click()
    form.locator("#import-preview").wait_for(state="visible")
    assert page.locator("#saved-note").count() == 0
