"""A campaign's run logs as the residuals the paper fits (section 3.3).

For each tilt position (the rows of a run log at one incl_x_deg, incl_y_deg:
a campaign run holds several, a logged run one) and each warming/cooling set
the device chose (``comp_set``), the residual of an axis is its filtered acceleration
minus its filtered acceleration at 25 degC, the temperature the
manufacturer references; the regressors are the filtered IMU temperature
and the filtered acceleration itself, the same values the firmware
compensates with. The 25 degC reading is a straight line fitted to the
set's rows within ``REFERENCE_BAND_C`` of 25 degC, read at 25 degC, so each
set of each position has its own reference: the paper's f(25, a) is ~0 for
both sets (Tables 2, 3), which only per-set references give.

Rows are used only where the data mean what the fit assumes: the chamber
program running (phase W or C, when the log has the chamber) from the moment
its inner face first reaches the setpoint (within the band lib/Program's
waiting steps use), and the filters settled after a table move
(``since_move_s`` at least ``settle_s``; logs without that column lose their
first ``settle_s``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..program import REACHED_BAND_C
from ..run import SETTLE_S
from ..run.folder import LOG_FILE, RunFolder
from ..run.log import RunLogError, format_number, read_run_columns
from ..run.positions import mountings, settled, staircase
from ..surfaces import REFERENCE_C
from .campaign.folder import CampaignError, CampaignFolder

# Wide enough for a 2 degC staircase step's rows on both sides of 25 degC.
REFERENCE_BAND_C = 1.5
# Enough rows to draw the reference line through.
MIN_REFERENCE_ROWS = 10
# dT/dt is the temperature's change over +-RATE_HALF_WINDOW_S: the IMU
# reports it in 1/16 degC-ish steps, so a shorter window shows the steps.
RATE_HALF_WINDOW_S = 5.0
FIT_AXES = ("X", "Y")


class CalibrationDataError(ValueError):
    """A campaign folder that cannot be fitted; one readable line."""


@dataclass(frozen=True)
class SetData:
    """The rows of one warming/cooling set of every position, as arrays."""

    temperature_c: np.ndarray
    acceleration: dict[str, np.ndarray]  # axis -> filtered LSB
    residual: dict[str, np.ndarray]  # axis -> LSB minus the position's 25 degC reading (both sets')
    position: np.ndarray  # index into Campaign.positions, for grouped statistics
    # dT/dt of the filtered IMU temperature, degC/s, for model families with a rate term.
    rate_c_per_s: np.ndarray | None = None
    # The log's time_s: with position, puts a position's rows of both sets back in time order.
    time_s: np.ndarray | None = None


@dataclass(frozen=True)
class Campaign:
    positions: tuple[str, ...]  # "file (x .. deg, y .. deg)", one per position
    sets: dict[str, SetData]  # "W", "C"
    skipped_rows: int  # rows with an empty or unreadable cell
    stabilizing_rows: int = 0  # program rows before the chamber first reached its setpoint
    # The IMU's sensor ID campaign.json recorded ("" a board without one);
    # None where the folder does not say (no campaign.json, the twin).
    sensor_id: str | None = None


def run_logs(folder: Path) -> list[Path]:
    """Each position's run log (``*/run.csv``) and logs kept under other names (``*.csv``), sorted."""
    if not folder.is_dir():
        raise CalibrationDataError(f"{folder}: not a folder of run logs")
    logs = sorted(set(folder.glob(f"*/{LOG_FILE}")) | set(folder.glob("*.csv")))
    if not logs:
        raise CalibrationDataError(f"{folder}: no run log (*/{LOG_FILE} or *.csv)")
    return logs


def reading_at_25(temperature: np.ndarray, values: np.ndarray) -> float | None:
    """The straight line through the rows within REFERENCE_BAND_C of 25 degC,
    read at 25 degC; None with too few such rows."""
    near = np.abs(temperature - REFERENCE_C) <= REFERENCE_BAND_C
    if np.count_nonzero(near) < MIN_REFERENCE_ROWS or np.ptp(temperature[near]) == 0.0:
        return None
    slope, intercept = np.polyfit(temperature[near] - REFERENCE_C, values[near], 1)
    return float(intercept)


def _temperature_rates(time_s: np.ndarray, temperature_c: np.ndarray) -> np.ndarray:
    """Each row's dT/dt over +-RATE_HALF_WINDOW_S of the rows given (NaN
    where the time or temperature is unknown, and everywhere when the
    known times do not increase)."""
    rates = np.full(len(time_s), np.nan)
    known = np.isfinite(time_s) & np.isfinite(temperature_c)
    times, temperatures = time_s[known], temperature_c[known]
    if len(times) < 2 or np.any(np.diff(times) <= 0):
        return rates
    early = np.interp(times - RATE_HALF_WINDOW_S, times, temperatures)
    late = np.interp(times + RATE_HALF_WINDOW_S, times, temperatures)
    spans = np.minimum(times + RATE_HALF_WINDOW_S, times[-1]) - np.maximum(times - RATE_HALF_WINDOW_S, times[0])
    rates[known] = (late - early) / spans
    return rates


