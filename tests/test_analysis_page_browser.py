"""The analysis page (web/analysis.html) in Debian's Chromium: a person uploads a recording,
reads the verdict, the findings and the residual plots before and after, and sees a broken
recording's field named beside the upload box.

The service runs for real (uvicorn, a temporary SQLite file). The recording is the simulated
UR10 tracker run with a hidden joint-2 compliance of the analysis API test.
``PENDANT_ANALYSIS_SCREENSHOT=docs/analysis-page.png`` keeps the screenshot of the report
(else it goes to a temporary directory).
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import pytest

from browser_helpers import VIEWPORT, auth_headers
from solvers.physics import Imperfections
from solvers.simulate import simulate_recording

N = 40


def compliant_ur10() -> dict:
    """UR10 tracker run, 5 kg payload, joint 2 yields 5e-4 deg/Nm, 0.02 mm noise."""
    imp = Imperfections(noise_mm=0.02, compliance_deg_per_Nm=(0, 5e-4, 0, 0, 0, 0))
    return simulate_recording("tracker", "ur10", imp, N, seed=5, payload=(5.0, [0, 0, 50]))


@pytest.fixture
def page(chromium, site: str):  # noqa: ANN001, ANN201
    context = chromium.new_context(viewport=VIEWPORT, extra_http_headers=auth_headers())
    context.set_default_timeout(15_000)
    p = context.new_page()
    errors: list[str] = []
    p.on("pageerror", lambda e: errors.append(str(e)))
    p.goto(site + "/analysis.html")
    idle(p)
    yield p
    context.close()
    assert not errors, f"JavaScript errors on the page: {errors}"


def idle(page) -> None:  # noqa: ANN001
    """Wait until the page has nothing in flight (file read, upload, analysis)."""
    page.wait_for_function("() => window.analysisPage && window.analysisPage.pending === 0 "
                           "&& document.body.dataset.ready")


def upload(page, path: Path) -> None:  # noqa: ANN001
    """Choose the file (the page only reads it), then Analyse."""
    page.get_by_label("Upload a file").set_input_files(str(path))
    idle(page)
    page.get_by_role("button", name="Analyse").click()
    idle(page)


def paste_and_analyse(page, text: str) -> None:  # noqa: ANN001
    page.get_by_label("or paste the JSON").fill(text)
    page.get_by_role("button", name="Analyse").click()
    idle(page)


def test_compliance_recording_is_explained_with_plots_before_and_after(page, site,
                                                                       tmp_path) -> None:
    """Upload the joint-2 compliance run: verdict, RMS, locate, the finding, the plots."""
    rec = tmp_path / "ur10-compliance.json"
    rec.write_text(json.dumps(compliant_ur10()), encoding="utf-8")
    upload(page, rec)
    assert page.locator("#upload-error").is_hidden()
    assert page.locator("#report").is_visible()

    verdict = page.locator("#verdict")
    assert verdict.get_attribute("data-verdict") == "explained"
    assert verdict.inner_text().lower() == "explained"
    rep = page.evaluate("window.analysisPage.report")
    assert rep == page.request.get(f"{site}/analysis/{rep['id']}").json()  # what the service stored
    assert page.evaluate("location.search") == f"?analysis={rep['id']}"

    for row, block in (("before", "baseline"), ("after", "final")):
        cells = page.locator(f'#metrics tr[data-row="{row}"]')
        assert cells.locator("td.rms").inner_text() == f"{rep[block]['rms_mm']:.3f} mm"
        assert cells.locator("td.heldout").inner_text() == f"{rep[block]['heldout_rms_mm']:.3f} mm"

    assert page.locator("#locate-summary").inner_text() == rep["locate"]["summary"]
    worst = [int(t) for t in page.locator("#worst-samples li").evaluate_all(
        "els => els.map(e => e.dataset.sample)")]
    assert worst == rep["locate"]["worst_samples"]

    finding = page.locator("#findings li.finding").first
    assert finding.get_attribute("data-effect") == "joint_compliance"
    assert finding.get_attribute("data-joint") == "2"
    assert finding.locator(".title").inner_text() == "Joint compliance J2"
    assert finding.locator(".explanation").inner_text() == rep["findings"][0]["explanation"]
    value = finding.locator('[data-param="compliance_deg_per_Nm"] td').inner_text()
    assert re.fullmatch(r"0\.000\d+ ± \S+ deg/Nm", value), value
    assert float(value.split()[0]) == pytest.approx(5e-4, rel=0.3)
    assert finding.locator('[data-evidence="p_value"] td').inner_text() != ""

    assert page.locator("#refused-panel").is_hidden()   # nothing refused as impossible

    notes = page.locator("#not-identifiable li")
    # one line per entry, the gear harmonics left out for too little travel on one line
    short = [n for n in rep["not_identifiable"] if isinstance(n.get("periods_per_turn"), list)]
    assert notes.count() == len(rep["not_identifiable"]) - len(short) + (1 if short else 0) > 0
    assert rep["not_identifiable"][0]["reason"] in notes.first.inner_text()

    # residual plots: one bar per sample of the report's baseline/final.residuals_mm
    for sel, block in (("#plot-before", "baseline"), ("#plot-after", "final")):
        assert len(rep[block]["residuals_mm"]) == rep["n_samples"] == N
        assert page.locator(f"{sel} svg rect.bar").count() == N
        assert page.locator(f"{sel} .no-data").count() == 0
    steps = page.locator("#plot-steps svg rect.step")
    assert steps.count() == 2 * (1 + len(rep["findings"]))

    shot = Path(os.environ.get("PENDANT_ANALYSIS_SCREENSHOT", tmp_path / "analysis-page.png"))
    shot.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(shot))
    assert shot.stat().st_size > 10_000

    # the stored report comes back by its address; an unknown one names the field
    page.goto(f"{site}/analysis.html?analysis={rep['id']}")
    idle(page)
    assert page.locator("#verdict").get_attribute("data-verdict") == "explained"
    assert page.locator("#findings li.finding").first.get_attribute("data-joint") == "2"
    page.goto(f"{site}/analysis.html?analysis=999")
    idle(page)
    assert page.locator("#upload-error code.loc").inner_text() == "analysis_id"
    assert "(404)" in page.locator("#upload-error").inner_text()


def test_a_best_fit_beyond_the_possible_is_shown_refused_not_explained(page, tmp_path) -> None:
    """A beam recording with a 150 ms trigger latency (limit 100 ms): the latency is listed as
    refused with its fitted value, the verdict is unexplained structure (tests/
    test_analysis_implausible.py has the report's side)."""
    imp = Imperfections(noise_mm=0.02, trigger_latency_ms=150.0)
    rec = tmp_path / "kuka-latency.json"
    rec.write_text(json.dumps(simulate_recording("beam", "kuka_kr6_r900_sixx", imp, 72, seed=1,
                                                 payload=(3.0, [0.0, 0.0, 60.0]))),
                   encoding="utf-8")
    upload(page, rec)
    assert page.locator("#verdict").get_attribute("data-verdict") == "unexplained_structure"
    rep = page.evaluate("window.analysisPage.report")
    refused = page.locator("#refused li")
    assert page.locator("#refused-panel").is_visible()
    assert refused.count() == len(rep["refused_as_implausible"]) > 0
    first = refused.first
    assert first.get_attribute("data-effect") == "trigger_latency"
    assert first.locator("strong").inner_text() == "Trigger latency"
    assert "150 ms, beyond what it can physically be (100 ms)" in first.inner_text()


def test_plots_draw_one_bar_per_sample_on_one_scale(page) -> None:
    """The drawing itself, with per-sample residuals put into the service's real report.

    (The report's per-sample fields are ``baseline.residuals_mm`` / ``final.residuals_mm``;
    this test replaces them in flight with known values so the drawing itself is checked.)
    """
    before = [0.2 + 0.01 * k for k in range(N)]
    after = [0.03 + 0.001 * (k % 5) for k in range(N)]

    def add_residuals(route) -> None:  # noqa: ANN001
        rep = route.fetch().json()
        rep["baseline"]["residuals_mm"] = before
        rep["final"]["residuals_mm"] = after
        route.fulfill(json=rep)

    page.route("**/analysis/*", add_residuals)  # the report, read from the job's result link
    page.get_by_role("button", name="Simulate example").click()
    idle(page)
    rep = page.evaluate("window.analysisPage.report")
    assert page.locator("#verdict").get_attribute("data-verdict") == rep["verdict"]

    b = page.locator("#plot-before svg rect.bar")
    a = page.locator("#plot-after svg rect.bar")
    assert b.count() == a.count() == N
    hb = [float(h) for h in b.evaluate_all("els => els.map(e => e.getAttribute('height'))")]
    ha = [float(h) for h in a.evaluate_all("els => els.map(e => e.getAttribute('height'))")]
    # one scale: bar heights are proportional to |r_k| across both plots
    scale = hb[-1] / before[-1]
    assert hb == pytest.approx([v * scale for v in before], rel=1e-6)
    assert ha == pytest.approx([v * scale for v in after], rel=1e-6)
    worst = page.locator("#plot-before svg rect.bar.worst")
    assert sorted(int(s) for s in worst.evaluate_all("els => els.map(e => e.dataset.sample)")) == \
        sorted(rep["locate"]["worst_samples"])
    assert page.locator("#plot-before svg rect.bar").nth(3).locator("title").text_content() == \
        f"sample 3: {before[3]:.3f} mm"

    page.get_by_label("Same scale for both plots").uncheck()  # each plot on its own scale
    ha2 = [float(h) for h in a.evaluate_all("els => els.map(e => e.getAttribute('height'))")]
    assert max(ha2) > 5 * max(ha)


@pytest.mark.parametrize("break_it, field, reason", [
    (lambda d: d["samples"][2]["measured_mm"].__setitem__(1, math.nan),
     "samples[2].measured_mm[1]", "not a finite number"),
    (lambda d: d["samples"][3].__setitem__("joints_deg", d["samples"][3]["joints_deg"][:5]),
     "samples[3].joints_deg", "has 5 values; the robot has 6 joints"),
], ids=["nan", "joint-count"])
def test_broken_recording_names_the_field_beside_the_upload_box(page, tmp_path, break_it,
                                                               field, reason) -> None:
    doc = compliant_ur10()
    break_it(doc)
    path = tmp_path / "broken.json"
    path.write_text(json.dumps(doc), encoding="utf-8")  # NaN written as NaN, as Python does
    upload(page, path)
    box = page.locator("#input-panel #upload-error")
    assert box.is_visible()
    assert box.locator("code.loc").first.inner_text() == field
    assert reason in box.inner_text()
    assert "(422)" in box.inner_text()
    assert page.locator("#report").is_hidden()
    assert page.get_by_label("or paste the JSON").get_attribute("aria-invalid") == "true"


def test_a_recording_too_short_to_analyse_names_the_field_and_starts_no_job(page) -> None:
    """Three samples are too few to analyse: the service refuses the recording with a 422
    naming ``samples`` (the analysis and the store share one minimum), so no job starts and
    no Cancel button shows. (A job that fails is shown the same way: tests/test_jobs.py.)"""
    doc = simulate_recording("tracker", "ur10", Imperfections(noise_mm=0.02), 3, seed=1)
    paste_and_analyse(page, json.dumps(doc))
    box = page.locator("#upload-error")
    assert box.is_visible() and "(422)" in box.inner_text()
    assert box.locator("code.loc").first.inner_text() == "samples"
    assert page.locator("#cancel-job").is_hidden()
    assert page.locator("#report").is_hidden()


def test_text_that_is_not_json_is_refused_with_its_line(page) -> None:
    paste_and_analyse(page, '{\n  "format": "robot-recording/1",\n  "kind": tracker\n}')
    box = page.locator("#upload-error")
    assert box.is_visible()
    assert "line 3" in box.locator("code.loc").inner_text()


def test_back_link_to_the_pendant(page) -> None:
    link = page.get_by_role("link", name=re.compile("Teach pendant"))
    assert link.get_attribute("href") == "/"


def test_download_the_model_and_harmonics_named_in_the_notes(page, tmp_path) -> None:
    """Issue 25: the report's fitted robot-model/1 downloads from the page, and the gear
    harmonics left out are named with their harmonics, not as twelve equal lines."""
    rec = tmp_path / "ur10-compliance.json"
    rec.write_text(json.dumps(compliant_ur10()), encoding="utf-8")
    upload(page, rec)
    button = page.get_by_role("button", name="Download the model")
    assert button.is_enabled()
    with page.expect_download() as info:
        button.click()
    idle(page)
    d = info.value
    rep = page.evaluate("window.analysisPage.report")
    assert d.suggested_filename == f"robot-model-{rep['id']}.json"
    model = json.loads(Path(d.path()).read_text(encoding="utf-8"))
    assert model["format"] == "robot-model/1"
    assert [(e["effect"], e["joint"]) for e in model["effects"]] == \
        [(f["effect"], f["joint"]) for f in rep["findings"]]
    gear_notes = page.locator('#not-identifiable li[data-effect="gear_transmission_error"]')
    titles = gear_notes.locator("strong").all_inner_texts()
    assert titles and len(set(titles)) == len(titles), titles
    assert all("per turn" in t for t in titles), titles
