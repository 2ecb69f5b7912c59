"""Where the service keeps its data: the DB URL (``--db`` / ``PENDANT_DB_URL``) and the web page."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import platformdirs

ROOT = Path(__file__).resolve().parent.parent
ENV_DB_URL = "PENDANT_DB_URL"
ENV_MIGRATE = "PENDANT_MIGRATE"  # "0": serve refuses an old schema instead of migrating it


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
    migrate: bool = field(default_factory=lambda: os.environ.get(ENV_MIGRATE, "1") != "0")
    # migrate an old schema at start (under the DB lock); False: refuse, name `pendant db upgrade`
