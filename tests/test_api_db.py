"""The DB: Alembic migrations match the models, SQLite runs in WAL mode, the URL is configurable."""

from __future__ import annotations

from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from sqlalchemy import inspect, text

from db import auth_models  # noqa: F401  (the users', tokens' and audit tables are Base's too)
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


def test_a_deleted_rows_id_is_never_given_again(client):
    """The newest controller deleted and another made: the new one gets a new id, so an ETag,
    an audit query or an OPC UA node id kept for the old one does not name the new one (on
    SQLite the id was given again: the largest id + 1). The same for a webhook."""
    from api_helpers import ok

    made = ok(client.post("/controllers", json={"name": "to-go", "robot": "kuka_kr6_r900_sixx"}))
    etag = client.get(f"/controllers/{made['id']}").headers["ETag"]
    assert client.delete(f"/controllers/{made['id']}", headers={"If-Match": etag}).status_code == 204
    again = ok(client.post("/controllers", json={"name": "new", "robot": "kuka_kr6_r900_sixx"}))
    assert again["id"] > made["id"]
    assert client.get(f"/controllers/{made['id']}").status_code == 404
    hook = ok(client.post("/webhooks", json={"url": "http://127.0.0.1:9/hook"}))
    assert client.delete(f"/webhooks/{hook['id']}").status_code == 204
    assert ok(client.post("/webhooks", json={"url": "http://127.0.0.1:9/hook"}))["id"] > hook["id"]


def test_the_upgrade_to_no_id_reuse_keeps_every_row(tmp_path):
    """A database at revision 0011 with a controller, its slots, history, a session with
    points and audit records, upgraded: every row is still there (each table is made anew;
    with foreign keys on, dropping the old controller table would have deleted the rows that
    refer to it by cascade), the ids too, and the newest controller's id is not given again."""
    from api_helpers import make_client, ok, open_session

    url = f"sqlite:///{tmp_path / 'u.db'}"
    with make_client(url) as c:
        cid = ok(c.post("/controllers", json={"name": "old", "robot": "kuka_kr6_r900_sixx"}))["id"]
        url_s = open_session(c, "tool.xyz_4point", 1, controller=f"/controllers/{cid}")
        for k in range(2):
            ok(c.post(f"{url_s}/touch-up", json={"step": k}))
    tables = [t for t in Base.metadata.tables if t != "alembic_version"]
    engine = make_engine(url)
    command.downgrade(alembic_config(url), "0011_session_opened_by")
    with engine.connect() as conn:
        before = {t: conn.execute(text(f"SELECT count(*) FROM {t}")).scalar() for t in tables}
        ids = conn.execute(text("SELECT id FROM controller ORDER BY id")).scalars().all()
    assert before["taught_point"] == 2 and before["frame_entry"] > 0 and before["audit_record"] > 0
    run_migrations(engine)
    with engine.connect() as conn:
        after = {t: conn.execute(text(f"SELECT count(*) FROM {t}")).scalar() for t in tables}
        assert conn.execute(text("SELECT id FROM controller ORDER BY id")).scalars().all() == ids
        assert conn.execute(text("PRAGMA foreign_keys")).scalar() == 1  # on again
        assert "AUTOINCREMENT" in conn.execute(text(
            "SELECT sql FROM sqlite_master WHERE name = 'controller'")).scalar()
    assert after == before
    engine.dispose()
    with make_client(url) as c:
        etag = c.get(f"/controllers/{cid}").headers["ETag"]
        assert c.delete(f"/controllers/{cid}", headers={"If-Match": etag}).status_code == 204
        assert ok(c.post("/controllers", json={"name": "next", "robot": "kuka_kr6_r900_sixx"}))["id"] > cid
