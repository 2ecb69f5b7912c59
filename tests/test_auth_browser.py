"""Cross-site writes in Debian's Chromium (issue 9): a person logged in to the pendant opens a
page of another origin (a second loopback server on another port: the same *site*, so the
SameSite=Strict login cookie does go along). The page fires the bodyless commands with
``fetch(..., {mode: "no-cors", credentials: "include"})`` and a form POST; nothing changes.

Also the first-start login link: ``/login.html#token=...`` logs the browser in and lands on the
pendant with the user shown, and each slot says "changed by USER at TIME".
"""

from __future__ import annotations

import functools
import re
import threading
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

import httpx
import pytest

from api_helpers import ADMIN_TOKEN, calibrate, ok, open_session, walk
from browser_helpers import VIEWPORT, free_port, idle

ATTACK = """<!doctype html><html><head><meta charset="utf-8"><title>cat pictures</title></head>
<body><iframe name="sink"></iframe>
<form id="f" method="post" target="sink" action="{site}/controllers/1/robot/home"></form>
<script>
const A = "{site}";
const paths = {paths};
(async () => {{
  await Promise.allSettled(paths.map((p) => fetch(A + p, {{method: "POST", mode: "no-cors",
    credentials: "include"}})));
  await Promise.allSettled([
    fetch(A + "/controllers/1/robot/jog", {{method: "POST", mode: "no-cors", credentials: "include",
      headers: {{"Content-Type": "text/plain"}},
      body: JSON.stringify({{mode: "joint", axis: "A1", increment: 10}})}}),
    fetch(A + "/controllers/1/robot/home", {{method: "POST", credentials: "include",
      headers: {{"X-CSRF-Token": "guess"}}}}),  // needs a preflight, which the service refuses
  ]);
  document.getElementById("f").submit();
  setTimeout(() => {{ document.title = "done"; }}, 1500);
}})();
</script></body></html>"""


@pytest.fixture
def attacker(tmp_path):  # noqa: ANN001, ANN201
    """A second loopback server on another port serving ``tmp_path``: another origin."""
    handler = functools.partial(SimpleHTTPRequestHandler, directory=str(tmp_path))
    handler.log_message = lambda *a: None  # type: ignore[attr-defined]
    server = ThreadingHTTPServer(("127.0.0.1", free_port()), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield tmp_path, f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()


def snapshot(api: httpx.Client, sid: int) -> dict:
    return {"robot": ok(api.get("/controllers/1/robot"))["joints_deg"],
            "tool1": ok(api.get("/controllers/1/tools/1")),
            "history": ok(api.get("/controllers/1/tools/1/history")),
            "session": ok(api.get(f"/controllers/1/sessions/{sid}"))["state"],
            "points": len(ok(api.get(f"/controllers/1/sessions/{sid}"))["steps"]),
            "audit": len(ok(api.get("/audit", params={"limit": 100000})))}


def test_cross_origin_page_changes_nothing(chromium, site, attacker):  # noqa: ANN001
    api = httpx.Client(base_url=site, headers={"Authorization": f"Bearer {ADMIN_TOKEN}"})
    calibrate(api, "tool.xyz_4point", 1)  # tool 1 has a history entry to restore
    ok(api.put("/controllers/1/tools/1", json={"name": "pointer"}, headers={"If-Match": "*"}))
    url = open_session(api, "tool.xyz_4point", 1)
    walk(api, url)
    ok(api.post(f"{url}/compute"))  # a computed session a forged save would write
    sid = int(url.rsplit("/", 1)[1])
    hid = ok(api.get("/controllers/1/tools/1/history"))[-1]["id"]
    before = snapshot(api, sid)

    context = chromium.new_context(viewport=VIEWPORT)
    context.set_default_timeout(15_000)
    page = context.new_page()
    # the person logs in with the first start's link and works at the pendant
    page.goto(f"{site}/login.html#token={ADMIN_TOKEN}")
    page.wait_for_url(f"{site}/")
    idle(page)
    assert page.locator("#who").inner_text().startswith("admin · Administrator")
    cookies = {c["name"]: c for c in context.cookies()}
    assert cookies["pendant_session"]["httpOnly"] and cookies["pendant_session"]["sameSite"] == "Strict"
    before = snapshot(api, sid)  # the login itself is audited; nothing after it may be

    # ... and opens another origin's page in the same browser
    root, evil = attacker
    paths = [f"/controllers/1/tools/1/restore/{hid}", "/controllers/1/robot/home",
             f"/controllers/1/sessions/{sid}/save", f"/controllers/1/sessions/{sid}/compute",
             f"/controllers/1/sessions/{sid}/touch-up", f"/controllers/1/sessions/{sid}/discard"]
    (root / "index.html").write_text(ATTACK.format(site=site, paths=paths))
    seen: list[tuple[str, str, int]] = []
    other = context.new_page()
    other.on("response", lambda r: seen.append((r.request.method, r.url, r.status))
             if r.url.startswith(site) else None)
    other.goto(evil + "/index.html")
    other.wait_for_function("document.title === 'done'")

    posts = [(m, u.removeprefix(site), s) for m, u, s in seen if m == "POST"]
    assert {u for _, u, _ in posts} >= set(paths) | {"/controllers/1/robot/jog"}, posts
    assert all(s == 403 for _, _, s in posts), posts  # refused: another origin's command
    assert sum(u == "/controllers/1/robot/home" for _, u, _ in posts) >= 2  # fetch and form
    assert snapshot(api, sid) == before

    # control: the same command from the pendant's own page goes through
    joints = page.evaluate("""async () => {
        const csrf = document.cookie.match(/pendant_csrf=([^;]*)/)[1];
        const r = await fetch("/controllers/1/robot/home", {method: "POST",
            headers: {"X-CSRF-Token": decodeURIComponent(csrf)}});
        return [r.status, (await r.json()).joints_deg];
    }""")
    assert joints[0] == 200 and joints[1] != before["robot"]

    # the pendant shows who changed each slot
    page.reload()
    idle(page)
    row = page.locator("#tool-table tr[data-number='1'] .changed").text_content()
    assert re.fullmatch(r"changed by admin at \d{4}-\d\d-\d\d \d\d:\d\d", row), row
    context.close()
