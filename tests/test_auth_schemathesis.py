"""schemathesis over the live OpenAPI, as each default role: no input makes a 500.

A bounded run for CI: two generated examples per operation and role (about 100 requests a
role). The longer run by hand is ``bash benchmarks/fuzz.sh [SECONDS] [PORT] [ROLE]`` (figures
in docs/security.md).

The operations are walked here with schemathesis's own strategies and hypothesis's ``given``,
not through schemathesis's pytest plugin (``schema.parametrize``): the plugin reaches into
pytest's internals, and pytest 9.2 broke it (``'Function' object has no attribute
'_nodeid'`` with schemathesis 4.32.5), so a newcomer's first run on the newest releases failed.
"""

from __future__ import annotations

import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from schemathesis.checks import not_a_server_error

from api_helpers import ADMIN_TOKEN, app_settings
from server.api.app import create_app

ROLES = ("Operator", "Programmer", "Expert", "Administrator")
EXAMPLES = settings(max_examples=2, deadline=None, suppress_health_check=list(HealthCheck),
                    phases=[Phase.generate], database=None)


@pytest.fixture(scope="module")
def fuzzed(tmp_path_factory):  # noqa: ANN001, ANN201
    """The live OpenAPI schema of a fresh service and one token per default role."""
    from fastapi.testclient import TestClient

    app = create_app(app_settings(f"sqlite:///{tmp_path_factory.mktemp('fuzz') / 'p.db'}"))
    headers = {}
    with TestClient(app, headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}) as admin:
        for role in ROLES:
            name = f"fuzz-{role.lower()}"
            admin.post("/users", json={"name": name, "role": role}).raise_for_status()
            token = admin.post(f"/users/{name}/tokens", json={}).json()["token"]
            headers[role] = {"Authorization": f"Bearer {token}"}
    return schemathesis.openapi.from_asgi("/openapi.json", app), headers


def test_no_server_error_as_any_role(fuzzed):  # noqa: ANN001
    schema, headers = fuzzed
    operations = [result.ok() for result in schema.get_all_operations()]
    answered: dict[str, int] = {}
    failures = []
    for operation in operations:
        @EXAMPLES
        @given(case=operation.as_strategy())
        def as_each_role(case):  # noqa: ANN001, ANN202
            for role in ROLES:
                response = case.call(headers=headers[role])
                answered[operation.label] = answered.get(operation.label, 0) + 1
                case.validate_response(response, checks=[not_a_server_error])

        try:
            as_each_role()
        except Exception as exc:  # noqa: BLE001 -- every operation's failure listed, not the first
            failures.append(f"{operation.label}: {exc}")
    assert not failures, "\n\n".join(failures)
    assert len(operations) > 50 and set(answered) == {op.label for op in operations}
