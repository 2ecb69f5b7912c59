"""The DB: Alembic migrations match the models, SQLite runs in WAL mode, the URL is configurable."""

from __future__ import annotations

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import inspect, text

from db import crud
from db.models import Base
from db.session import alembic_config, make_engine, make_sessionmaker, run_migrations
from server.settings import ENV_DB_URL, default_db_url


def test_migrations_build_exactly_the_models(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 'm.db'}")
    run_migrations(engine)
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
        assert conn.execute(text("PRAGMA journal_mode")).scalar() == "wal"
        assert conn.execute(text("PRAGMA foreign_keys")).scalar() == 1
    assert diff == []
    names = {c["name"] for c in inspect(engine).get_unique_constraints("frame_entry")}
    assert "uq_frame_entry_controller_id_entry_table_number" in names  # the naming convention


def test_downgrade_and_upgrade_again(tmp_path):
    url = f"sqlite:///{tmp_path / 'd.db'}"
    engine = make_engine(url)
    run_migrations(engine)
    cfg = alembic_config(url)
    command.downgrade(cfg, "base")
    assert "controller" not in inspect(make_engine(url)).get_table_names()
    command.upgrade(cfg, "head")
    assert "stored_document" in inspect(make_engine(url)).get_table_names()


def test_stored_documents(tmp_path):
    engine = make_engine(f"sqlite:///{tmp_path / 's.db'}")
    run_migrations(engine)
    with make_sessionmaker(engine)() as db:
        i = crud.store_document(db, "recordings", {"format": "robot-recording/1"})
        db.commit()
        assert crud.load_document(db, "recordings", i, "recording_id") == {"format": "robot-recording/1"}
        try:
            crud.load_document(db, "analyses", i, "analysis_id")
        except crud.NotFound as err:
            assert err.loc == ("analysis_id",)


def test_db_url_from_the_environment(monkeypatch):
    monkeypatch.setenv(ENV_DB_URL, "sqlite:////tmp/elsewhere.db")
    assert default_db_url() == "sqlite:////tmp/elsewhere.db"


def test_migrations_build_exactly_the_models_on_the_suite_backend(fresh_db):
    """The same check on the suite's backend (PostgreSQL in tests/run's second pass)."""
    from db.session import upgrade

    engine = make_engine(fresh_db(migrated=False))
    upgrade(engine)
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    engine.dispose()
    assert diff == []
