"""file encoding: a kept controller file's own encoding (utf-8 or cp1252) in a column

A kept file that was not UTF-8 carried its encoding in a private-use mark before its first
character; the mark moves into the column.

Revision ID: 0010_file_encoding
Revises: 0009_rws_secret
Create Date: 2026-11-26 16:10:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0010_file_encoding'
down_revision = '0009_rws_secret'
branch_labels = None
depends_on = None

MARK = "\ue000"


def upgrade() -> None:
    with op.batch_alter_table('controller_file', schema=None) as batch_op:
        batch_op.add_column(sa.Column('encoding', sa.String(length=16), nullable=False,
                                      server_default='utf-8'))
    files = sa.table('controller_file', sa.column('id', sa.Integer), sa.column('text', sa.Text),
                     sa.column('encoding', sa.String))
    conn = op.get_bind()
    for row in conn.execute(sa.select(files.c.id, files.c.text)).all():
        text = row.text or ""
        end = text.find(MARK, 1) if text.startswith(MARK) else -1
        if end > 0 and text[1:end] in ("utf-8", "cp1252"):
            conn.execute(files.update().where(files.c.id == row.id)
                         .values(text=text[end + 1:], encoding=text[1:end]))


def downgrade() -> None:
    with op.batch_alter_table('controller_file', schema=None) as batch_op:
        batch_op.drop_column('encoding')
