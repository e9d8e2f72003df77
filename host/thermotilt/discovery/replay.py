"""The model replayed open loop on a measured run's inputs.

The sensor part of the physics model (the same `Sensor` the twin steps) is
driven by the inner face's temperature, as the logged thermistor reading
(``chamber_c``) and the model's ``thermistor_lag`` imply, and the table
angles, with its random terms switched off; what it would have put in the
registers then goes through the firmware's own processing (Kalman filters,
trend detector; ``thermotilt.native``, the firmware's C++ compiled for the
host) on the IMU's 100 Hz sample grid, and is read at the logged rows. The
result predicts each channel the log measured: the IMU's filtered
temperature and filtered acceleration per axis.

The replay is open loop: nothing measured on the sensor side feeds it, so a
model error shows where it acts instead of being absorbed by a controller.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .. import native
from ..physics import Model, Sensor
from ..runlog import RunLogError, read_run_columns

# Channel -> the run.csv column it is measured in.
CHANNEL_COLUMNS: Mapping[str, str] = {
    "temperature": "imu_temp_c",
    "X": "ax_filt",
    "Y": "ay_filt",
    "Z": "az_filt",
}
CHANNELS = tuple(CHANNEL_COLUMNS)
# Channel -> the firmware output (thermotilt.native) it is.
FIRMWARE_OUTPUTS: Mapping[str, str] = {
    "temperature": "temp_c", "X": "ax_filt", "Y": "ay_filt", "Z": "az_filt",
}
ACCELERATION_CHANNELS = ("X", "Y", "Z")
INPUT_COLUMNS = ("time_s", "chamber_c", "incl_x_deg", "incl_y_deg")
# The terms that draw random numbers: they are the noise a replay cannot
# predict, so the replay runs without them (docs/discovery.md).
STOCHASTIC_TERMS = ("noise", "bias_instability", "drift_repeatability")
# The IMU samples at 100 Hz (firmware/imu_reader).
SAMPLE_PERIOD_S = 0.01
# The thermistor's rate for the face behind it (inner_face_c): long against
# the reading's 0.01 degC steps and its frames, short against the 2.5 s lag.
FACE_RATE_HALF_WINDOW_S = 1.0
# How often the replay steps the model's sensor (sensor_steps).
SENSOR_STEP_S = 0.2
# The firmware's Kalman filters seed on their first sample and take ~1/gain
# samples to forget it; the replay seeds at the log's first row and at every
# table move, where the real filters may have run for long before, so rows
# this close to either are left out (as `thermotilt fit` does).
DEFAULT_SETTLE_S = 120.0


class DiscoveryDataError(ValueError):
    """A measured run that cannot be replayed; one readable line."""


@dataclass(frozen=True)
class Measured:
    """A measured run's inputs and channels at its rows (rows with every
    input known), with the rows each channel can be compared on."""

    source: str
    time_s: np.ndarray
    chamber_c: np.ndarray
    incl_x_deg: np.ndarray
    incl_y_deg: np.ndarray
    # The table position's index, one more at every move (a new mounting).
    mounting: np.ndarray
    observed: Mapping[str, np.ndarray]  # channel -> measured values (NaN: empty)
    used: Mapping[str, np.ndarray]  # channel -> bool mask of the rows compared
    skipped_rows: int  # rows without one of the inputs
    skipped_channels: Mapping[str, str]  # channel -> why it cannot be compared

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(channel for channel in CHANNELS if channel in self.used)


def run_csv_of(path: Path) -> Path:
    """MEASURED is a run folder (with run.csv) or a run.csv itself."""
    if path.is_dir():
        path = path / "run.csv"
    if not path.is_file():
        raise DiscoveryDataError(f"{path}: no run log (a run folder with run.csv, or a run.csv)")
    return path


def settled_rows(time_s: np.ndarray, mounting: np.ndarray, settle_s: float) -> np.ndarray:
    """The rows at least settle_s after the run's start and after their
    mounting's first row (mounting never decreases)."""
    first_of_mounting = time_s[np.searchsorted(mounting, mounting)]
    return (time_s - first_of_mounting >= settle_s) & (time_s - time_s[0] >= settle_s)


