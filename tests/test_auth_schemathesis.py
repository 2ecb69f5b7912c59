"""schemathesis over the live OpenAPI, as an authenticated Expert: no input makes a 500.

A bounded run for CI: two generated examples per operation (about 100 requests, ~15 s).
The longer run by hand is ``bash benchmarks/fuzz.sh [SECONDS]`` (figures in docs/security.md).
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, settings
from schemathesis.checks import not_a_server_error

from api_helpers import ADMIN_TOKEN, app_settings
from server.app import create_app

EXPERT: dict[str, str] = {}


@pytest.fixture(scope="module")
def api_schema(tmp_path_factory):  # noqa: ANN001, ANN201
    from fastapi.testclient import TestClient

    app = create_app(app_settings(f"sqlite:///{tmp_path_factory.mktemp('fuzz') / 'p.db'}"))
    with TestClient(app, headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}) as admin:
        admin.post("/users", json={"name": "fuzz", "role": "Expert"}).raise_for_status()
        token = admin.post("/users/fuzz/tokens", json={}).json()["token"]
    EXPERT["Authorization"] = f"Bearer {token}"
    return schemathesis.openapi.from_asgi("/openapi.json", app)


schema = schemathesis.pytest.from_fixture("api_schema")


@schema.parametrize()
@settings(max_examples=2, deadline=None, suppress_health_check=list(HealthCheck),
          phases=[Phase.generate])
def test_no_server_error_as_an_expert(case):  # noqa: ANN001
    response = case.call(headers=EXPERT)
    case.validate_response(response, checks=[not_a_server_error])
