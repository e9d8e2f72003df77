"""The initial schema: sensors, and per artefact (fit, campaign, validation,
board run) a table keyed by its folder.

Revision ID: 0001
Revises:
Create Date: 2026-12-06
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op
from sqlalchemy.schema import SchemaItem

revision: str = "0001"
down_revision: str | Sequence[str] | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

SENSOR_ID = sa.String(length=8)
SHA256 = sa.String(length=64)
ARTEFACT_TABLES = ("calibrations", "campaigns", "validations", "board_runs")


def artefact_columns(table: str) -> list[SchemaItem]:
    """What every artefact table starts with and how it refers to its sensor."""
    return [
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("folder", sa.Text(), nullable=False),
        sa.Column("source_sha256", SHA256, nullable=False),
        sa.Column("sensor_id", SENSOR_ID, nullable=True),
        sa.PrimaryKeyConstraint("id", name=op.f(f"pk_{table}")),
        sa.UniqueConstraint("folder", name=op.f(f"uq_{table}_folder")),
        sa.ForeignKeyConstraint(["sensor_id"], ["sensors.sensor_id"], name=op.f(f"fk_{table}_sensor_id_sensors")),
    ]


def upgrade() -> None:
    op.create_table(
        "sensors",
        sa.Column("sensor_id", SENSOR_ID, nullable=False),
        sa.PrimaryKeyConstraint("sensor_id", name=op.f("pk_sensors")),
    )
    op.create_table(
        "calibrations",
        *artefact_columns("calibrations"),
        sa.Column("coefficients_sha256", SHA256, nullable=True),
        sa.Column("positions", sa.Integer(), nullable=False),
        sa.Column("certificate_number", sa.String(length=64), nullable=True),
        sa.Column("started_utc", sa.DateTime(), nullable=True),
        sa.Column("ended_utc", sa.DateTime(), nullable=True),
        sa.Column("issue_date", sa.Date(), nullable=True),
        sa.Column("tilt_u95_deg", sa.Float(), nullable=True),
        sa.Column("u95_max_deg", sa.JSON(), nullable=True),
        sa.Column("domain", sa.JSON(), nullable=False),
        sa.Column("campaign", sa.Text(), nullable=True),
    )
    op.create_table(
        "campaigns",
        *artefact_columns("campaigns"),
        sa.Column("rig", sa.String(length=16), nullable=False),
        sa.Column("created_utc", sa.DateTime(), nullable=True),
        sa.Column("started_utc", sa.DateTime(), nullable=True),
        sa.Column("ended_utc", sa.DateTime(), nullable=True),
        sa.Column("positions_planned", sa.Integer(), nullable=False),
        sa.Column("positions_done", sa.Integer(), nullable=False),
        sa.Column("program", sa.JSON(), nullable=False),
        sa.Column("firmware", sa.JSON(), nullable=False),
        sa.Column("model", sa.Text(), nullable=True),
        sa.Column("seed", sa.Integer(), nullable=True),
    )
    op.create_table(
        "validations",
        *artefact_columns("validations"),
        sa.Column("validated_utc", sa.DateTime(), nullable=False),
        sa.Column("tilt_change_p95_deg", sa.Float(), nullable=True),
        sa.Column("rows_within_u_share", sa.Float(), nullable=True),
        sa.Column("tilt_error_p95_deg", sa.Float(), nullable=True),
        sa.Column("compensated_with", sa.Text(), nullable=False),
    )
    op.create_table(
        "board_runs",
        *artefact_columns("board_runs"),
        sa.Column("source", sa.String(length=16), nullable=True),
        sa.Column("scenario", sa.Text(), nullable=True),
        sa.Column("rows", sa.Integer(), nullable=True),
        sa.Column("end_reason", sa.Text(), nullable=True),
        sa.Column("imu_firmware", sa.Text(), nullable=True),
        sa.Column("eeprom_coefficients_sha256", SHA256, nullable=True),
        sa.Column("eeprom_fitted_for", SENSOR_ID, nullable=True),
    )
    for table in ARTEFACT_TABLES:
        op.create_index(op.f(f"ix_{table}_sensor_id"), table, ["sensor_id"])


def downgrade() -> None:
    for table in ARTEFACT_TABLES:
        op.drop_index(op.f(f"ix_{table}_sensor_id"), table_name=table)
        op.drop_table(table)
    op.drop_table("sensors")
