"""The pendant page in a real browser: the service under uvicorn, Debian's Chromium under
Playwright, and a person's clicks (open a menu, Move to, Touch up, Compute, Save).

The browser is ``/usr/bin/chromium`` (``tests/run`` installs Debian's package); Playwright
never downloads one. A missing Chromium is a test failure with the reason, not a skip.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
VIEWPORT = {"width": 1280, "height": 900}


def auth_headers() -> dict[str, str]:
    """The first Administrator's bearer token, for a browser context (extra_http_headers)."""
    from api_helpers import ADMIN_TOKEN

    return {"Authorization": f"Bearer {ADMIN_TOKEN}"}


def log_in(context, site: str, token: str | None = None) -> dict:  # noqa: ANN001
    """Log the browser context in as the login page does (the session and CSRF cookies).

    Chromium sends no extra_http_headers with a download, so a page that downloads needs
    the cookie login too."""
    from api_helpers import ADMIN_TOKEN

    r = context.request.post(site + "/auth/login", data={"token": token or ADMIN_TOKEN})
    assert r.ok, r.text()
    return r.json()


def chromium_path() -> str:
    """The Chromium executable; fails the test with the fix when it is missing."""
    import pytest

    path = os.environ.get("PENDANT_CHROMIUM", CHROMIUM)
    if not (Path(path).is_file() and os.access(path, os.X_OK)):
        found = shutil.which("chromium")
        if found is None:
            pytest.fail(f"Chromium not found at {path}: the browser tests drive Debian's chromium "
                        "(apt-get install chromium, or run bash tests/run, which installs it)", pytrace=False)
        path = found
    return path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def serve(db_url: str | None = None, app: object | None = None) -> Iterator[str]:
    """The real service (create_app on ``db_url``, its first Administrator's token is
    api_helpers.ADMIN_TOKEN) or ``app`` under uvicorn in a thread, with a ``pendant worker``
    process for its jobs (analyses, restores); yields its URL."""
    import subprocess
    import sys

    import uvicorn
    from api_helpers import app_settings

    from server.api.app import create_app

    port = free_port()
    app = app if app is not None else create_app(app_settings(db_url))
    config = uvicorn.Config(app, host="127.0.0.1", port=port,
                            log_level="warning", lifespan="off")
    server = uvicorn.Server(config)
    thread = threading.Thread(target=server.run, name="pendant-uvicorn", daemon=True)
    thread.start()
    ready = threading.Event()
    for _ in range(500):  # started is set once the socket listens
        if server.started or not thread.is_alive():
            break
        ready.wait(0.01)
    if not server.started:
        raise RuntimeError(f"uvicorn did not start on 127.0.0.1:{port}")
    root = Path(__file__).resolve().parent.parent
    env = {**os.environ, "PYTHONPATH": f"{root}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    worker = subprocess.Popen([sys.executable, "-m", "server.cli", "worker", "--db",
                               app.state.settings.db_url, "--processes", "1"], env=env)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        worker.terminate()
        worker.wait(timeout=30)
        server.should_exit = True
        thread.join(timeout=10)


@contextmanager
def browser() -> Iterator[object]:
    """Headless Debian Chromium under Playwright (no browser download)."""
    from playwright.sync_api import sync_playwright

    path = chromium_path()
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=path, headless=True, args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


@contextmanager
def browser_page(chromium, site: str | None = None, timeout_ms: int = 15_000,  # noqa: ANN001
                 **context_options) -> Iterator[object]:
    """A page in a fresh context (VIEWPORT), logged in to ``site`` as its first Administrator
    (the login link's cookie, and the bearer header); fails the test if the page threw a
    JavaScript error."""
    if site is not None:
        context_options.setdefault("extra_http_headers", auth_headers())
    context = chromium.new_context(viewport=VIEWPORT, **context_options)
    if site is not None:
        log_in(context, site)  # a download carries the login cookie, not the bearer header
    context.set_default_timeout(timeout_ms)
    p = context.new_page()
    errors: list[str] = []
    p.on("pageerror", lambda e: errors.append(str(e)))
    try:
        yield p
    finally:
        context.close()
    assert not errors, f"JavaScript errors on the page: {errors}"


# ------------------------------------------------------------------------------ the person

def idle(page) -> None:  # noqa: ANN001
    """Wait until the page has no request in flight."""
    page.wait_for_function("() => window.pendant && window.pendant.pending === 0 && document.body.dataset.ready")


def open_pendant(page, url: str):  # noqa: ANN001, ANN201
    page.goto(url + "/")
    idle(page)
    return page


def wizard(page):  # noqa: ANN001, ANN201
    return page.locator("#wizard")


def open_menu(page, method: str, target_no: int, **params: int) -> None:  # noqa: ANN001
    """Pick the menu, the slot and its params, then Open session."""
    w = wizard(page)
    w.get_by_label("Menu").select_option(method)
    w.get_by_label("Target number").fill(str(target_no))
    for name, value in params.items():
        w.locator(f'#params [name="{name}"]').fill(str(value))
    w.get_by_role("button", name="Open session").click()
    idle(page)


def walk_steps(page, n_steps: int) -> None:  # noqa: ANN001
    """For each step: read the prompt, Move to (the emulator's careful jogging), Touch up."""
    w = wizard(page)
    for k in range(n_steps):
        label = w.locator("#step-label")
        assert label.text_content().startswith(f"Step {k + 1} of {n_steps}"), label.text_content()
        w.get_by_role("button", name="Move to", exact=True).click()
        idle(page)
        assert w.locator("#current .err").first.inner_text() == "", w.locator("#current").inner_text()
        w.get_by_role("button", name="Touch up", exact=True).click()
        idle(page)
        assert w.get_by_role("button", name=re.compile(rf"^Step {k + 1}: .* \(taught\)$")).count() == 1


def compute(page):  # noqa: ANN001, ANN201
    wizard(page).get_by_role("button", name="Compute").click()
    idle(page)
    return page.locator("#report")


def save(page) -> None:  # noqa: ANN001
    page.locator("#report").get_by_role("button", name="Save").click()
    idle(page)


KUKA_FRAME = r"{array}\[{n}\]=\{{X ([^,]+),Y ([^,]+),Z ([^,]+),A ([^,]+),B ([^,]+),C ([^}}]+)\}}"


def kuka_frame(text: str, array: str, number: int) -> list[float]:
    """X, Y, Z, A, B, C of ``TOOL_DATA[n]`` / ``BASE_DATA[n]`` in a ``$config.dat`` text."""
    m = re.search(KUKA_FRAME.format(array=array, n=number), text)
    assert m, f"{array}[{number}] not in the export"
    return [float(v) for v in m.groups()]
