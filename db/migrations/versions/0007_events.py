"""the event outbox, webhooks and their deliveries (the MES face)

Revision ID: 0003_events
Revises: 0003_auth
Create Date: 2026-11-24 07:30:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op


revision = '0003_events'
down_revision = '0003_auth'
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        'event',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('kind', sa.String(length=32), nullable=False),
        sa.Column('controller_id', sa.Integer(), nullable=True),
        sa.Column('controller_name', sa.String(length=64), nullable=True),
        sa.Column('payload', sa.JSON(), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_event')))
    op.create_index(op.f('ix_event_kind'), 'event', ['kind'])
    op.create_table(
        'webhook',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('url', sa.String(length=2048), nullable=False),
        sa.Column('secret', sa.String(length=128), nullable=False),
        sa.Column('kinds', sa.JSON(), nullable=True),
        sa.Column('active', sa.Boolean(), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_webhook')))
    op.create_table(
        'delivery',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('event_id', sa.Integer(), nullable=False),
        sa.Column('sink', sa.String(length=16), nullable=False),
        sa.Column('webhook_id', sa.Integer(), nullable=True),
        sa.Column('state', sa.String(length=16), nullable=False),
        sa.Column('attempts', sa.Integer(), nullable=False),
        sa.Column('next_attempt_at', sa.DateTime(timezone=True), nullable=False),
        sa.Column('claimed_at', sa.DateTime(timezone=True), nullable=True),
        sa.Column('delivered_at', sa.DateTime(timezone=True), nullable=True),
        sa.Column('last_status', sa.Integer(), nullable=True),
        sa.Column('last_error', sa.String(length=512), nullable=True),
        sa.ForeignKeyConstraint(['event_id'], ['event.id'], name=op.f('fk_delivery_event_id_event'),
                                ondelete='CASCADE'),
        sa.ForeignKeyConstraint(['webhook_id'], ['webhook.id'],
                                name=op.f('fk_delivery_webhook_id_webhook'), ondelete='CASCADE'),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_delivery')))
    op.create_index(op.f('ix_delivery_event_id'), 'delivery', ['event_id'])
    op.create_index(op.f('ix_delivery_webhook_id'), 'delivery', ['webhook_id'])
    op.create_index(op.f('ix_delivery_state'), 'delivery', ['state'])


def downgrade() -> None:
    op.drop_table('delivery')
    op.drop_table('webhook')
    op.drop_index(op.f('ix_event_kind'), table_name='event')
    op.drop_table('event')
