"""Scans keep an optional ambient image (projector off) used to normalise the stripe image's albedo.

Revision ID: 0003
Revises: 0002
Create Date: 2026-11-22
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("scan", schema=None) as batch_op:
        batch_op.add_column(sa.Column("ambient_blob_id", sa.Integer(), nullable=True))
        batch_op.create_foreign_key("fk_scan_ambient_blob_id_blob", "blob", ["ambient_blob_id"], ["id"])


def downgrade() -> None:
    with op.batch_alter_table("scan", schema=None) as batch_op:
        batch_op.drop_constraint("fk_scan_ambient_blob_id_blob", type_="foreignkey")
        batch_op.drop_column("ambient_blob_id")
