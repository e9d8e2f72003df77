"""``thermotilt sensors``: one line per sensor the registry knows — its
last calibration (date, the certificate's U, the fit folder), the fit its
board runs (its last upload) and whether that is the latest, its last
validation's p95 change of tilt, and when it is due for recalibration.

A calibration's date is when its campaign ended (the certificate's
calibration_dates), else the certificate's issue date; a validation's is
its validation.json's. Everything comes from the registry's rows, so the
listing after ``registry rebuild`` is the listing before it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import date, datetime, time, timedelta
from pathlib import Path
from typing import TypeVar

from sqlalchemy import select

from . import DEFAULT_INTERVAL_DAYS
from .database import Registry
from .schema import Calibration, Sensor, Upload, Validation

NONE = "-"
HEADER = (
    "sensor",
    "calibrated",
    "U (deg)",
    "fit",
    "fit on its board",
    "last validation p95 (deg)",
    "recalibration due",
)

_Row = TypeVar("_Row", Calibration, Validation, Upload)


@dataclass(frozen=True)
class SensorLine:
    sensor_id: str
    calibrated: date | None = None
    u95_deg: float | None = None
    fit_folder: str | None = None
    validation_p95_deg: float | None = None
    validated: date | None = None
    on_board: str | None = None  # the last upload's fit folder
    on_board_latest: bool = False  # its coefficients are the last calibration's
    on_board_saved: bool = True  # False: in the board's RAM only, until its next reset

    def due(self, interval_days: int) -> date | None:
        return None if self.calibrated is None else self.calibrated + timedelta(days=interval_days)


@dataclass(frozen=True)
class Fleet:
    registry: str
    lines: list[SensorLine]
    interval_days: int
    today: date

    def summary(self) -> str:
        if not self.lines:
            return (
                f"no sensors in the registry {self.registry} yet: `thermotilt registry rebuild FOLDER...` "
                "records the campaigns, fits and runs in those folders"
            )
        return aligned([HEADER, *(self.cells(line) for line in self.lines)])

    def cells(self, line: SensorLine) -> tuple[str, ...]:
        """The line as `thermotilt sensors` prints it, a cell per HEADER column."""
        due = line.due(self.interval_days)
        validation = NONE
        if line.validation_p95_deg is not None:
            validation = f"{two_significant(line.validation_p95_deg)} ({line.validated})"
        return (
            line.sensor_id,
            str(line.calibrated or NONE),
            NONE if line.u95_deg is None else two_significant(line.u95_deg),
            NONE if line.fit_folder is None else shown_path(line.fit_folder),
            _on_board(line),
            validation,
            NONE if due is None else f"{due}{' overdue' if due < self.today else ''}",
        )


def fleet(registry: Registry, interval_days: int = DEFAULT_INTERVAL_DAYS, today: date | None = None) -> Fleet:
    """Every sensor's line, by ID; due dates interval_days after the last calibration."""
    with registry.reading() as session:
        # Sorted here: a server's collation may order IDs by language (case and '-' aside), not by character.
        sensors = sorted(session.scalars(select(Sensor.sensor_id)))
        calibrations = latest(session.scalars(select(Calibration)), calibrated_at)
        validations = latest(session.scalars(select(Validation)), lambda row: row.validated_utc)
        uploads = latest(session.scalars(select(Upload)), lambda row: row.uploaded_utc)
        lines = [
            _line(sensor_id, calibrations.get(sensor_id), validations.get(sensor_id), uploads.get(sensor_id))
            for sensor_id in sensors
        ]
    return Fleet(registry.shown_url, lines, interval_days, today or date.today())


def _line(
    sensor_id: str, calibration: Calibration | None, validation: Validation | None, upload: Upload | None
) -> SensorLine:
    return SensorLine(
        sensor_id,
        calibration_date(calibration) if calibration else None,
        calibration.tilt_u95_deg if calibration else None,
        calibration.folder if calibration else None,
        validation.tilt_change_p95_deg if validation else None,
        validation.validated_utc.date() if validation else None,
        upload.fit_folder if upload else None,
        bool(upload and calibration and upload.coefficients_sha256 == calibration.coefficients_sha256),
        upload.saved if upload else True,
    )


def _on_board(line: SensorLine) -> str:
    if line.on_board is None:
        return NONE
    notes = ["latest" if line.on_board_latest else "not the latest"]
    if not line.on_board_saved:
        notes.append("RAM only")
    return f"{shown_path(line.on_board)} ({', '.join(notes)})"


def calibration_date(calibration: Calibration) -> date | None:
    return calibration.ended_utc.date() if calibration.ended_utc else calibration.issue_date


def calibrated_at(calibration: Calibration) -> datetime | None:
    """When a calibration was made, to order them by: calibration_date's moment."""
    if calibration.ended_utc is None and calibration.issue_date is not None:
        return datetime.combine(calibration.issue_date, time())
    return calibration.ended_utc


def latest(rows: Iterable[_Row], when: Callable[[_Row], datetime | None]) -> dict[str, _Row]:
    """Per sensor, its latest row (undated rows before any dated one, a
    tie to the last folder by name)."""
    by_sensor: dict[str, _Row] = {}
    for row in sorted(rows, key=lambda row: (when(row) or datetime.min, _folder_of(row))):
        if row.sensor_id is not None:
            by_sensor[row.sensor_id] = row
    return by_sensor


def _folder_of(row: Calibration | Validation | Upload) -> str:
    return row.fit_folder if isinstance(row, Upload) else row.folder


def aligned(rows: list[tuple[str, ...]]) -> str:
    """Rows of cells as left-aligned columns, the first row the header."""
    widths = [max(len(row[column]) for row in rows) for column in range(len(rows[0]))]
    return "\n".join("  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip() for row in rows)


def two_significant(value: float) -> str:
    """As the certificate writes U (certificate.budget.two_significant_text,
    which would load scipy for one format): 0.40, 0.018, 1.2."""
    return f"{value:#.2g}".rstrip(".")


def shown_path(folder: str) -> str:
    """A folder relative to the current one when it lies inside it."""
    path, here = Path(folder), Path.cwd()
    return str(path.relative_to(here)) if path.is_relative_to(here) else folder
