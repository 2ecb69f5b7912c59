"""``/docs`` in Debian's Chromium with every request to another host blocked (an offline robot
cell): Swagger UI's assets come from the package, and the page lists the API's operations."""

from __future__ import annotations

from urllib.parse import urlsplit

from browser_helpers import VIEWPORT


def test_api_docs_render_with_the_network_off(chromium, site):  # noqa: ANN001
    """Every request leaving 127.0.0.1 is aborted; Swagger UI and ReDoc still show the API."""
    context = chromium.new_context(viewport=VIEWPORT)
    context.set_default_timeout(15_000)
    here = urlsplit(site).netloc
    blocked: list[str] = []

    def only_this_host(route) -> None:  # noqa: ANN001
        if urlsplit(route.request.url).netloc == here:
            route.continue_()
        else:
            blocked.append(route.request.url)
            route.abort("internetdisconnected")

    context.route("**/*", only_this_host)
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        page.goto(site + "/docs")
        page.locator(".swagger-ui .information-container .title").wait_for()
        assert "pendant" in page.locator(".swagger-ui .information-container .title").inner_text()
        approach = page.locator(".opblock-summary-path", has_text="/robot/approach")
        approach.first.wait_for()
        assert page.locator(".opblock").count() > 20  # the operations, not an empty frame
        assert not blocked, f"/docs fetched from other hosts: {blocked}"

        page.goto(site + "/redoc")
        page.get_by_role("heading", name="pendant (0", exact=False).first.wait_for()
        page.get_by_text("/controllers/{controller_id}/robot/approach").first.wait_for(state="attached")
        # ReDoc's footer asks its maker's CDN for a logo; the page renders without it
        assert [u for u in blocked if not u.endswith("/redoc/logo-mini.svg")] == [], blocked
        assert not errors, errors
    finally:
        context.close()
