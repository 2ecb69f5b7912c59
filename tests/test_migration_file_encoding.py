"""Revision 0010 moves a kept controller file's encoding out of its text into a column: a
file kept by 0009's code (a private-use mark before its text) reads back as the same text,
with its encoding beside it, and exports the same bytes."""

from __future__ import annotations

import sqlalchemy as sa
from alembic import command
from migration_helpers import add_controller, at_revision, utc_now


def test_a_marked_kept_file_gets_its_encoding_column(fresh_db):  # noqa: ANN001
    cfg, engine, meta = at_revision(fresh_db, "0009_rws_secret")
    files = meta.tables["controller_file"]
    now = utc_now()
    text = 'TOOL_NAME[1,]="Greifer Öl"\n'
    with engine.begin() as conn:
        cid = add_controller(conn, meta)
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
