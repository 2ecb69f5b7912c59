"""Every route of the live OpenAPI x every role -> the expected status (issue 9, item 5).

The permission a route needs comes from ONE table, server/auth/permissions.py ``ROUTES``; a route
missing from it fails ``test_every_route_declares_a_permission`` (and is refused at run time).
Path parameters name things that do not exist (controller 999, ...), so a request the guard
lets through ends in 404/422 and changes nothing; the guard's refusals are 401 and 403.
"""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from api_helpers import make_client, ok
from server.auth.permissions import DEFAULT_ROLES, PERMISSIONS, PUBLIC, ROUTES, SIGNED_IN

ROLES = list(DEFAULT_ROLES)
PATH_VALUES = {"controller_id": "999", "number": "1", "history_id": "999", "session_id": "999",
               "step": "0", "recording_id": "999", "analysis_id": "999",
               "user_name": "nobody", "job_id": "999", "webhook_id": "999"}


def operations(app) -> list[tuple[str, str]]:  # noqa: ANN001
    return sorted((m.upper(), p) for p, ops in app.openapi()["paths"].items() for m in ops)


def concrete(path: str) -> str:
    return re.sub(r"\{(\w+)\}", lambda m: PATH_VALUES[m.group(1)], path)


@pytest.fixture(scope="module")
def world(fresh_db):  # noqa: ANN001, ANN201
    """The app with one user and token per default role."""
    with make_client(fresh_db("perm")) as admin:  # noqa: F405
        tokens = {}
        for role in ROLES:
            name = role.lower()
            ok(admin.post("/users", json={"name": name, "role": role}))  # noqa: F405
            tokens[role] = ok(admin.post(f"/users/{name}/tokens", json={}))["token"]  # noqa: F405
        yield admin, tokens


def call(client, method: str, path: str, token: str | None):  # noqa: ANN001, ANN201
    """``method path`` with a bearer ``token``, or with no credential at all (None)."""
    kw = {"json": {}} if method in ("POST", "PUT") else {}
    if token is None:
        with TestClient(client.app, raise_server_exceptions=False) as anonymous:
            return anonymous.request(method, concrete(path), **kw)
    return client.request(method, concrete(path), headers={"Authorization": f"Bearer {token}"},
                          **kw)


def test_every_route_declares_a_permission(world):  # noqa: ANN001
    admin, _ = world
    missing = [op for op in operations(admin.app) if op not in ROUTES]
    assert not missing, f"routes without a permission in server/auth/permissions.py: {missing}"
    pages = {("GET", "/"), ("GET", "/{name}"), ("GET", "/docs"), ("GET", "/docs/oauth2-redirect"),
             ("GET", "/redoc")}  # the pendant page, its files and the API docs (not in the OpenAPI)
    stale = [op for op in ROUTES if op not in operations(admin.app) and op not in pages]
    assert not stale, f"permissions declared for routes that do not exist: {stale}"
    assert all(v in PERMISSIONS or v in (PUBLIC, SIGNED_IN) for v in ROUTES.values())


def test_every_route_times_every_role(world):  # noqa: ANN001
    """No credential: 401 (public routes excepted); a role without the route's permission: 403;
    a role with it: neither (the request reaches the route)."""
    admin, tokens = world
    wrong = []
    for method, path in operations(admin.app):
        need = ROUTES[(method, path)]
        r = call(admin, method, path, None)
        if need != PUBLIC and r.status_code != 401:
            wrong.append((method, path, "anonymous", r.status_code))
        for role in ROLES:
            r = call(admin, method, path, tokens[role])
            allowed = need in (PUBLIC, SIGNED_IN) or need in DEFAULT_ROLES[role]
            if allowed and r.status_code in (401, 403) or not allowed and r.status_code != 403:
                wrong.append((method, path, role, r.status_code, r.text[:120]))
    assert not wrong, wrong


