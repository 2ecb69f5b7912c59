"""the emulated arm's hidden physics, clock and backlash flanks; time of each taught point

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-22 12:30:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0002'
down_revision = '0001'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('controller', schema=None) as batch_op:
        batch_op.add_column(sa.Column('physics', sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column('clock_s', sa.Double(), server_default='0', nullable=False))
        batch_op.add_column(sa.Column('motion_sign', sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column('motion_count', sa.Integer(), server_default='0',
                                      nullable=False))
    with op.batch_alter_table('taught_point', schema=None) as batch_op:
        batch_op.add_column(sa.Column('t_s', sa.Double(), nullable=True))
        batch_op.add_column(sa.Column('motion_sign', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('taught_point', schema=None) as batch_op:
        batch_op.drop_column('motion_sign')
        batch_op.drop_column('t_s')
    with op.batch_alter_table('controller', schema=None) as batch_op:
        batch_op.drop_column('motion_count')
        batch_op.drop_column('motion_sign')
        batch_op.drop_column('clock_s')
        batch_op.drop_column('physics')
