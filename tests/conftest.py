"""Shared fixtures: the robot library, a seeded random generator, and for the browser
tests a live service on a temporary SQLite file with Debian's Chromium."""

from __future__ import annotations

import numpy as np
import pytest

from solvers.robots import ROBOTS


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture(params=sorted(ROBOTS))
def robot(request):
    """Every arm of the library in turn."""
    return ROBOTS[request.param]


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201
    """The real service (uvicorn, loopback, free port) on a fresh database per module."""
    from browser_helpers import serve

    from db_backends import fresh_url

    with serve(fresh_url(tmp_path_factory.mktemp("site"))) as url:
        yield url


@pytest.fixture(scope="module")
def chromium():  # noqa: ANN201
    """Headless Debian Chromium under Playwright (never a downloaded browser)."""
    from browser_helpers import browser

    with browser() as b:
        yield b
