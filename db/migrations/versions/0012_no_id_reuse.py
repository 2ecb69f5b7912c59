"""no id reuse: every table with an integer id gets SQLite's AUTOINCREMENT

SQLite gave a new row the largest id + 1, so the id of the newest row, once deleted, went to
the next row made (a controller deleted and another made got its id, and with it the old
one's ETags, audit records and OPC UA node ids). AUTOINCREMENT keeps the largest id ever
given (``sqlite_sequence``) and never gives one twice. SQLite cannot add it to a table: each
table is made anew and its rows copied (Alembic's batch mode), with foreign keys off for the
run (``db.session.run_migrations``: the DROP of a table other rows refer to would otherwise
delete them by cascade). The largest id given before this revision is the largest left in
each table: an id deleted before it may still be given once. PostgreSQL: nothing to do.

Revision ID: 0012_no_id_reuse
Revises: 0011_session_opened_by
Create Date: 2026-11-27 11:30:00
"""
from __future__ import annotations

from alembic import op

revision = '0012_no_id_reuse'
down_revision = '0011_session_opened_by'
branch_labels = None
depends_on = None

# every table whose primary key is an integer id (db.models.NO_ID_REUSE), parents first
TABLES = ('controller', 'frame_entry', 'entry_history', 'calib_session', 'taught_point',
          'external_kinematic', 'stored_document', 'controller_file', 'job', 'event', 'webhook',
          'delivery', 'auth_user', 'auth_token', 'auth_web_session', 'audit_record')


def _rebuild(autoincrement: bool) -> None:
    if op.get_bind().dialect.name != 'sqlite':
        return
    for table in TABLES:
        with op.batch_alter_table(table, recreate='always',
                                  table_kwargs={'sqlite_autoincrement': autoincrement}):
            pass


def upgrade() -> None:
    _rebuild(True)


def downgrade() -> None:
    _rebuild(False)
