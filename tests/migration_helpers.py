"""A database left at an older revision, with rows its code wrote, for the tests of what a
later migration does to them (tests/test_migration_*.py, tests/test_sessions_whose.py)."""

from __future__ import annotations

from datetime import datetime, timezone

import sqlalchemy as sa
from alembic import command
from alembic.config import Config

from db.session import alembic_config, make_engine


def at_revision(fresh_db, revision: str) -> tuple[Config, sa.Engine, sa.MetaData]:  # noqa: ANN001
    """A fresh database migrated up to ``revision`` only: its Alembic config (upgrade it to
    ``"head"`` next), an engine, and its tables as they were at that revision."""
    url = fresh_db(migrated=False)
    cfg = alembic_config(url)
    command.upgrade(cfg, revision)
    engine = make_engine(url)
    meta = sa.MetaData()
    meta.reflect(engine)
    return cfg, engine, meta


def utc_now() -> datetime:
    """Now as the service stores it (UTC, no zone)."""
    return datetime.now(timezone.utc).replace(tzinfo=None)


def add_controller(conn: sa.Connection, meta: sa.MetaData, name: str = "old-cell") -> int:
    """A controller row with only its required columns (zero, or now for a time); its id."""
    controller = meta.tables["controller"]
    row = {c.name: utc_now() if isinstance(c.type, sa.DateTime) else 0 for c in controller.c
           if not c.nullable and c.name != "id" and c.server_default is None}
    row.update(name=name, joints_deg=[0.0] * 6)
    return conn.execute(controller.insert().values(**row)).inserted_primary_key[0]
