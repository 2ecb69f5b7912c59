"""The pendant page attacked from outside, in Debian's Chromium: what the probes found.

1. After "Log out" the Administrator's API answers (the tool table, /auth/me) stayed in the
   browser's HTTP cache: ``fetch(..., {cache: "only-if-cached"})`` on the login page read them
   back without any credential (the next person at a shared pendant PC). API answers are now
   ``Cache-Control: no-store``.
"""

from __future__ import annotations

from api_helpers import ADMIN_TOKEN
from browser_helpers import browser_page, idle


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
