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


def test_docs_authorize_then_try_it_out_changes_a_slot(chromium, site):  # noqa: ANN001
    """``/docs`` as a client (issue 27): *Authorize* with an API token, then *Try it out* on
    ``PUT /controllers/{id}/tools/{number}``: the slot is changed (200), as the API reads it."""
    import httpx

    from api_helpers import ADMIN_TOKEN

    context = chromium.new_context(viewport=VIEWPORT)
    context.set_default_timeout(15_000)
    page = context.new_page()
    try:
        page.goto(site + "/docs")
        page.locator(".swagger-ui .btn.authorize").first.click()
        bearer = page.locator(".auth-container", has_text="bearer")
        bearer.locator("input").first.fill(ADMIN_TOKEN)
        bearer.locator("button.authorize").click()  # "Authorize" (aria-label: Apply credentials)
        page.locator(".auth-btn-wrapper .btn-done").first.click()  # "Close"
        op = page.locator(".opblock-put").filter(
            has=page.locator('[data-path="/controllers/{controller_id}/tools/{number}"]'))
        op.locator(".opblock-summary").first.click()
        op.get_by_role("button", name="Try it out").click()
        op.locator('tr[data-param-name="controller_id"] input').fill("1")
        op.locator('tr[data-param-name="number"] input').fill("7")
        op.locator('tr[data-param-name="If-Match"] input').fill("*")
        op.locator("textarea.body-param__text").fill(
            '{"name": "from-docs", "pose": {"x": 1, "y": 2, "z": 150, "a": 0, "b": 0, "c": 0}}')
        op.get_by_role("button", name="Execute").click()
        status = op.locator(".live-responses-table tbody .response-col_status").first
        status.wait_for()
        assert status.inner_text().strip().startswith("200"), status.inner_text()
    finally:
        context.close()
    slot = httpx.get(f"{site}/controllers/1/tools/7",
                     headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}).json()
    assert slot["name"] == "from-docs" and slot["pose"]["z"] == 150
