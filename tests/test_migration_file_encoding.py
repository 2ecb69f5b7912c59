"""Revision 0010 moves a kept controller file's encoding out of its text into a column: a
file kept by 0009's code (a private-use mark before its text) reads back as the same text,
with its encoding beside it, and exports the same bytes."""

from __future__ import annotations

from datetime import datetime, timezone

import sqlalchemy as sa
from alembic import command

from db.session import alembic_config, make_engine


def test_a_marked_kept_file_gets_its_encoding_column(fresh_db):  # noqa: ANN001
    url = fresh_db(migrated=False)
    cfg = alembic_config(url)
    command.upgrade(cfg, "0009_rws_secret")
    engine = make_engine(url)
    meta = sa.MetaData()
    meta.reflect(engine)
    controller, files = meta.tables["controller"], meta.tables["controller_file"]
    now = datetime.now(timezone.utc).replace(tzinfo=None)
    row = {c.name: now if isinstance(c.type, sa.DateTime) else 0 for c in controller.c
           if not c.nullable and c.name != "id" and c.server_default is None}
    row.update(name="old-cell", joints_deg=[0.0] * 6)
    text = 'TOOL_NAME[1,]="Greifer Öl"\n'
    with engine.begin() as conn:
        cid = conn.execute(controller.insert().values(**row)).inserted_primary_key[0]
        conn.execute(files.insert().values(controller_id=cid, format="kuka",
                                           text="\ue000cp1252\ue000" + text,
                                           imported_at=now))
        conn.execute(files.insert().values(controller_id=cid, format="abb", text="MODULE M\n",
                                           imported_at=now))
    command.upgrade(cfg, "head")
    with engine.connect() as conn:
        got = dict(conn.execute(sa.text(
            "SELECT format, text || '|' || encoding FROM controller_file")).all())
    engine.dispose()
    assert got == {"kuka": text + "|cp1252", "abb": "MODULE M\n|utf-8"}
