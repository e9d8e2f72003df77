"""The registry's tables as SQLAlchemy 2 typed ORM classes. The database
gets them only through the Alembic revisions in ``migrations/versions``;
a change here is a new revision there (docs/registry.md), and
``alembic check`` (host/tests/test_registry.py) holds the two equal.

Every artefact table keys its rows by the artefact's folder (its resolved
path) and keeps the sha256 of the files that define it, so ingesting a
folder again changes nothing unless those files changed. Times are UTC.

``uploads`` and ``id_assignments`` are what ``upload`` and ``assign-id``
did, recorded as they finish: no folder holds them, so a rebuild keeps
them, and they name a sensor without making it one of ``sensors`` (the
fleet is what the folders say).
"""

from __future__ import annotations

from datetime import date, datetime
from typing import Any

from sqlalchemy import JSON, Boolean, Date, DateTime, Float, ForeignKey, Integer, MetaData, String, Text
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

from ..surfaces import SENSOR_ID_LENGTH

SHA256_LENGTH = 64

# Named constraints, so that a later revision can drop or alter them by name.
NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING_CONVENTION)
    type_annotation_map = {dict[str, Any]: JSON, list[str]: JSON}


def _sensor() -> Mapped[str | None]:
    return mapped_column(String(SENSOR_ID_LENGTH), ForeignKey("sensors.sensor_id"), index=True)


class Sensor(Base):
    """Every sensor ID a folder named: a fit, a campaign, a board's EEPROM."""

    __tablename__ = "sensors"

    sensor_id: Mapped[str] = mapped_column(String(SENSOR_ID_LENGTH), primary_key=True)


class Artefact:
    """What every artefact row has: its folder and the digest of its defining files."""

    id: Mapped[int] = mapped_column(Integer, primary_key=True, sort_order=-3)
    folder: Mapped[str] = mapped_column(Text, unique=True, sort_order=-2)
    source_sha256: Mapped[str] = mapped_column(String(SHA256_LENGTH), sort_order=-1)


class Calibration(Artefact, Base):
    """A fit folder (coefficients.json, coefficients.bin, certificate.json
    when the fit had a sensor ID)."""

    __tablename__ = "calibrations"

    sensor_id: Mapped[str | None] = _sensor()
    coefficients_sha256: Mapped[str | None] = mapped_column(String(SHA256_LENGTH))
    positions: Mapped[int]
    # The certificate's: its number, when its campaign ran and when it was issued.
    certificate_number: Mapped[str | None] = mapped_column(String(64))
    started_utc: Mapped[datetime | None] = mapped_column(DateTime)
    ended_utc: Mapped[datetime | None] = mapped_column(DateTime)
    issue_date: Mapped[date | None] = mapped_column(Date)
    # U of the tilt change, degrees: the headline and each axis's largest.
    tilt_u95_deg: Mapped[float | None] = mapped_column(Float)
    u95_max_deg: Mapped[dict[str, Any] | None]
    # The certificate's domain, else the fit's calibrated_domain.
    domain: Mapped[dict[str, Any]]
    campaign: Mapped[str | None] = mapped_column(Text)


class Campaign(Artefact, Base):
    """A campaign folder (campaign.json and a run folder per position)."""

    __tablename__ = "campaigns"

    sensor_id: Mapped[str | None] = _sensor()
    rig: Mapped[str] = mapped_column(String(16))
    created_utc: Mapped[datetime | None] = mapped_column(DateTime)
    started_utc: Mapped[datetime | None] = mapped_column(DateTime)
    ended_utc: Mapped[datetime | None] = mapped_column(DateTime)
    positions_planned: Mapped[int]
    positions_done: Mapped[int]
    program: Mapped[dict[str, Any]]
    firmware: Mapped[list[str]]
    model: Mapped[str | None] = mapped_column(Text)
    seed: Mapped[int | None] = mapped_column(Integer)


class Validation(Artefact, Base):
    """A run folder's validation.json (``thermotilt validate``)."""

    __tablename__ = "validations"

    sensor_id: Mapped[str | None] = _sensor()
    # validation.json records no date: its file's modification time.
    validated_utc: Mapped[datetime] = mapped_column(DateTime)
    tilt_change_p95_deg: Mapped[float | None] = mapped_column(Float)
    rows_within_u_share: Mapped[float | None] = mapped_column(Float)
    tilt_error_p95_deg: Mapped[float | None] = mapped_column(Float)
    compensated_with: Mapped[str] = mapped_column(Text)


class BoardRun(Artefact, Base):
    """A run folder outside a campaign (run.csv, summary.json, in the twin
    the IMU's EEPROM image)."""

    __tablename__ = "board_runs"

    sensor_id: Mapped[str | None] = _sensor()
    source: Mapped[str | None] = mapped_column(String(16))
    scenario: Mapped[str | None] = mapped_column(Text)
    rows: Mapped[int | None] = mapped_column(Integer)
    end_reason: Mapped[str | None] = mapped_column(Text)
    imu_firmware: Mapped[str | None] = mapped_column(Text)
    # The coefficient block the IMU's EEPROM held at the end of the run.
    eeprom_coefficients_sha256: Mapped[str | None] = mapped_column(String(SHA256_LENGTH))
    eeprom_fitted_for: Mapped[str | None] = mapped_column(String(SENSOR_ID_LENGTH))


class Upload(Base):
    """A fit written into a board by ``thermotilt upload`` and read back
    equal (an upload that failed is not recorded)."""

    __tablename__ = "uploads"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    uploaded_utc: Mapped[datetime] = mapped_column(DateTime)
    # The fit's sensor, which upload held equal to the board's own ID.
    sensor_id: Mapped[str | None] = mapped_column(String(SENSOR_ID_LENGTH), index=True)
    port: Mapped[str] = mapped_column(Text)
    fit_folder: Mapped[str] = mapped_column(Text)
    coefficients_sha256: Mapped[str | None] = mapped_column(String(SHA256_LENGTH))
    # False for --no-save: in the board's RAM only, until its next reset.
    saved: Mapped[bool] = mapped_column(Boolean)


class IdAssignment(Base):
    """The sensor ID ``thermotilt assign-id`` gave the board on a port."""

    __tablename__ = "id_assignments"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    assigned_utc: Mapped[datetime] = mapped_column(DateTime)
    sensor_id: Mapped[str] = mapped_column(String(SENSOR_ID_LENGTH), index=True)
    port: Mapped[str] = mapped_column(Text)
