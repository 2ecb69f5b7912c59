"""The permissions, the default roles modelled on the controllers' user groups, and the one
table that says which permission every route needs (docs/security.md).

A route missing from ``ROUTES`` is refused to everyone (403 naming the gap), and the
table-driven test (tests/test_auth_permissions.py) fails for it: a new route must be declared here.
"""

from __future__ import annotations

from typing import Final, Literal

Permission = Literal["frames:read", "robot:jog", "sessions:run", "frames:commit", "data:import",
                     "backup:write", "backup:restore", "emulator:physics", "controllers:admin",
                     "users:admin", "audit:read"]
PERMISSIONS: Final[tuple[str, ...]] = Permission.__args__  # type: ignore[attr-defined]

PUBLIC: Final = "public"  # no credentials: the pages, the login itself
SIGNED_IN: Final = "signed-in"  # any valid credential, whatever its role (who am I, log out)

OPERATOR = ("frames:read", "robot:jog")  # light-barrier cycle: robot:jog (a measuring motion)
PROGRAMMER = OPERATOR + ("sessions:run",)
EXPERT = PROGRAMMER + ("frames:commit", "data:import")
DEFAULT_ROLES: Final[dict[str, tuple[str, ...]]] = {
    "Operator": OPERATOR,
    "Programmer": PROGRAMMER,
    "Expert": EXPERT,
    "Administrator": PERMISSIONS,
}
IDLE_ROLE: Final = "Operator"  # what a browser login drops to after the idle timeout

C = "/controllers/{controller_id}"
S = C + "/sessions/{session_id}"

