"""controller files kept for patching on export; load inertia axes; coordinated bases

Revision ID: 0003_files
Revises: 0002
Create Date: 2026-11-24 07:10:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0003_files'
down_revision = '0002'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        'controller_file',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('controller_id', sa.Integer(), nullable=False),
        sa.Column('format', sa.String(length=8), nullable=False),
        sa.Column('text', sa.Text(), nullable=False),
        sa.Column('imported_at', sa.DateTime(timezone=True), nullable=False),
        sa.ForeignKeyConstraint(['controller_id'], ['controller.id'],
                                name=op.f('fk_controller_file_controller_id_controller'),
                                ondelete='CASCADE'),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_controller_file')),
        sa.UniqueConstraint('controller_id', 'format',
                            name=op.f('uq_controller_file_controller_id_format')),
    )
    with op.batch_alter_table('controller_file', schema=None) as batch_op:
        batch_op.create_index(batch_op.f('ix_controller_file_controller_id'), ['controller_id'],
                              unique=False)
    with op.batch_alter_table('frame_entry', schema=None) as batch_op:
        batch_op.add_column(sa.Column('inertia_a_deg', sa.Double(), nullable=True))
        batch_op.add_column(sa.Column('inertia_b_deg', sa.Double(), nullable=True))
        batch_op.add_column(sa.Column('inertia_c_deg', sa.Double(), nullable=True))
        batch_op.add_column(sa.Column('mech_unit', sa.String(length=32), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('frame_entry', schema=None) as batch_op:
        batch_op.drop_column('mech_unit')
        batch_op.drop_column('inertia_c_deg')
        batch_op.drop_column('inertia_b_deg')
        batch_op.drop_column('inertia_a_deg')
    with op.batch_alter_table('controller_file', schema=None) as batch_op:
        batch_op.drop_index(batch_op.f('ix_controller_file_controller_id'))
    op.drop_table('controller_file')