# the roles as the issue states them, written out independently of DEFAULT_ROLES
ALL = {"Operator", "Programmer", "Expert", "Administrator"}
ISSUE = [
    ("PUT", "/controllers/1/tools/1", {"name": "t"}, {"Expert", "Administrator"}),
    ("POST", "/controllers/1/robot/jog", {"mode": "joint", "axis": "A1", "increment": 1.0}, ALL),
    ("POST", "/controllers/1/sessions", {"method": "tool.xyz_4point", "target_no": 2},
     {"Programmer", "Expert", "Administrator"}),
    ("POST", "/controllers/1/sessions/999/run-cycle", {}, ALL),  # the Operator's light barrier
    ("PUT", "/controllers/1/cell/physics", {}, {"Administrator"}),
    ("POST", "/controllers", {"name": "cell-x", "robot": "kuka_kr6_r900_sixx"}, {"Administrator"}),
    ("POST", "/controllers/1/import", {"format": "kuka", "text": "x"}, {"Expert", "Administrator"}),
    ("GET", "/audit", None, {"Administrator"}),
    ("GET", "/controllers/1/cell/clock", None, {"Administrator"}),  # emulator:physics (issue 21)
    ("POST", "/users", {"name": "x", "role": "Operator"}, {"Administrator"}),
]


@pytest.mark.parametrize("method,path,body,allowed", ISSUE,
                         ids=[f"{m} {p}" for m, p, _, _ in ISSUE])
def test_roles_as_the_issue_states_them(world, method, path, body, allowed):  # noqa: ANN001
    admin, tokens = world
    for role in ROLES:
        r = admin.request(method, path, json=body,
                          headers={"Authorization": f"Bearer {tokens[role]}"})
        assert (r.status_code != 403) == (role in allowed), (role, r.status_code, r.text)


def test_json_backup_needs_backup_permissions(world):  # noqa: ANN001
    """A controller file is data:import (Expert); a JSON backup is backup:write to export and
    backup:restore to import (Administrator), the same route with another format."""
    admin, tokens = world
    expert = {"Authorization": f"Bearer {tokens['Expert']}"}
    assert admin.get("/controllers/1/export?format=kuka", headers=expert).status_code == 200
    r = admin.get("/controllers/1/export?format=json", headers=expert)
    assert r.status_code == 403 and "backup:write" in r.json()["detail"][0]["msg"]
    text = admin.get("/controllers/1/export?format=json").text
    r = admin.post("/controllers/1/import", json={"format": "json", "text": text}, headers=expert)
    assert r.status_code == 403 and "backup:restore" in r.json()["detail"][0]["msg"]
    assert admin.post("/controllers/1/import", json={"format": "json", "text": text}).status_code \
        == 202  # the restore is queued as a job


def test_docs_route_table_is_the_permission_table():
    """docs/security.md's "Every route" table holds exactly server/auth/permissions.py's ROUTES
    (issue 21, item 7: three routes were missing, and the docs put the clock under
    emulator:physics while the code let every role read it). Regenerate the table with
    ``python -m server.auth.permissions``."""
    import re
    from pathlib import Path

    from server.auth.permissions import markdown_table

    text = (Path(__file__).resolve().parent.parent / "docs" / "security.md").read_text()
    m = re.search(r"<!-- routes: [^>]*-->\n(.*?)<!-- /routes -->", text, re.S)
    assert m, "docs/security.md has no generated route table"
    documented = {}
    for line in m.group(1).splitlines()[2:]:
        method, path, need = (c.strip() for c in line.strip("|").split("|"))
        documented[(method, path.strip("`"))] = need.strip("`").split(" ")[0]
    code = {op: {"public": "public", "signed-in": "any"}.get(v, v) for op, v in ROUTES.items()}
    assert {op: v for op, v in documented.items() if code.get(op) != v} == {}, \
        "docs/security.md differs from ROUTES: run python -m server.auth.permissions"
    assert set(code) - set(documented) == set(), "routes missing from docs/security.md"
    assert m.group(1) == markdown_table()