def _position_groups(name: str, numbers: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A run log's rows by mounting of the tilt table (run.positions), in
    order; a campaign run holds several, a logged run one. Each is named
    by its angles (and, for a position the table came back to, its count)."""
    mounting = mountings(numbers["incl_x_deg"], numbers["incl_y_deg"], numbers["since_move_s"])
    starts = np.flatnonzero(np.diff(mounting, prepend=-1))
    groups = {}
    for start, end in zip(starts, [*starts[1:], len(mounting)]):
        x, y = (format_number(numbers[column][start], 2) for column in ("incl_x_deg", "incl_y_deg"))
        label = f"{name} (" + (f"x {x} deg, y {y} deg" if x or y else "angles unknown") + ")"
        visits = sum(key.split(" #")[0] == label for key in groups)
        groups[label if not visits else f"{label} #{visits + 1}"] = np.arange(start, end)
    return groups


def _position_reference(label: str, by_set: dict[str, np.ndarray]) -> np.ndarray:
    """The one reading both sets' residuals are taken against, per column
    (temperature, X, Y, rate, time; zero but for X and Y): the mean of the two
    sets' readings at 25 degC. Each set's surface then carries its offset
    from the other, and a reading compensated with either set is the same."""
    references = []
    for set_name, data in by_set.items():
        if not len(data):
            raise CalibrationDataError(f"{label}: no settled rows of the {set_name} set")
        at_25 = [reading_at_25(data[:, 0], data[:, column]) for column in (1, 2)]
        if None in at_25:
            raise CalibrationDataError(
                f"{label}: the {set_name} set never crosses {REFERENCE_C:g} degC "
                f"(needs {MIN_REFERENCE_ROWS} rows within {REFERENCE_BAND_C:g} degC of it)"
            )
        references.append(at_25)
    return np.array([0.0, *np.mean(references, axis=0), 0.0, 0.0])


def load(folder: Path, settle_s: float | None = None) -> Campaign:
    """Every position's residuals per set; CalibrationDataError when a
    position cannot give them."""
    settle_s = SETTLE_S if settle_s is None else settle_s
    positions: list[str] = []
    parts: dict[str, list[tuple[int, np.ndarray, np.ndarray]]] = {"W": [], "C": []}
    skipped = stabilizing = 0
    for path in run_logs(folder):
        try:
            log = read_run_columns(str(path))
        except RunLogError as error:
            raise CalibrationDataError(str(error)) from None
        if log.rows == 0:
            raise CalibrationDataError(f"{path}: no rows")
        numbers, texts = log.numbers, log.texts
        has_chamber = bool((texts["phase"] != "").any())
        for label, rows in _position_groups(RunFolder.of(path).name, numbers).items():
            index = len(positions)
            positions.append(label)
            time_s = numbers["time_s"][rows]
            mounting = np.zeros(len(rows), dtype=int)
            used = settled(time_s, mounting, numbers["since_move_s"][rows], settle_s)
            if has_chamber:
                kept, before_setpoint = staircase(
                    texts["phase"][rows], numbers["chamber_c"][rows], numbers["setpoint_c"][rows], mounting
                )
                if before_setpoint.any() and not kept.any():
                    raise CalibrationDataError(
                        f"{label}: the chamber's inner face never came within "
                        f"{REACHED_BAND_C:g} degC of its program's setpoint"
                    )
                stabilizing += int(np.count_nonzero(before_setpoint))
                used &= kept
            used_rows = rows[used]
            columns = np.column_stack(
                [
                    numbers["imu_temp_c"][used_rows],
                    numbers["ax_filt"][used_rows],
                    numbers["ay_filt"][used_rows],
                    _temperature_rates(numbers["time_s"][used_rows], numbers["imu_temp_c"][used_rows]),
                    numbers["time_s"][used_rows],
                ]
            )
            comp_set = texts["comp_set"][used_rows]
            by_set = {}
            for set_name in parts:
                cells = columns[comp_set == set_name]
                by_set[set_name] = cells[np.isfinite(cells).all(axis=1)]
                skipped += len(cells) - len(by_set[set_name])
            reference = _position_reference(label, by_set)
            for set_name, set_parts in parts.items():
                set_parts.append((index, by_set[set_name], reference))
    sets = {}
    for set_name, set_parts in parts.items():
        data = np.concatenate([part[1] for part in set_parts])
        residual = np.concatenate([part[1] - part[2] for part in set_parts])
        sets[set_name] = SetData(
            temperature_c=data[:, 0],
            acceleration={axis: data[:, 1 + i] for i, axis in enumerate(FIT_AXES)},
            residual={axis: residual[:, 1 + i] for i, axis in enumerate(FIT_AXES)},
            position=np.concatenate([np.full(len(part[1]), part[0]) for part in set_parts]),
            rate_c_per_s=data[:, 3],
            time_s=data[:, 4],
        )
    try:
        sensor_id = CampaignFolder(folder).recorded_sensor_id()
    except CampaignError as error:
        raise CalibrationDataError(str(error)) from None
    return Campaign(tuple(positions), sets, skipped, stabilizing, sensor_id)
