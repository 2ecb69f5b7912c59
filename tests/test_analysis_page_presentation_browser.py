"""The analysis page as a person reads it (issue 14), in Debian's Chromium on the real UR10
laser-tracker recording: one analysis per file choice, titles that tell a2 from d2, p-values
and shares a person can read, the sign of a length in words, findings collapsed to one line
each (the strongest open), and chart labels no bigger than the body text at 800 px."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from browser_helpers import VIEWPORT, browser_page

UR10 = Path(__file__).resolve().parent / "data" / "ur10-laser-tracker" / "recording-series-d.json"


@pytest.fixture
def page(chromium, site: str):  # noqa: ANN001, ANN201
    with browser_page(chromium, site, timeout_ms=60_000) as p:
        p.posts = []  # the POSTs the page sent
        p.on("request", lambda r: p.posts.append(r.url) if r.method == "POST" else None)
        p.goto(site + "/analysis.html")
        idle(p)
        yield p


def idle(page) -> None:  # noqa: ANN001
    page.wait_for_function("() => window.analysisPage && window.analysisPage.pending === 0 "
                           "&& document.body.dataset.ready")


def test_the_ur10_report_reads_plainly(page):  # noqa: ANN001
    page.get_by_label("Held-out split").select_option("random")   # issue 11's report
    page.get_by_label("Upload a file").set_input_files(str(UR10))
    idle(page)
    # choosing the file only reads it (issue 27: it used to start the analysis, so the
    # person's Analyse then said "Already analysed")
    assert "press Analyse" in page.locator("#status").inner_text()
    assert page.locator("#report").is_hidden()
    assert sum("/analyze" in u for u in page.posts) == 0
    page.get_by_role("button", name="Analyse").click()
    idle(page)
    assert page.locator("#report").is_visible()
    assert sum("/analyze" in u for u in page.posts) == 1
    page.get_by_role("button", name="Analyse").click()  # same text, folds and seed: not again
    idle(page)
    assert sum("/analyze" in u for u in page.posts) == 1
    assert "Already analysed" in page.locator("#status").inner_text()

    rep = page.evaluate("window.analysisPage.report")
    assert rep["split"]["method"] == "random" and "split=random" in page.posts[-1]
    page.wait_for_function("() => document.querySelector('.sign-words')")  # the nominal DH arrived
    titles = page.locator("#findings .finding .title").all_inner_texts()
    assert len(titles) == len(set(titles)), titles  # a2 and d2 are two titles, not "Link length J2" twice
    lengths = [t for t in titles if t.startswith("Link length")]
    assert all(re.fullmatch(r"Link length J(\d) \([ad]\1\)", t) for t in lengths), lengths
    assert {t[-3] for t in lengths} == {"a", "d"}  # both kinds, each named by its parameter

    first = page.locator("#findings li.finding").first
    a2 = rep["findings"][0]
    assert (a2["effect"], a2["joint"], a2["parameters"]["dh_parameter"]) == ("link_length", 2, "a")
    sign = first.locator(".sign-words").inner_text()
    delta = a2["parameters"]["delta_mm"]  # a2 is negative in the table: -0.8 mm is 0.8 mm longer
    assert delta < 0 and re.search(rf"{abs(delta):.3f} mm longer", sign), (delta, sign)
    p_text = first.locator('[data-evidence="p_value"] td').inner_text()
    assert p_text == "< 1e-15", p_text  # not 3.9e-233
    shares = page.locator('[data-evidence="structure_share"] td').all_text_contents()
    assert shares and all(re.fullmatch(r"\d{1,3} %|all of it \(\d+ % of what the best generic group explains\)", s)
                          for s in shares), shares

    boxes = page.locator("#findings details.finding-box")
    assert boxes.count() == len(rep["findings"]) > 3
    assert boxes.first.get_attribute("open") is not None
    assert all(b.get_attribute("open") is None for b in boxes.all()[1:])
    head = page.locator("#findings .finding .headline").first.inner_text()
    assert re.fullmatch(rf"{delta:.4f} ± 0\.\d+ mm", head), head  # the value and its std
    height = page.evaluate("document.documentElement.scrollHeight")
    assert height < 3000, height  # 4,300 px with every finding open

    page.set_viewport_size({"width": 800, "height": VIEWPORT["height"]})
    body_px = page.evaluate("parseFloat(getComputedStyle(document.body).fontSize)")
    label_px = page.evaluate("""() => Math.max(...[...document.querySelectorAll('svg.chart text')].map(t => {
        const svg = t.ownerSVGElement;  // font size in the drawing times the drawing's scale on screen
        const scale = svg.getBoundingClientRect().width / svg.viewBox.baseVal.width;
        return parseFloat(getComputedStyle(t).fontSize) * scale;
    }))""")
    assert 0 < label_px <= body_px, (label_px, body_px)
