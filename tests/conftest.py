"""Shared fixtures: the robot library and a seeded random generator."""

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