def load_measured(path: Path, settle_s: float = DEFAULT_SETTLE_S, inputs_only: bool = False) -> Measured:
    """A run's inputs and channels; inputs_only: a run that only drives a
    replay (thermotilt hide-effect's) and need not have any channel."""
    csv_path = run_csv_of(path)
    try:
        columns = read_run_columns(str(csv_path))
    except RunLogError as error:
        raise DiscoveryDataError(str(error)) from None
    if columns.rows == 0:
        raise DiscoveryDataError(f"{csv_path}: no rows")
    numbers = columns.numbers
    known = np.ones(columns.rows, dtype=bool)
    for column in INPUT_COLUMNS:
        known &= np.isfinite(numbers[column])
    if np.count_nonzero(known) < 2:
        empty = [column for column in INPUT_COLUMNS if not np.isfinite(numbers[column]).any()]
        why = f"no {', '.join(empty)}" if empty else "too few rows with all of them"
        raise DiscoveryDataError(
            f"{csv_path}: the replay needs {', '.join(INPUT_COLUMNS)} and the log has {why}"
        )
    time_s = numbers["time_s"][known]
    steps = np.diff(time_s)
    if np.any(steps <= 0):
        row = int(np.flatnonzero(steps <= 0)[0]) + 2
        raise DiscoveryDataError(f"{csv_path}: time_s does not increase at row {row}")
    incl_x, incl_y = numbers["incl_x_deg"][known], numbers["incl_y_deg"][known]
    moved = np.zeros(len(time_s), dtype=bool)
    moved[1:] = (np.diff(incl_x) != 0) | (np.diff(incl_y) != 0)
    since_move = numbers["since_move_s"][known]
    if np.isfinite(since_move).all():
        moved[1:] |= np.diff(since_move) < 0
    mounting = np.cumsum(moved)
    settled = settled_rows(time_s, mounting, settle_s)

    observed: dict[str, np.ndarray] = {}
    used: dict[str, np.ndarray] = {}
    skipped_channels: dict[str, str] = {}
    for channel, column in CHANNEL_COLUMNS.items():
        values = numbers[column][known]
        mask = settled & np.isfinite(values)
        if not np.isfinite(values).any():
            skipped_channels[channel] = f"the log has no {column}"
        elif np.count_nonzero(mask) < 2:
            skipped_channels[channel] = (
                f"fewer than 2 rows of {column} at least {settle_s:g} s after the start "
                "and after a table move"
            )
        else:
            observed[channel] = values
            used[channel] = mask
    if not used and not inputs_only:
        raise DiscoveryDataError(
            f"{csv_path}: no channel to compare: " + "; ".join(skipped_channels.values())
        )
    return Measured(
        source=str(csv_path),
        time_s=time_s,
        chamber_c=numbers["chamber_c"][known],
        incl_x_deg=incl_x,
        incl_y_deg=incl_y,
        mounting=mounting,
        observed=observed,
        used=used,
        skipped_rows=int(np.count_nonzero(~known)),
        skipped_channels=skipped_channels,
    )


def deterministic(model: Model) -> Model:
    """The model without its random terms."""
    return model.with_terms({term: False for term in STOCHASTIC_TERMS})


@dataclass(frozen=True)
class SampleGrid:
    """The IMU's 100 Hz samples over a run: the grid index of each logged row
    and the samples at which the firmware's filters start again."""

    time_s: np.ndarray
    row_index: np.ndarray
    reset: np.ndarray

    @classmethod
    def of(cls, time_s: np.ndarray, mounting: np.ndarray) -> SampleGrid:
        count = int(round((time_s[-1] - time_s[0]) / SAMPLE_PERIOD_S)) + 1
        grid = time_s[0] + SAMPLE_PERIOD_S * np.arange(count)
        row_index = np.minimum(np.rint((time_s - time_s[0]) / SAMPLE_PERIOD_S).astype(np.int64),
                               count - 1)
        reset = np.zeros(count, dtype=bool)
        reset[row_index[np.flatnonzero(np.diff(mounting, prepend=-1))]] = True
        return cls(grid, row_index, reset)

    def sample(self, row_time_s: np.ndarray, values: np.ndarray) -> np.ndarray:
        return np.interp(self.time_s, row_time_s, values)