# (method, path template as in the OpenAPI) -> the permission it needs
ROUTES: Final[dict[tuple[str, str], str]] = {
    ("GET", "/"): PUBLIC,
    ("GET", "/{name}"): PUBLIC,  # the page's files (web/), not in the OpenAPI
    ("GET", "/docs"): PUBLIC,  # the API docs (Swagger UI, ReDoc), served offline
    ("GET", "/docs/oauth2-redirect"): PUBLIC,
    ("GET", "/redoc"): PUBLIC,
    ("POST", "/auth/login"): PUBLIC,
    ("POST", "/auth/logout"): SIGNED_IN,
    ("GET", "/auth/me"): SIGNED_IN,
    ("GET", "/audit"): "audit:read",
    ("GET", "/users"): "users:admin",
    ("POST", "/users"): "users:admin",
    ("DELETE", "/users/{user_name}"): "users:admin",
    ("POST", "/users/{user_name}/tokens"): "users:admin",
    ("GET", "/roles"): "users:admin",
    ("GET", "/controllers"): "frames:read",
    ("POST", "/controllers"): "controllers:admin",
    ("GET", C): "frames:read",
    ("DELETE", C): "controllers:admin",
    ("GET", C + "/cell"): "frames:read",
    ("GET", C + "/cell/physics"): "emulator:physics",
    ("PUT", C + "/cell/physics"): "emulator:physics",
    ("GET", C + "/cell/clock"): "emulator:physics",  # the hidden state's clock (thermal drift)
    ("PUT", C + "/cell/clock"): "emulator:physics",
    ("GET", C + "/robot"): "frames:read",
    ("PUT", C + "/robot/joints"): "robot:jog",
    ("POST", C + "/robot/home"): "robot:jog",
    ("POST", C + "/robot/jog"): "robot:jog",
    ("PUT", C + "/robot/active"): "robot:jog",
    ("POST", C + "/robot/approach"): "robot:jog",
    ("GET", C + "/tools"): "frames:read",
    ("GET", C + "/tools/{number}"): "frames:read",
    ("PUT", C + "/tools/{number}"): "frames:commit",
    ("GET", C + "/tools/{number}/history"): "frames:read",
    ("POST", C + "/tools/{number}/restore/{history_id}"): "frames:commit",
    ("GET", C + "/bases"): "frames:read",
    ("GET", C + "/bases/{number}"): "frames:read",
    ("PUT", C + "/bases/{number}"): "frames:commit",
    ("GET", C + "/bases/{number}/history"): "frames:read",
    ("POST", C + "/bases/{number}/restore/{history_id}"): "frames:commit",
    ("GET", C + "/fixed-tools"): "frames:read",
    ("GET", C + "/workpieces"): "frames:read",
    ("PUT", C + "/robot/external"): "robot:jog",
    ("GET", C + "/cell/external"): "emulator:physics",
    ("PUT", C + "/cell/external"): "emulator:physics",
    ("GET", C + "/external-kinematics"): "frames:read",
    ("GET", C + "/external-kinematics/{number}"): "frames:read",
    ("PUT", C + "/external-kinematics/{number}"): "frames:commit",
    ("GET", C + "/external-kinematics/{number}/history"): "frames:read",
    ("POST", C + "/external-kinematics/{number}/restore/{history_id}"): "frames:commit",
    ("GET", "/methods"): "frames:read",
    ("POST", C + "/sessions"): "sessions:run",
    ("GET", C + "/sessions"): "frames:read",
    ("GET", S): "frames:read",
    ("POST", S + "/touch-up"): "sessions:run",
    ("DELETE", S + "/points/{step}"): "sessions:run",
    ("POST", S + "/compute"): "sessions:run",
    ("POST", S + "/save"): "frames:commit",
    ("POST", S + "/discard"): "sessions:run",
    ("POST", S + "/run-cycle"): "robot:jog",
    ("POST", S + "/beam-recording"): "sessions:run",
    ("GET", S + "/recording"): "frames:read",
    ("GET", C + "/export"): "frames:read",  # format=json (a backup) also needs backup:write
    ("POST", C + "/import"): "data:import",  # format=json (a restore) needs backup:restore
    ("POST", "/recordings"): "sessions:run",
    ("GET", "/recordings/{recording_id}"): "frames:read",
    ("POST", "/recordings/{recording_id}/analyze"): "sessions:run",
    ("GET", "/analysis/{analysis_id}"): "frames:read",
    ("GET", "/analysis/{analysis_id}/model"): "frames:read",  # the fitted robot-model/1
    ("POST", "/predict"): "sessions:run",  # a computation with a saved model
    ("POST", "/plan"): "sessions:run",  # which poses to measure (a computation)
    ("POST", "/plan/recording"): "sessions:run",  # a simulated recording at a plan's poses
    ("GET", "/jobs/{job_id}"): "frames:read",
    ("POST", "/jobs/{job_id}/cancel"): "sessions:run",
    ("GET", "/healthz"): PUBLIC,  # load balancers and compose health checks
    # MES integration (docs/events.md): a subscription sends every frame to its URL
    ("GET", "/webhooks"): "controllers:admin",
    ("POST", "/webhooks"): "controllers:admin",
    ("DELETE", "/webhooks/{webhook_id}"): "controllers:admin",
    ("POST", "/webhooks/{webhook_id}/test"): "controllers:admin",
    ("GET", "/webhooks/{webhook_id}/deliveries"): "controllers:admin",
}


# the OPC UA face's methods (server/opcua): each needs what the REST route it mirrors needs
OPCUA_METHODS: Final[dict[str, tuple[str, str]]] = {
    "ReadFrame": ("GET", C + "/tools/{number}"),
    "ExportFile": ("GET", C + "/export"),
    "CommitFrame": ("PUT", C + "/tools/{number}"),
}
BACKUP_EXPORT: Final = "backup:write"  # GET /export?format=json and ExportFile("json") also need it


def required(method: str, path: str) -> str | None:
    """The permission ``method path`` needs (HEAD as GET); None when the route is undeclared."""
    return ROUTES.get(("GET" if method == "HEAD" else method, path))


def markdown_table() -> str:
    """The route table of docs/security.md ("Every route"), generated from :data:`ROUTES`
    (``python -m server.auth.permissions``); tests/test_auth_permissions.py checks that the
    docs hold exactly this."""
    lines = ["| Method | Path | Needs |", "|---|---|---|"]
    for (method, path), need in ROUTES.items():
        shown = {PUBLIC: "public (no credential)", SIGNED_IN: "any signed-in user"}.get(
            need, f"`{need}`")
        lines.append(f"| {method} | `{path}` | {shown} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown_table(), end="")
