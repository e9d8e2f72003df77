"""What upload and assign-id did, recorded as they finish: uploads (a fit
onto the board on a port) and id_assignments (a sensor ID given to one).

Revision ID: 0002
Revises: 0001
Create Date: 2026-12-06
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0002"
down_revision: str | Sequence[str] | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

SENSOR_ID = sa.String(length=8)
SHA256 = sa.String(length=64)
EVENT_TABLES = ("uploads", "id_assignments")


def upgrade() -> None:
    op.create_table(
        "uploads",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("uploaded_utc", sa.DateTime(), nullable=False),
        sa.Column("sensor_id", SENSOR_ID, nullable=True),
        sa.Column("port", sa.Text(), nullable=False),
        sa.Column("fit_folder", sa.Text(), nullable=False),
        sa.Column("coefficients_sha256", SHA256, nullable=True),
        sa.Column("saved", sa.Boolean(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_uploads")),
    )
    op.create_table(
        "id_assignments",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("assigned_utc", sa.DateTime(), nullable=False),
        sa.Column("sensor_id", SENSOR_ID, nullable=False),
        sa.Column("port", sa.Text(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_id_assignments")),
    )
    for table in EVENT_TABLES:
        op.create_index(op.f(f"ix_{table}_sensor_id"), table, ["sensor_id"])


def downgrade() -> None:
    for table in EVENT_TABLES:
        op.drop_index(op.f(f"ix_{table}_sensor_id"), table_name=table)
        op.drop_table(table)
