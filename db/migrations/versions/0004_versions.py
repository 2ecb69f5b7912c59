"""versions for optimistic concurrency (ETag / If-Match), the target slot's version at compute,
64-bit cell seeds, and stored Idempotency-Key responses

Revision ID: 0003_versions
Revises: 0003_files
Create Date: 2026-11-24 07:00:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0003_versions'
down_revision = '0003_files'
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table('controller', schema=None) as batch_op:
        batch_op.add_column(sa.Column('version', sa.Integer(), server_default='1', nullable=False))
        # seeds up to 2**32 - 1 (the API's range): more than PostgreSQL's 4-byte INTEGER holds
        batch_op.alter_column('cell_seed', existing_type=sa.Integer(), type_=sa.BigInteger(),
                              existing_nullable=False)
    with op.batch_alter_table('frame_entry', schema=None) as batch_op:
        batch_op.add_column(sa.Column('version', sa.Integer(), server_default='1', nullable=False))
    with op.batch_alter_table('calib_session', schema=None) as batch_op:
        batch_op.add_column(sa.Column('version', sa.Integer(), server_default='1', nullable=False))
        batch_op.add_column(sa.Column('updated_at', sa.DateTime(timezone=True), nullable=True))
        batch_op.add_column(sa.Column('target_version', sa.Integer(), nullable=True))
    op.create_table(
        'idempotency_key',
        sa.Column('key', sa.String(length=255), nullable=False),
        sa.Column('fingerprint', sa.String(length=64), nullable=False),
        sa.Column('method', sa.String(length=8), nullable=False),
        sa.Column('path', sa.String(length=512), nullable=False),
        sa.Column('status', sa.Integer(), nullable=True),
        sa.Column('headers', sa.JSON(), nullable=True),
        sa.Column('body', sa.LargeBinary(), nullable=True),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint('key', name=op.f('pk_idempotency_key')),
    )
    op.create_index(op.f('ix_idempotency_key_created_at'), 'idempotency_key', ['created_at'])


def downgrade() -> None:
    op.drop_index(op.f('ix_idempotency_key_created_at'), table_name='idempotency_key')
    op.drop_table('idempotency_key')
    with op.batch_alter_table('calib_session', schema=None) as batch_op:
        batch_op.drop_column('target_version')
        batch_op.drop_column('updated_at')
        batch_op.drop_column('version')
    with op.batch_alter_table('frame_entry', schema=None) as batch_op:
        batch_op.drop_column('version')
    with op.batch_alter_table('controller', schema=None) as batch_op:
        batch_op.alter_column('cell_seed', existing_type=sa.BigInteger(), type_=sa.Integer(),
                              existing_nullable=False)
        batch_op.drop_column('version')
