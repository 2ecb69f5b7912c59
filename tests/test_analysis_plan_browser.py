"""The analysis page's "Plan poses" panel in Debian's Chromium: a person plans poses for a
suspected joint-2 compliance, reads the predicted standard deviations, sees a bad effect
named, and starts a recording from the plan, which is analysed and shown.

The service runs for real (uvicorn, a temporary SQLite file); the first controller's hidden
physics is set to a joint-2 compliance through the API first.
"""

from __future__ import annotations

import json
import urllib.request

import pytest

from browser_helpers import auth_headers, browser_page


def _api(site: str, method: str, path: str, body: dict | None = None) -> object:
    req = urllib.request.Request(site + path, method=method,
                                 data=None if body is None else json.dumps(body).encode(),
                                 headers={"Content-Type": "application/json", **auth_headers()})
    with urllib.request.urlopen(req) as r:
        return json.loads(r.read() or b"null")


@pytest.fixture
def page(chromium, site: str):  # noqa: ANN001, ANN201
    with browser_page(chromium, site, timeout_ms=30_000) as p:  # logged in as the Administrator
        p.goto(site + "/analysis.html")
        yield p


def test_plan_then_record_then_read_the_analysis(page, site: str) -> None:  # noqa: ANN001
    cells = _api(site, "GET", "/controllers")
    if not cells:
        cells = [_api(site, "POST", "/controllers", {"name": "cell-p", "robot": "ur10"})]
    _api(site, "PUT", f"/controllers/{cells[0]['id']}/cell/physics",
         {"compliance_deg_per_Nm": [0, 1e-3, 0, 0, 0, 0], "noise_mm": 0.02})

    page.locator("#plan-effects").fill("joint_compliance:2, backlash:1")
    page.get_by_role("button", name="Plan", exact=True).click()
    page.wait_for_function("() => /refused/.test(document.querySelector('#plan-status').textContent)")
    assert "effects.backlash:1" in page.locator("#plan-status").inner_text()

    page.locator("#plan-effects").fill("joint_compliance:2, link_length:3")
    page.locator("#plan-n").fill("24")
    page.get_by_role("button", name="Plan", exact=True).click()
    page.wait_for_function("() => /poses for/.test(document.querySelector('#plan-status').textContent)")
    assert page.locator("#plan-std tr").filter(has_text="joint_compliance_j2").count() == 1
    assert page.locator("#plan-poses tr").count() == 24

    page.get_by_role("button", name="Record from plan").click()
    page.wait_for_url("**/analysis.html?analysis=*")
    page.wait_for_function("() => document.querySelector('#verdict') "
                           "&& document.querySelector('#verdict').dataset.verdict")
    assert "joint 2" in page.locator("#findings-panel").inner_text().lower()
