"""The pendant page attacked from outside, in Debian's Chromium: what the probes found.

1. After "Log out" the Administrator's API answers (the tool table, /auth/me) stayed in the
   browser's HTTP cache: ``fetch(..., {cache: "only-if-cached"})`` on the login page read them
   back without any credential (the next person at a shared pendant PC). API answers are now
   ``Cache-Control: no-store``.
2. A slot name with a right-to-left override (U+202E, which the API and the file readers take:
   it is no control character) reversed the numbers that follow it on the same line: the
   history row of tool 5 "pen" + U+202E at x, y, z = 111, 222, 333 read "000.222 000.111 000.0 /
   000.333 ..." (measured with the rendered positions). The page now isolates such a name.
3. The first-start login link (``/login.html#token=...``) logged in whoever opened it: a link
   with Mallory's (an Operator's) token, opened by the Administrator logged in at the pendant,
   silently made the page Mallory's (/auth/me said mallory). Logged in already, the person is
   now asked first.
"""

from __future__ import annotations

import httpx

from api_helpers import ADMIN_TOKEN
from browser_helpers import browser_page, idle, log_in, open_pendant

RLO = "\u202e"


def api(site: str) -> httpx.Client:
    return httpx.Client(base_url=site, headers={"Authorization": f"Bearer {ADMIN_TOKEN}"})


def test_a_right_to_left_override_in_a_name_does_not_reorder_the_numbers(chromium, site):
    # a name a client types may not hold one (422, server.service.bounds.check_given_name);
    # a controller file's names are read as they are: the name comes in with a $config.dat
    http = api(site)
    text = http.get("/controllers/1/export", params={"format": "kuka"}).text
    text = text.replace("TOOL_DATA[5]={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}",
                        "TOOL_DATA[5]={X 111.0,Y 222.0,Z 333.0,A 0.0,B 0.0,C 0.0}")
    text = text.replace('TOOL_NAME[5,]=" "', f'TOOL_NAME[5,]="pen{RLO}"')
    r = http.post("/controllers/1/import", json={"format": "kuka", "text": text})
    assert r.status_code == 200, r.text
    assert http.get("/controllers/1/tools/5").json()["name"] == f"pen{RLO}"
    with browser_page(chromium, site) as page:
        open_pendant(page, site)
        page.locator("#tool-table tr[data-number='5']").click()
        idle(page)
        # where x, y and z of the history row's "after" are drawn: in reading order
        xs = page.evaluate("""() => {
          const td = [...document.querySelectorAll('#history-rows tbody td')]
            .find((t) => t.textContent.includes('111.000'));
          const at = {};
          const walk = document.createTreeWalker(td, NodeFilter.SHOW_TEXT);
          for (let n = walk.nextNode(); n; n = walk.nextNode()) {
            for (const s of ['111.000', '222.000', '333.000']) {
              const i = n.data.indexOf(s);
              if (i < 0) continue;
              const range = document.createRange();
              range.setStart(n, i);
              range.setEnd(n, i + s.length);
              const box = range.getBoundingClientRect();
              at[s] = [Math.round(box.y), box.x];  // line, then left to right
            }
          }
          return at;
        }""")
        assert xs["111.000"] < xs["222.000"] < xs["333.000"], xs  # (line, x) pairs
        # the name isolated (U+2068 ... U+2069): its override ends with it, whatever the
        # cell's width (in a narrow one each number is on a line of its own)
        cell = page.evaluate("""() => [...document.querySelectorAll('#history-rows tbody td')]
          .find((t) => t.textContent.includes('111.000')).textContent""")
        assert f"\u2068pen{RLO}\u2069" in cell, cell
        title = page.locator("#history-title").inner_text()
        assert title.endswith(": 1 change"), title  # the name does not swallow the rest


def test_after_log_out_the_api_answers_are_not_in_the_browser_cache(chromium, site):
    with browser_page(chromium, None) as page:
        page.context.set_default_timeout(15_000)
        page.goto(site + f"/login.html#token={ADMIN_TOKEN}")
        page.wait_for_url(site + "/")
        idle(page)
        page.get_by_role("button", name="Log out").click()
        page.wait_for_url(site + "/login.html")
        assert page.context.cookies() == []
        cached = page.evaluate("""async () => {
          const out = {};
          for (const p of ['/controllers/1/tools', '/auth/me', '/controllers']) {
            try {
              const r = await fetch(p, {cache: 'only-if-cached', mode: 'same-origin'});
              out[p] = r.status;
            } catch (e) { out[p] = 'not cached'; }
          }
          return out;
        }""")
        assert all(v != 200 for v in cached.values()), cached


def test_a_login_link_does_not_silently_swap_the_login_for_the_links_user(chromium, site):
    admin = api(site)
    r = admin.post("/users", json={"name": "mallory", "role": "Operator"})
    assert r.status_code == 201, r.text
    theirs = admin.post("/users/mallory/tokens", json={}).json()["token"]
    with browser_page(chromium, None) as page:
        log_in(page.context, site)  # the Administrator, logged in at the pendant
        asked: list[str] = []
        page.on("dialog", lambda d: (asked.append(d.message), d.dismiss()))
        page.goto(site + f"/login.html#token={theirs}")  # a link someone sent
        page.wait_for_url(site + "/")
        idle(page)
        assert page.request.get(site + "/auth/me").json()["user"] == "admin"
        assert len(asked) == 1 and "admin" in asked[0], asked
        assert theirs not in page.url
