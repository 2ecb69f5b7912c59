"""Where the service keeps its data: the DB URL (``--db`` / ``PENDANT_DB_URL``) and the web page."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import platformdirs

ROOT = Path(__file__).resolve().parent.parent
ENV_DB_URL = "PENDANT_DB_URL"
ENV_ADMIN_TOKEN = "PENDANT_ADMIN_TOKEN"  # the first administrator's token (else one is made)
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")


def default_db_url() -> str:
    """``PENDANT_DB_URL`` if set, else ``pendant.db`` in the user data dir of "pendant"."""
    url = os.environ.get(ENV_DB_URL)
    if url:
        return url
    data = Path(platformdirs.user_data_dir("pendant"))
    data.mkdir(parents=True, exist_ok=True)
    return f"sqlite:///{data / 'pendant.db'}"


@dataclass(frozen=True)
class Settings:
    db_url: str = field(default_factory=default_db_url)
    web_dir: Path = ROOT / "web"
    demo_controller: bool = True  # create "cell-1" (KUKA KR 6 R900 sixx) in an empty DB
    # who may change a frame (docs/security.md)
    auth: bool = True  # False: --no-auth demo on loopback, everyone an Administrator
    bootstrap_token: str | None = field(default_factory=lambda: os.environ.get(ENV_ADMIN_TOKEN))
    allowed_hosts: tuple[str, ...] = LOOPBACK_HOSTS  # Host header allow-list ("*": any)
    cors_origins: tuple[str, ...] = ()  # closed unless origins are named
    idle_timeout_s: float = 600.0  # a browser login idle this long acts as an Operator
    session_lifetime_s: float = 12 * 3600.0  # a browser login ends after this
