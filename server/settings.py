"""Where the service keeps its data: the DB URL (``--db`` / ``PENDANT_DB_URL``) and the web page."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import platformdirs

ROOT = Path(__file__).resolve().parent.parent
ENV_DB_URL = "PENDANT_DB_URL"


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
    # events (docs/events.md): the MQTT broker that takes every event, and the unified-namespace
    # levels of its topics <site>/<area>/<cell>/pendant/<event>; the webhook retry back-off
    mqtt_url: str | None = field(default_factory=lambda: _env("PENDANT_MQTT_URL"))
    uns_site: str = field(default_factory=lambda: _env("PENDANT_UNS_SITE", "site") or "site")
    uns_area: str = field(default_factory=lambda: _env("PENDANT_UNS_AREA", "area") or "area")
    events_backoff_s: float = 2.0
    dispatch_events: bool = True  # deliver webhooks / MQTT from this process
