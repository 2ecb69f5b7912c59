"""users, roles, API tokens, browser sessions, the audit trail; who changed a slot

Revision ID: 0003_auth
Revises: 0003_jobs
Create Date: 2026-11-24 07:10:00
"""
from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = '0003_auth'
down_revision = '0003_jobs'
branch_labels = None
depends_on = None

# the default roles as they were at this revision (later changes go into a new revision)
DEFAULT_ROLES = {
    "Operator": ["frames:read", "robot:jog"],
    "Programmer": ["frames:read", "robot:jog", "sessions:run"],
    "Expert": ["frames:read", "robot:jog", "sessions:run", "frames:commit", "data:import"],
    "Administrator": ["frames:read", "robot:jog", "sessions:run", "frames:commit", "data:import",
                      "backup:write", "backup:restore", "emulator:physics", "controllers:admin",
                      "users:admin", "audit:read"],
}


def upgrade() -> None:
    role = op.create_table(
        'auth_role',
        sa.Column('name', sa.String(32), nullable=False),
        sa.Column('permissions', sa.JSON(), nullable=False),
        sa.Column('description', sa.String(200), nullable=False),
        sa.PrimaryKeyConstraint('name', name=op.f('pk_auth_role')))
    op.create_table(
        'auth_user',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('name', sa.String(64), nullable=False),
        sa.Column('role', sa.String(32), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.Column('revoked_at', sa.DateTime(timezone=True), nullable=True),
        sa.ForeignKeyConstraint(['role'], ['auth_role.name'],
                                name=op.f('fk_auth_user_role_auth_role')),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_auth_user')),
        sa.UniqueConstraint('name', name=op.f('uq_auth_user_name')))
    op.create_table(
        'auth_token',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('user_id', sa.Integer(), nullable=False),
        sa.Column('token_sha256', sa.String(64), nullable=False),
        sa.Column('label', sa.String(64), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.Column('expires_at', sa.DateTime(timezone=True), nullable=True),
        sa.Column('revoked_at', sa.DateTime(timezone=True), nullable=True),
        sa.ForeignKeyConstraint(['user_id'], ['auth_user.id'], ondelete='CASCADE',
                                name=op.f('fk_auth_token_user_id_auth_user')),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_auth_token')),
        sa.UniqueConstraint('token_sha256', name=op.f('uq_auth_token_token_sha256')))
    op.create_index(op.f('ix_auth_token_user_id'), 'auth_token', ['user_id'])
    op.create_table(
        'auth_web_session',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('user_id', sa.Integer(), nullable=False),
        sa.Column('cookie_sha256', sa.String(64), nullable=False),
        sa.Column('csrf_token', sa.String(64), nullable=False),
        sa.Column('created_at', sa.DateTime(timezone=True), nullable=False),
        sa.Column('last_seen_at', sa.DateTime(timezone=True), nullable=False),
        sa.Column('expires_at', sa.DateTime(timezone=True), nullable=False),
        sa.Column('ended_at', sa.DateTime(timezone=True), nullable=True),
        sa.ForeignKeyConstraint(['user_id'], ['auth_user.id'], ondelete='CASCADE',
                                name=op.f('fk_auth_web_session_user_id_auth_user')),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_auth_web_session')),
        sa.UniqueConstraint('cookie_sha256', name=op.f('uq_auth_web_session_cookie_sha256')))
    op.create_index(op.f('ix_auth_web_session_user_id'), 'auth_web_session', ['user_id'])
    op.create_table(
        'audit_record',
        sa.Column('id', sa.Integer(), nullable=False),
        sa.Column('at', sa.DateTime(timezone=True), nullable=False),
        sa.Column('user_name', sa.String(64), nullable=True),
        sa.Column('role', sa.String(32), nullable=True),
        sa.Column('source', sa.String(16), nullable=False),
        sa.Column('request_id', sa.String(64), nullable=True),
        sa.Column('client', sa.String(64), nullable=True),
        sa.Column('action', sa.String(32), nullable=False),
        sa.Column('controller_id', sa.Integer(), nullable=True),
        sa.Column('entry_table', sa.String(8), nullable=True),
        sa.Column('number', sa.Integer(), nullable=True),
        sa.Column('session_id', sa.Integer(), nullable=True),
        sa.Column('before', sa.JSON(), nullable=True),
        sa.Column('after', sa.JSON(), nullable=True),
        sa.Column('quality', sa.JSON(), nullable=True),
        sa.PrimaryKeyConstraint('id', name=op.f('pk_audit_record')))
    op.create_index(op.f('ix_audit_record_at'), 'audit_record', ['at'])
    op.create_index(op.f('ix_audit_record_user_name'), 'audit_record', ['user_name'])
    op.create_index(op.f('ix_audit_record_controller_id'), 'audit_record', ['controller_id'])
    with op.batch_alter_table('frame_entry', schema=None) as batch_op:
        batch_op.add_column(sa.Column('updated_by', sa.String(64), nullable=True))
    with op.batch_alter_table('entry_history', schema=None) as batch_op:
        batch_op.add_column(sa.Column('changed_by', sa.String(64), nullable=True))
    op.bulk_insert(role, [{"name": k, "permissions": v, "description": "default role"}
                          for k, v in DEFAULT_ROLES.items()])


def downgrade() -> None:
    with op.batch_alter_table('entry_history', schema=None) as batch_op:
        batch_op.drop_column('changed_by')
    with op.batch_alter_table('frame_entry', schema=None) as batch_op:
        batch_op.drop_column('updated_by')
    op.drop_table('audit_record')
    op.drop_table('auth_web_session')
    op.drop_table('auth_token')
    op.drop_table('auth_user')
    op.drop_table('auth_role')
