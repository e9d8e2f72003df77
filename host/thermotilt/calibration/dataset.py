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

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..run.log import RunLogError, read_run_log
from ..program import REACHED_BAND_C

REFERENCE_C = 25.0
# Wide enough for a 2 degC staircase step's rows on both sides of 25 degC.
REFERENCE_BAND_C = 1.5
# Enough rows to draw the reference line through.
MIN_REFERENCE_ROWS = 10
# After a table move without RESEED the Kalman filter needs ~90 s to forget
# a 45 deg step (docs/run-log.md); with RESEED it is settled within a second.
DEFAULT_SETTLE_S = 120.0
# dT/dt is the temperature's change over +-RATE_HALF_WINDOW_S: the IMU
# reports it in 1/16 degC-ish steps, so a shorter window shows the steps.
RATE_HALF_WINDOW_S = 5.0
FIT_AXES = ("X", "Y")
_RUNNING_PHASES = {"W", "C"}


class CalibrationDataError(ValueError):
    """A campaign folder that cannot be fitted; one readable line."""


@dataclass(frozen=True)
class SetData:
    """The rows of one warming/cooling set of every position, as arrays."""

    temperature_c: np.ndarray
    acceleration: dict[str, np.ndarray]  # axis -> filtered LSB
    residual: dict[str, np.ndarray]  # axis -> LSB minus the 25 degC reading
    position: np.ndarray  # index into Campaign.positions, for grouped statistics
    # dT/dt of the filtered IMU temperature, degC/s, for model families with a rate term.
    rate_c_per_s: np.ndarray | None = None


@dataclass(frozen=True)
class Campaign:
    positions: tuple[str, ...]  # "file (x .. deg, y .. deg)", one per position
    sets: dict[str, SetData]  # "W", "C"
    skipped_rows: int  # rows with an empty or unreadable cell
    stabilizing_rows: int = 0  # program rows before the chamber first reached its setpoint


def run_logs(folder: Path) -> list[Path]:
    """``*/run.csv`` and ``*.csv`` in the run-log schema, sorted."""
    if not folder.is_dir():
        raise CalibrationDataError(f"{folder}: not a folder of run logs")
    logs = sorted(set(folder.glob("*/run.csv")) | set(folder.glob("*.csv")))
    if not logs:
        raise CalibrationDataError(f"{folder}: no run log (*/run.csv or *.csv)")
    return logs


def _number(cell: str) -> float:
    return float(cell) if cell else math.nan


def _settled(rows: list[dict[str, str]], settle_s: float, start_s: float) -> list[dict[str, str]]:
    """Rows at least settle_s after the table's move, or after start_s in a
    log that does not say when the table moved."""
    if rows and rows[0].get("since_move_s", "") != "":
        return [row for row in rows if _number(row["since_move_s"]) >= settle_s]
    return [row for row in rows if _number(row["time_s"]) - start_s >= settle_s]


def _staircase(rows: list[dict[str, str]]) -> tuple[list[dict[str, str]], int]:
    """The rows of each program run (phase W or C) from the first one whose
    inner face is within REACHED_BAND_C of its setpoint, and how many
    program rows came before. Before that the chamber is still coming at
    full drive from where the program found it (the lab, a rest): the
    paper's "temperature stabilization" ahead of its measuring steps
    (section 3.1), whose fast cooling would otherwise fill the cooling set
    (docs/calibration.md). A log without the inner face's temperature keeps
    every program row."""
    knows_face = any(row["chamber_c"] for row in rows)
    kept: list[dict[str, str]] = []
    stabilizing = 0
    arrived = False
    for row in rows:
        if row["phase"] not in _RUNNING_PHASES:
            arrived = False
            continue
        arrived = arrived or not knows_face or (
            abs(_number(row["chamber_c"]) - _number(row["setpoint_c"])) <= REACHED_BAND_C)
        if arrived:
            kept.append(row)
        else:
            stabilizing += 1
    return kept, stabilizing


