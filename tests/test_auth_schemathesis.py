"""schemathesis over the live OpenAPI, as each default role: no input makes a 500.

A bounded run for CI: two generated examples per operation and role (about 100 requests a
role). The longer run by hand is ``bash benchmarks/fuzz.sh [SECONDS] [PORT] [ROLE]`` (figures
in docs/security.md).
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, settings
from schemathesis.checks import not_a_server_error

from api_helpers import ADMIN_TOKEN, app_settings
from server.api.app import create_app

ROLES = ("Operator", "Programmer", "Expert", "Administrator")
HEADERS: dict[str, dict[str, str]] = {}


@pytest.fixture(scope="module")
def api_schema(tmp_path_factory):  # noqa: ANN001, ANN201
    from fastapi.testclient import TestClient

    app = create_app(app_settings(f"sqlite:///{tmp_path_factory.mktemp('fuzz') / 'p.db'}"))
    with TestClient(app, headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}) as admin:
        for role in ROLES:
            name = f"fuzz-{role.lower()}"
            admin.post("/users", json={"name": name, "role": role}).raise_for_status()
            token = admin.post(f"/users/{name}/tokens", json={}).json()["token"]
            HEADERS[role] = {"Authorization": f"Bearer {token}"}
    return schemathesis.openapi.from_asgi("/openapi.json", app)


schema = schemathesis.pytest.from_fixture("api_schema")


@schema.parametrize()
@settings(max_examples=2, deadline=None, suppress_health_check=list(HealthCheck),
          phases=[Phase.generate])
def test_no_server_error_as_any_role(case):  # noqa: ANN001
    for role in ROLES:
        response = case.call(headers=HEADERS[role])
        case.validate_response(response, checks=[not_a_server_error])
