"""session opened by: who opened a calibration session (the user name the audit records)

Sessions opened before this revision keep NULL: nobody recorded who opened them.

Revision ID: 0011_session_opened_by
Revises: 0010_file_encoding
Create Date: 2026-11-27 10:00:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0011_session_opened_by'
down_revision = '0010_file_encoding'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('calib_session', schema=None) as batch_op:
        batch_op.add_column(sa.Column('opened_by', sa.String(length=64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('calib_session', schema=None) as batch_op:
        batch_op.drop_column('opened_by')
