"""external kinematics: EX_KIN slots, the emulated external axes, the axis values of touch-ups

Revision ID: 0008_external_kinematics
Revises: 0003_events
Create Date: 2026-11-25 18:30:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0008_external_kinematics'
down_revision = '0003_events'
branch_labels = None
depends_on = None

POSE = ('x_mm', 'y_mm', 'z_mm', 'a_deg', 'b_deg', 'c_deg')


def upgrade() -> None:
    op.create_table(
        'external_kinematic',
        *[sa.Column(c, sa.Double(), nullable=False) for c in POSE],
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('controller_id', sa.Integer(), nullable=False),
        sa.Column('number', sa.Integer(), nullable=False),
        sa.Column('name', sa.String(length=64), nullable=False),
        sa.Column('kind', sa.String(length=16), nullable=False),
        sa.Column('axes', sa.String(length=32), nullable=False),
        *[sa.Column(f'flange_{c}', sa.Double(), nullable=False) for c in POSE],
        sa.Column('scale', sa.Double(), nullable=True),
        sa.Column('method', sa.String(length=32), nullable=True),
        sa.Column('session_id', sa.Integer(), nullable=True),
        sa.Column('error_max_mm', sa.Double(), nullable=True),
        sa.Column('error_rms_mm', sa.Double(), nullable=True),
        sa.Column('updated_at', sa.DateTime(timezone=True), nullable=True),
        sa.Column('updated_by', sa.String(length=64), nullable=True),
        sa.Column('version', sa.Integer(), server_default='1', nullable=False),
        sa.ForeignKeyConstraint(['controller_id'], ['controller.id'], ondelete='CASCADE',
                                name=op.f('fk_external_kinematic_controller_id_controller')),
        sa.ForeignKeyConstraint(['session_id'], ['calib_session.id'], ondelete='SET NULL',
                                name=op.f('fk_external_kinematic_session_id_calib_session')),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_external_kinematic')),
        sa.UniqueConstraint('controller_id', 'number',
                            name=op.f('uq_external_kinematic_controller_id_number')))
    op.create_index(op.f('ix_external_kinematic_controller_id'), 'external_kinematic',
                    ['controller_id'])
    with op.batch_alter_table('controller', schema=None) as batch_op:
        batch_op.add_column(sa.Column('external_axes', sa.JSON(), nullable=True))
        batch_op.add_column(sa.Column('external_errors', sa.JSON(), nullable=True))
    with op.batch_alter_table('taught_point', schema=None) as batch_op:
        batch_op.add_column(sa.Column('external_axes', sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table('taught_point', schema=None) as batch_op:
        batch_op.drop_column('external_axes')
    with op.batch_alter_table('controller', schema=None) as batch_op:
        batch_op.drop_column('external_errors')
        batch_op.drop_column('external_axes')
    op.drop_index(op.f('ix_external_kinematic_controller_id'), table_name='external_kinematic')
    op.drop_table('external_kinematic')
