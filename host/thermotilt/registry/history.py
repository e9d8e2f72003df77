"""``thermotilt history ID``: a sensor's calibrations over time and, between
consecutive ones, how its drift surfaces changed.

The calibrations and their order come from the registry (a calibration's
date as ``thermotilt sensors`` gives it); each fit's surfaces from its
folder's coefficients.json (``calibration.compare.read_fit``). The change
per set (W, C) and axis (X, Y) is ``calibration.surface_change``'s: its RMS
and its largest value in LSB and in degrees of tilt over the domain both
fits calibrated. What compensation subtracts changes by exactly this when
the board gets the new fit.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from datetime import date, datetime
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select

from ..calibration.compare import GRID_POINTS, FittedSurface, read_fit
from ..calibration.dataset import CalibrationDataError
from ..calibration.surface_change import SurfaceChange, surface_change
from ..surfaces import SET_NAMES, SETS
from .database import Registry
from .fleet import NONE, aligned, calibrated_at, calibration_date, shown_path, two_significant
from .schema import Calibration, Sensor

COMPARED_AXES = ("X", "Y")
SET_COLOURS = {"W": "tab:red", "C": "tab:blue"}
AXIS_MARKERS = {"X": "o", "Y": "s"}
HISTORY_FILE = "history.json"
FIGURE_FILE = "history.png"
CALIBRATION_HEADER = ("calibrated", "certificate", "U (deg)", "fit")
CHANGE_HEADER = (
    "from",
    "to",
    "surface",
    "T (degC)",
    "a (LSB)",
    "RMS (LSB)",
    "largest (LSB)",
    "RMS (deg)",
    "largest (deg)",
)


class HistoryError(RuntimeError):
    """A sensor the registry does not know, or a fit folder that cannot be read; one line."""


@dataclass(frozen=True)
class CalibrationEntry:
    calibrated: date | None
    certificate_number: str | None
    u95_deg: float | None
    fit_folder: str

    @property
    def shown_date(self) -> str:
        return str(self.calibrated or "undated")


@dataclass(frozen=True)
class CalibrationChange:
    older: CalibrationEntry
    newer: CalibrationEntry
    surfaces: list[SurfaceChange]
    # Surfaces not compared, with why: one fit lacks it, or the domains do not meet.
    not_compared: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class History:
    sensor_id: str
    registry: str
    calibrations: list[CalibrationEntry]
    changes: list[CalibrationChange]

    def summary(self) -> str:
        count = len(self.calibrations)
        if count == 0:
            return f"sensor {self.sensor_id} has no calibration in the registry {self.registry}"
        if count == 1:
            only = self.calibrations[0]
            return (
                f"sensor {self.sensor_id} has one calibration ({only.shown_date}, {_calibration_text(only)}): "
                "the change of its drift surfaces needs a second"
            )
        lines = [
            f"sensor {self.sensor_id}: {count} calibrations",
            aligned([CALIBRATION_HEADER, *(_calibration_cells(entry) for entry in self.calibrations)]),
            "",
            "change of the drift surfaces between consecutive calibrations, new - old, "
            f"on a {GRID_POINTS} x {GRID_POINTS} grid over the domain both calibrated:",
            aligned([CHANGE_HEADER, *(cells for change in self.changes for cells in _change_cells(change))]),
        ]
        lines += [
            f"  {change.older.shown_date} -> {change.newer.shown_date} {surface}: {why}"
            for change in self.changes
            for surface, why in change.not_compared.items()
        ]
        return "\n".join(lines)

    def document(self) -> dict[str, Any]:
        return {
            "sensor_id": self.sensor_id,
            "registry": self.registry,
            "change": "f_new - f_old over the intersection of both fits' temperature and acceleration ranges, "
            f"on a {GRID_POINTS} x {GRID_POINTS} grid; degrees: tilt_deg(a + change) - tilt_deg(a)",
            "calibrations": [_entry_json(entry) for entry in self.calibrations],
            "changes": [
                {
                    "from": _entry_json(change.older),
                    "to": _entry_json(change.newer),
                    "surfaces": {surface.surface: surface.document() for surface in change.surfaces},
                    "not_compared": change.not_compared,
                }
                for change in self.changes
            ],
        }

    def write(self, out_dir: Path) -> list[Path]:
        """history.json and, with a change to show, its figure; the files written."""
        written = [out_dir / HISTORY_FILE]
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
            written[0].write_text(json.dumps(self.document(), indent=2) + "\n", encoding="utf-8")
            if self.changes:
                written.append(out_dir / FIGURE_FILE)
                _figure(self, written[-1])
        except OSError as error:
            raise HistoryError(f"cannot write {error.filename or out_dir}: {error.strerror or error}") from None
        return written


def history(registry: Registry, sensor_id: str) -> History:
    """sensor_id's calibrations, oldest first (undated ones before the
    dated), and the change between each and the next."""
    with registry.reading() as session:
        if session.get(Sensor, sensor_id) is None:
            raise HistoryError(
                f"no sensor {sensor_id} in the registry {registry.shown_url}: `thermotilt sensors` lists those it has"
            )
        rows = session.scalars(select(Calibration).where(Calibration.sensor_id == sensor_id))
        ordered = sorted(rows, key=lambda row: (calibrated_at(row) or datetime.min, row.folder))
    entries = [
        CalibrationEntry(calibration_date(row), row.certificate_number, row.tilt_u95_deg, row.folder) for row in ordered
    ]
    changes = []
    if len(entries) > 1:
        fits = [_read_surfaces(entry) for entry in entries]
        changes = [
            _calibration_change(entries[index], entries[index + 1], fits[index], fits[index + 1])
            for index in range(len(entries) - 1)
        ]
    return History(sensor_id, registry.shown_url, entries, changes)


def _read_surfaces(entry: CalibrationEntry) -> dict[str, FittedSurface]:
    try:
        return read_fit(Path(entry.fit_folder))
    except CalibrationDataError as error:
        raise HistoryError(
            f"{error} (the registry recorded a fit there: `thermotilt registry rebuild` records the folders as they are)"
        ) from None


def _calibration_change(
    older: CalibrationEntry,
    newer: CalibrationEntry,
    old_fits: dict[str, FittedSurface],
    new_fits: dict[str, FittedSurface],
) -> CalibrationChange:
    surfaces, not_compared = [], {}
    for key in (f"{set_name}{axis}" for set_name in SETS for axis in COMPARED_AXES):
        if key not in old_fits or key not in new_fits:
            if key in old_fits or key in new_fits:
                not_compared[key] = f"fitted only in the {'older' if key in old_fits else 'newer'} calibration"
            continue
        change = surface_change(key, old_fits[key], new_fits[key])
        if change is None:
            not_compared[key] = "the two fits' domains do not overlap"
        else:
            surfaces.append(change)
    return CalibrationChange(older, newer, surfaces, not_compared)


def _calibration_text(entry: CalibrationEntry) -> str:
    certificate = f"certificate {entry.certificate_number}" if entry.certificate_number else "no certificate"
    u95 = f"U {two_significant(entry.u95_deg)} deg" if entry.u95_deg is not None else "no U"
    return f"{certificate}, {u95}, fit {shown_path(entry.fit_folder)}"


def _calibration_cells(entry: CalibrationEntry) -> tuple[str, ...]:
    return (
        entry.shown_date,
        entry.certificate_number or NONE,
        NONE if entry.u95_deg is None else two_significant(entry.u95_deg),
        shown_path(entry.fit_folder),
    )


def _change_cells(change: CalibrationChange) -> list[tuple[str, ...]]:
    return [
        (
            change.older.shown_date,
            change.newer.shown_date,
            f"{surface.surface[0]} {surface.surface[1]}",
            "{:.4g}..{:.4g}".format(*surface.temperature_c),
            "{:.0f}..{:.0f}".format(*surface.acceleration_lsb),
            f"{surface.rms_lsb:.3g}",
            f"{surface.largest_lsb:+.3g}",
            f"{surface.rms_deg:.2g}",
            f"{surface.largest_deg:+.2g}",
        )
        for surface in change.surfaces
    ]


def _entry_json(entry: CalibrationEntry) -> dict[str, Any]:
    return {
        "calibrated": None if entry.calibrated is None else entry.calibrated.isoformat(),
        "certificate_number": entry.certificate_number,
        "tilt_u95_deg": entry.u95_deg,
        "fit_folder": entry.fit_folder,
    }


def _figure(result: History, path: Path) -> None:
    """Above, the latest recalibration's change of tilt over the common
    domain, a map per set and axis; below, each recalibration's RMS
    (line) and largest (dashed) change of tilt beside each calibration's U."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    latest = result.changes[-1]
    figure = plt.figure(figsize=(4.5 * max(len(latest.surfaces), 3), 7.5), layout="constrained")
    maps, trends = figure.subfigures(2, 1)
    maps.suptitle(f"{result.sensor_id}: {latest.older.shown_date} → {latest.newer.shown_date}, new − old", fontsize=10)
    for panel, surface in zip(maps.subplots(1, max(len(latest.surfaces), 1), squeeze=False)[0], latest.surfaces):
        limit = max(float(np.max(np.abs(surface.grid_deg))), 1e-9)
        image = panel.imshow(
            surface.grid_deg,
            origin="lower",
            aspect="auto",
            extent=(*surface.temperature_c, *surface.acceleration_lsb),
            cmap="RdBu_r",
            vmin=-limit,
            vmax=limit,
        )
        maps.colorbar(image, ax=panel, label="change of tilt (°)")
        panel.set_title(f"{SET_NAMES[surface.surface[0]]} {surface.surface[1]}", fontsize=9)
        panel.set_xlabel("IMU temperature (°C)")
        panel.set_ylabel("acceleration (LSB)")
    changes, uncertainty = trends.subplots(1, 2)
    _draw_trends(result, changes)
    calibrations = range(len(result.calibrations))
    u95 = [np.nan if entry.u95_deg is None else entry.u95_deg for entry in result.calibrations]
    uncertainty.plot(calibrations, u95, marker="o", color="black")
    uncertainty.set_xticks(list(calibrations), [entry.shown_date for entry in result.calibrations])
    uncertainty.set_ylabel("certificate's U (°)")
    uncertainty.set_title("U of each calibration", fontsize=10)
    uncertainty.set_ylim(bottom=0.0)
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _draw_trends(result: History, panel: Any) -> None:
    steps = range(len(result.changes))
    for key in sorted({surface.surface for change in result.changes for surface in change.surfaces}):
        by_step = [{surface.surface: surface for surface in change.surfaces}.get(key) for change in result.changes]
        colour, marker = SET_COLOURS[key[0]], AXIS_MARKERS[key[1]]
        rms = [np.nan if surface is None else surface.rms_deg for surface in by_step]
        largest = [np.nan if surface is None else abs(surface.largest_deg) for surface in by_step]
        panel.plot(steps, rms, marker=marker, color=colour, label=f"{key} RMS")
        panel.plot(
            steps, largest, marker=marker, color=colour, linestyle="--", fillstyle="none", label=f"{key} |largest|"
        )
    labels = [f"{change.older.shown_date}\n→ {change.newer.shown_date}" for change in result.changes]
    panel.set_xticks(list(steps), labels)
    panel.set_xlim(-0.5, len(result.changes) - 0.5)
    panel.set_ylabel("change of tilt (°)")
    panel.set_title("change of the drift surfaces at each recalibration", fontsize=10)
    panel.set_ylim(bottom=0.0)
    panel.legend(fontsize=7, ncol=2)
