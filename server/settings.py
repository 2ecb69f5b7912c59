"""Where the service keeps its data: the DB URL (``--db`` / ``PENDANT_DB_URL``) and the web page."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import platformdirs

ROOT = Path(__file__).resolve().parent.parent
ENV_DB_URL = "PENDANT_DB_URL"
ENV_MIGRATE = "PENDANT_MIGRATE"  # "0": serve refuses an old schema instead of migrating it
ENV_ADMIN_TOKEN = "PENDANT_ADMIN_TOKEN"  # the first administrator's token (else one is made)
ENV_NO_AUTH = "PENDANT_NO_AUTH"  # "1": the --no-auth demo (loopback only)
ENV_ALLOWED_HOSTS = "PENDANT_ALLOWED_HOSTS"  # Host names besides loopback, comma-separated
ENV_CORS_ORIGINS = "PENDANT_CORS_ORIGINS"  # origins whose pages may call the API
ENV_PARENT_PID = "PENDANT_PARENT_PID"  # serve's pid, given to the children it starts
ENV_TOKEN = "PENDANT_TOKEN"  # the CLI's bearer token when it talks to a service (--service/--url)
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")


def parent_pid() -> int:
    """The pid of the ``pendant serve`` that started this child (given in the environment, as
    the child may start after its parent is already gone), else this process's parent."""
    return int(os.environ.get(ENV_PARENT_PID) or os.getppid())


def bearer_headers() -> dict[str, str]:
    """``Authorization: Bearer $PENDANT_TOKEN`` for the CLI's requests to a service, if set."""
    token = os.environ.get(ENV_TOKEN)
    return {"Authorization": f"Bearer {token}"} if token else {}


def _env_list(name: str) -> tuple[str, ...]:
    return tuple(v.strip() for v in os.environ.get(name, "").split(",") if v.strip())


def default_db_url() -> str:
    """``PENDANT_DB_URL`` if set, else ``pendant.db`` in the user data dir of "pendant"."""
    url = os.environ.get(ENV_DB_URL)
    if url:
        return url
    data = Path(platformdirs.user_data_dir("pendant"))
    data.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{data / 'pendant.db'}"


def _env(name: str, default: str | None = None) -> str | None:
    return os.environ.get(name) or default


@dataclass(frozen=True)
class Settings:
    db_url: str = field(default_factory=default_db_url)
    web_dir: Path = ROOT / "web"
    demo_controller: bool = True  # create "cell-1" (KUKA KR 6 R900 sixx) in an empty DB
    migrate: bool = field(default_factory=lambda: os.environ.get(ENV_MIGRATE, "1") != "0")
    # migrate an old schema at start (under the DB lock); False: refuse, name `pendant db upgrade`
    # who may change a frame (docs/security.md)
    auth: bool = field(default_factory=lambda: os.environ.get(ENV_NO_AUTH, "0") != "1")
    # False: --no-auth demo on loopback, everyone an Administrator
    bootstrap_token: str | None = field(default_factory=lambda: os.environ.get(ENV_ADMIN_TOKEN))
    allowed_hosts: tuple[str, ...] = field(
        default_factory=lambda: LOOPBACK_HOSTS + _env_list(ENV_ALLOWED_HOSTS))
    # Host header allow-list ("*": any)
    cors_origins: tuple[str, ...] = field(default_factory=lambda: _env_list(ENV_CORS_ORIGINS))
    # closed unless origins are named
    idle_timeout_s: float = 600.0  # a browser login idle this long acts as an Operator
    session_lifetime_s: float = 12 * 3600.0  # a browser login ends after this
    # events (docs/events.md): the MQTT broker that takes every event, and the unified-namespace
    # levels of its topics <site>/<area>/<cell>/pendant/<event>; the webhook retry back-off
    mqtt_url: str | None = field(default_factory=lambda: _env("PENDANT_MQTT_URL"))
    uns_site: str = field(default_factory=lambda: _env("PENDANT_UNS_SITE", "site") or "site")
    uns_area: str = field(default_factory=lambda: _env("PENDANT_UNS_AREA", "area") or "area")
    events_backoff_s: float = 2.0
    dispatch_events: bool = True  # deliver webhooks / MQTT from this process
