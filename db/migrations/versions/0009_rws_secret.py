"""rws secret: a user's HTTP Digest secret for the RWS face, kept as its HA1

Revision ID: 0009_rws_secret
Revises: 0008_external_kinematics
Create Date: 2026-11-26 15:20:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0009_rws_secret'
down_revision = '0008_external_kinematics'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('auth_user', schema=None) as batch_op:
        batch_op.add_column(sa.Column('rws_ha1', sa.String(length=64), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('auth_user', schema=None) as batch_op:
        batch_op.drop_column('rws_ha1')