def _positions(path: Path, rows: list[dict[str, str]]) -> dict[str, list[dict[str, str]]]:
    """A run log's rows by tilt position (its incl_x_deg, incl_y_deg cells),
    in order; a campaign run holds several, a logged run one."""
    name = path.parent.name if path.name == "run.csv" else path.stem
    groups: dict[str, list[dict[str, str]]] = {}
    for row in rows:
        x, y = row["incl_x_deg"], row["incl_y_deg"]
        angles = f"x {x} deg, y {y} deg" if x or y else "angles unknown"
        groups.setdefault(f"{name} ({angles})", []).append(row)
    return groups


def reading_at_25(temperature: np.ndarray, values: np.ndarray) -> float | None:
    """The straight line through the rows within REFERENCE_BAND_C of 25 degC,
    read at 25 degC; None with too few such rows."""
    near = np.abs(temperature - REFERENCE_C) <= REFERENCE_BAND_C
    if np.count_nonzero(near) < MIN_REFERENCE_ROWS or np.ptp(temperature[near]) == 0.0:
        return None
    slope, intercept = np.polyfit(temperature[near] - REFERENCE_C, values[near], 1)
    return float(intercept)


def _temperature_rates(rows: list[dict[str, str]]) -> list[str]:
    """Each row's dT/dt over +-RATE_HALF_WINDOW_S of its position's rows, as
    text like the other cells ("" where the temperature or time is empty)."""
    cells = [(_number(row["time_s"]), _number(row["imu_temp_c"])) for row in rows]
    known = np.array([cell for cell in cells if not math.isnan(cell[0] + cell[1])])
    if len(known) < 2 or np.any(np.diff(known[:, 0]) <= 0):
        return [""] * len(rows)
    times, temperatures = known[:, 0], known[:, 1]
    early = np.interp(times - RATE_HALF_WINDOW_S, times, temperatures)
    late = np.interp(times + RATE_HALF_WINDOW_S, times, temperatures)
    spans = np.minimum(times + RATE_HALF_WINDOW_S, times[-1]) - np.maximum(times - RATE_HALF_WINDOW_S, times[0])
    rate = iter((late - early) / spans)
    return [repr(float(next(rate))) if not math.isnan(time + temperature) else "" for time, temperature in cells]


def load(folder: Path, settle_s: float | None = None) -> Campaign:
    """Every position's residuals per set; CalibrationDataError when a
    position cannot give them."""
    settle_s = DEFAULT_SETTLE_S if settle_s is None else settle_s
    positions: list[str] = []
    parts: dict[str, list[tuple[int, np.ndarray, np.ndarray]]] = {"W": [], "C": []}
    skipped = stabilizing = 0
    for path in run_logs(folder):
        try:
            rows = read_run_log(str(path))
        except RunLogError as error:
            raise CalibrationDataError(str(error)) from None
        if not rows:
            raise CalibrationDataError(f"{path}: no rows")
        has_chamber = any(row["phase"] for row in rows)
        for label, position_rows in _positions(path, rows).items():
            index = len(positions)
            positions.append(label)
            staircase = position_rows
            if has_chamber:
                staircase, before_setpoint = _staircase(position_rows)
                if before_setpoint and not staircase:
                    raise CalibrationDataError(f"{label}: the chamber's inner face never came within "
                                               f"{REACHED_BAND_C:g} degC of its program's setpoint")
                stabilizing += before_setpoint
            used = _settled(staircase, settle_s, start_s=_number(position_rows[0]["time_s"]))
            rates = _temperature_rates(used)
            for set_name, set_parts in parts.items():
                cells = [(row["imu_temp_c"], row["ax_filt"], row["ay_filt"], rate)
                         for row, rate in zip(used, rates) if row["comp_set"] == set_name]
                complete = [cell for cell in cells if all(cell)]
                skipped += len(cells) - len(complete)
                if not complete:
                    raise CalibrationDataError(f"{label}: no settled rows of the {set_name} set")
                data = np.array(complete, dtype=float)
                references = [reading_at_25(data[:, 0], data[:, column]) for column in (1, 2)]
                if None in references:
                    raise CalibrationDataError(
                        f"{label}: the {set_name} set never crosses {REFERENCE_C:g} degC "
                        f"(needs {MIN_REFERENCE_ROWS} rows within {REFERENCE_BAND_C:g} degC of it)"
                    )
                set_parts.append((index, data, np.array([0.0, *references, 0.0])))
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
        )
    return Campaign(tuple(positions), sets, skipped, stabilizing)