def sensor_steps(measured: Measured) -> np.ndarray:
    """The rows the replay steps the sensor at: about one per SENSOR_STEP_S,
    every mounting's first and last row. The model's sensor output is smooth
    on that scale (the die lags 15 s) and the firmware's filters see it
    linearly interpolated onto the 100 Hz grid. The step is short because
    the model's rate term takes the die's mean rate over a step for its end:
    a 0.2 s step leaves ~0.2 LSB RMS on Z over a staircase (rate_sensitivity
    z 1200 LSB per degC/s), a 1 s step 1.8 LSB."""
    typical_step = float(np.median(np.diff(measured.time_s)))
    stride = max(1, int(round(SENSOR_STEP_S / typical_step)))
    chosen = np.zeros(len(measured.time_s), dtype=bool)
    chosen[::stride] = True
    chosen[np.flatnonzero(np.diff(measured.mounting, prepend=-1))] = True
    chosen[np.flatnonzero(np.diff(measured.mounting, append=measured.mounting[-1] + 1))] = True
    return np.flatnonzero(chosen)


def sensor_values(measured: Measured, model: Model, steps: np.ndarray, seed: int = 0) -> np.ndarray:
    """The model's sensor stepped through the chosen rows: per row the
    reported temperature and the unrounded acceleration per axis (4 x rows).
    A step's chamber temperature is the mean of its two ends, so the die
    neither leads nor lags a ramp by half a step."""
    chamber_c = measured.chamber_c[steps]
    middle_c = np.concatenate([chamber_c[:1], 0.5 * (chamber_c[1:] + chamber_c[:-1])])
    sensor = Sensor(model, seed, float(chamber_c[0]))
    values = np.empty((4, len(steps)))
    previous = measured.time_s[steps[0]] - SAMPLE_PERIOD_S
    for index, (time_s, environment_c, incl_x, incl_y) in enumerate(zip(
        measured.time_s[steps].tolist(), middle_c.tolist(),
        measured.incl_x_deg[steps].tolist(), measured.incl_y_deg[steps].tolist(),
    )):
        sample = sensor.step(time_s - previous, environment_c, incl_x, incl_y)
        previous = time_s
        values[:, index] = (
            sample.reported_c, sample.unrounded_ax, sample.unrounded_ay, sample.unrounded_az
        )
    return values


def inner_face_c(time_s: np.ndarray, chamber_c: np.ndarray, model: Model) -> np.ndarray:
    """The inner face's temperature from its thermistor's reading, as the
    model's `thermistor_lag` implies: a first-order lag reads r' = (face - r)
    / tau, so face = r + tau r', the rate taken over +-FACE_RATE_HALF_WINDOW_S."""
    if not model.enabled("thermistor_lag"):
        return chamber_c
    tau = float(model.terms["thermistor_lag"]["time_constant_s"])
    early = np.interp(time_s - FACE_RATE_HALF_WINDOW_S, time_s, chamber_c)
    late = np.interp(time_s + FACE_RATE_HALF_WINDOW_S, time_s, chamber_c)
    span = (np.minimum(time_s + FACE_RATE_HALF_WINDOW_S, time_s[-1])
            - np.maximum(time_s - FACE_RATE_HALF_WINDOW_S, time_s[0]))
    return chamber_c + tau * (late - early) / span


def replay(measured: Measured, model: Model, grid: SampleGrid | None = None) -> dict[str, np.ndarray]:
    """Each channel as the model predicts it at the measured rows: the
    sensor, on the inner face the thermistor reading implies, at the rows
    sensor_steps chooses, the firmware's processing on the 100 Hz grid
    between them."""
    grid = SampleGrid.of(measured.time_s, measured.mounting) if grid is None else grid
    steps = sensor_steps(measured)
    face = replace(measured, chamber_c=inner_face_c(measured.time_s, measured.chamber_c, model))
    values = sensor_values(face, deterministic(model), steps)
    samples = [grid.sample(measured.time_s[steps], row) for row in values]
    filtered = native.imu_process_unrounded(samples[1], samples[2], samples[3], samples[0], grid.reset)
    return {channel: filtered[output][grid.row_index].astype(float)
            for channel, output in FIRMWARE_OUTPUTS.items()}
