"""The model replayed open loop on a measured run's inputs.

The sensor part of the physics model (the same `Sensor` the twin steps) is
driven by the inner face's temperature, as the logged thermistor reading
(``chamber_c``) and the model's ``thermistor_lag`` imply, and the table
angles, with its random terms switched off; what it would have put in the
registers then goes through the firmware's own filters (the Kalman filter
lib/ImuProcessing runs per axis and for the temperature;
``thermotilt.native``, the firmware's C++ compiled for the host) on the
IMU's 100 Hz sample grid, and is read at the logged rows. The
result predicts each channel the log measured: the IMU's filtered
temperature and filtered acceleration per axis.

The chamber part (the same `Chamber` the twin steps) is driven by the
logged ambient temperature and the bridge's drive (``pwm``, ``direction``)
from one chamber status frame to the next, from faces at rest where the
first readings put them, and predicts both thermistors' readings.

The replay is open loop: nothing measured on the sensor side feeds it, and
no reading feeds the chamber after its first, so a model error shows where
it acts instead of being absorbed by a controller.
"""

from __future__ import annotations

import functools
import hashlib
import json
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .. import native
from ..physics import Chamber, Model
from ..physics.document import plain
from ..physics.sensor import registered_temperature_c, sensor_series
from ..physics.terms import REGISTRY, SensorTerm
from ..run import SETTLE_S, positions
from ..run.folder import RunFolder, RunFolderError
from ..run.log import RunColumns, RunLogError, read_run_columns

# Channel -> the run.csv column it is measured in.
CHANNEL_COLUMNS: Mapping[str, str] = {
    "temperature": "imu_temp_c",
    "X": "ax_filt",
    "Y": "ay_filt",
    "Z": "az_filt",
}
# The chamber's channels: each thermistor's reading, predicted from the drive.
CHAMBER_CHANNEL_COLUMNS: Mapping[str, str] = {"inner": "chamber_c", "outer": "outer_c"}
CHAMBER_CHANNELS = tuple(CHAMBER_CHANNEL_COLUMNS)
CHANNELS = tuple(CHANNEL_COLUMNS) + CHAMBER_CHANNELS
# Channel -> the firmware output (thermotilt.native) it is.
FIRMWARE_OUTPUTS: Mapping[str, str] = {
    "temperature": "temp_c",
    "X": "ax_filt",
    "Y": "ay_filt",
    "Z": "az_filt",
}
ACCELERATION_CHANNELS = ("X", "Y", "Z")
INPUT_COLUMNS = ("time_s", "chamber_c", "incl_x_deg", "incl_y_deg")
CHAMBER_INPUT_COLUMNS = ("ambient_c", "pwm", "direction", "outer_c")
CHAMBER_INPUTS = ("ambient_c", "duty", "direction", "outer_c")  # Measured's names of them
# The CHS frame's direction letter -> the bridge's direction.
DIRECTIONS: Mapping[str, int] = {"H": 1, "C": -1, "O": 0}
# analogWrite's full scale: the bridge conducts pwm/255 of the time (the
# Mega's pin 9 runs phase-correct PWM, which the twin's bridge measures too).
PWM_FULL_SCALE = 255.0
# The terms that draw random numbers: they are the noise a replay cannot
# predict, so the replay runs without them (docs/discovery.md).
STOCHASTIC_TERMS = ("noise", "bias_instability", "drift_repeatability")
SENSOR_TERM_NAMES = frozenset(name for name, term in REGISTRY.items() if issubclass(term, SensorTerm))
# The IMU samples at 100 Hz (firmware/imu_reader).
SAMPLE_PERIOD_S = 0.01
# The thermistor's rate for the face behind it (inner_face_c): long against
# the reading's 0.01 degC steps and its 1 s frames, short against the 2.5 s lag.
FACE_RATE_HALF_WINDOW_S = 1.0
# How often the replay steps the model's sensor (sensor_steps).
SENSOR_STEP_S = 0.2
# Four thermistor time constants (chamber_rows).
CHAMBER_SETTLE_S = 10.0


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
    # The chamber's inputs (NaN where the log has none): the room, the
    # outer reading, the bridge's duty 0..1 and direction +1/-1/0, and the
    # rows that show a new chamber status frame.
    ambient_c: np.ndarray
    outer_c: np.ndarray
    duty: np.ndarray
    direction: np.ndarray
    status: np.ndarray
    observed: Mapping[str, np.ndarray]  # channel -> measured values (NaN: empty)
    used: Mapping[str, np.ndarray]  # channel -> bool mask of the rows compared
    skipped_rows: int  # rows without one of the inputs
    skipped_channels: Mapping[str, str]  # channel -> why it cannot be compared

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(channel for channel in CHANNELS if channel in self.used)


def settled_rows(
    time_s: np.ndarray, mounting: np.ndarray, since_move_s: np.ndarray, settle_s: float = SETTLE_S
) -> np.ndarray:
    """The rows settled after a table move (run.positions) and at least
    settle_s after the run's first row: the replay seeds its filters there,
    where the real ones may have run for long before."""
    return positions.settled(time_s, mounting, since_move_s, settle_s) & (time_s - time_s[0] >= settle_s)


def chamber_rows(time_s: np.ndarray, status: np.ndarray) -> np.ndarray:
    """The rows the chamber's channels are compared on: each new status
    frame from CHAMBER_SETTLE_S on. There is no filter to settle; the
    replay starts at rest where the first readings are, which holds once
    the thermistors' lag has had a few time constants."""
    return status & (time_s - time_s[0] >= CHAMBER_SETTLE_S)


def load_measured(path: Path, settle_s: float = SETTLE_S, inputs_only: bool = False) -> Measured:
    """A run's inputs and channels; inputs_only: a run that only drives a
    replay (thermotilt hide-effect's) and need not have any channel."""
    return measured_of(read_columns(path), settle_s, inputs_only)


def read_columns(path: Path) -> RunColumns:
    """A run folder's run.csv as columns."""
    try:
        return read_run_columns(str(RunFolder.of(path).log))
    except (RunFolderError, RunLogError) as error:
        raise DiscoveryDataError(str(error)) from None


def measured_of(columns: RunColumns, settle_s: float = SETTLE_S, inputs_only: bool = False) -> Measured:
    """load_measured of a run.csv already read."""
    csv_path = columns.path
    if columns.rows == 0:
        raise DiscoveryDataError(f"{csv_path}: no rows")
    numbers = columns.numbers
    known = np.ones(columns.rows, dtype=bool)
    for column in INPUT_COLUMNS:
        known &= np.isfinite(numbers[column])
    if np.count_nonzero(known) < 2:
        empty = [column for column in INPUT_COLUMNS if not np.isfinite(numbers[column]).any()]
        why = f"no {', '.join(empty)}" if empty else "too few rows with all of them"
        raise DiscoveryDataError(f"{csv_path}: the replay needs {', '.join(INPUT_COLUMNS)} and the log has {why}")
    time_s = numbers["time_s"][known]
    steps = np.diff(time_s)
    if np.any(steps <= 0):
        row = int(np.flatnonzero(steps <= 0)[0]) + 2
        raise DiscoveryDataError(f"{csv_path}: time_s does not increase at row {row}")
    incl_x, incl_y = numbers["incl_x_deg"][known], numbers["incl_y_deg"][known]
    since_move_s = numbers["since_move_s"][known]
    mounting = positions.mountings(incl_x, incl_y, since_move_s)
    settled = settled_rows(time_s, mounting, since_move_s, settle_s)

    chamber = _chamber_inputs(columns, known)
    observed: dict[str, np.ndarray] = {}
    used: dict[str, np.ndarray] = {}
    skipped_channels: dict[str, str] = {}
    chamber_missing = [
        column for column, name in zip(CHAMBER_INPUT_COLUMNS, CHAMBER_INPUTS) if not np.isfinite(chamber[name]).all()
    ]
    for channel, column in {**CHANNEL_COLUMNS, **CHAMBER_CHANNEL_COLUMNS}.items():
        values = numbers[column][known]
        compared = chamber_rows(time_s, chamber["status"]) if channel in CHAMBER_CHANNELS else settled
        mask = compared & np.isfinite(values)
        if channel in CHAMBER_CHANNELS:
            if chamber_missing:
                skipped_channels[channel] = (
                    f"the chamber replay needs {', '.join(CHAMBER_INPUT_COLUMNS)} on every row "
                    f"and the log lacks {', '.join(chamber_missing)} on some or all"
                )
                continue
        if not np.isfinite(values).any():
            skipped_channels[channel] = f"the log has no {column}"
        elif np.count_nonzero(mask) < 2:
            skipped_channels[channel] = (
                f"fewer than 2 rows of {column} at least {settle_s:g} s after the start and after a table move"
            )
        else:
            observed[channel] = values
            used[channel] = mask
    if not used and not inputs_only:
        raise DiscoveryDataError(f"{csv_path}: no channel to compare: " + "; ".join(skipped_channels.values()))
    return Measured(
        source=str(csv_path),
        time_s=time_s,
        chamber_c=numbers["chamber_c"][known],
        incl_x_deg=incl_x,
        incl_y_deg=incl_y,
        mounting=mounting,
        ambient_c=chamber["ambient_c"],
        outer_c=chamber["outer_c"],
        duty=chamber["duty"],
        direction=chamber["direction"],
        status=chamber["status"],
        observed=observed,
        used=used,
        skipped_rows=int(np.count_nonzero(~known)),
        skipped_channels=skipped_channels,
    )


def _chamber_inputs(columns, known: np.ndarray) -> dict[str, np.ndarray]:
    """The chamber's inputs at the known rows, and which rows show a new
    status frame (a logger repeats the last one on every IMU row)."""
    numbers = columns.numbers
    letters = columns.texts.get("direction", [""] * columns.rows)
    direction = np.array([DIRECTIONS.get(letter, np.nan) for letter in letters], dtype=float)[known]
    inputs = {
        "ambient_c": numbers["ambient_c"][known],
        "outer_c": numbers["outer_c"][known],
        "duty": numbers["pwm"][known] / PWM_FULL_SCALE,
        "direction": direction,
    }
    status = np.ones(int(np.count_nonzero(known)), dtype=bool)
    frame = [numbers["chamber_c"][known], inputs["outer_c"], inputs["duty"], direction]
    status[1:] = np.any([np.diff(values) != 0 for values in frame], axis=0)
    inputs["status"] = status
    return inputs


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
        row_index = np.minimum(np.rint((time_s - time_s[0]) / SAMPLE_PERIOD_S).astype(np.int64), count - 1)
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
    time_s = measured.time_s[steps]
    dt_s = np.diff(time_s, prepend=time_s[0] - SAMPLE_PERIOD_S)
    series = sensor_series(
        model, seed, float(chamber_c[0]), dt_s, middle_c, measured.incl_x_deg[steps], measured.incl_y_deg[steps]
    )
    return np.stack([series.reported_c, series.unrounded_ax, series.unrounded_ay, series.unrounded_az])


def inner_face_c(time_s: np.ndarray, chamber_c: np.ndarray, model: Model, status: np.ndarray) -> np.ndarray:
    """The inner face's temperature at every row from its thermistor's
    reading, taken where it was new (the status rows: a logger holds it
    between), as the model's `thermistor_lag` implies: a first-order lag
    reads r' = (face - r) / tau, so face = r + tau r', the rate taken over
    +-FACE_RATE_HALF_WINDOW_S."""
    read_s, reading = time_s[status], chamber_c[status]
    if not model.enabled("thermistor_lag") or len(read_s) < 2:
        return np.interp(time_s, read_s, reading)
    tau = float(model.terms["thermistor_lag"]["time_constant_s"])
    early = np.interp(time_s - FACE_RATE_HALF_WINDOW_S, read_s, reading)
    late = np.interp(time_s + FACE_RATE_HALF_WINDOW_S, read_s, reading)
    span = np.minimum(time_s + FACE_RATE_HALF_WINDOW_S, read_s[-1]) - np.maximum(
        time_s - FACE_RATE_HALF_WINDOW_S, read_s[0]
    )
    return np.interp(time_s, read_s, reading) + tau * (late - early) / np.maximum(span, 1e-9)


def reading_offsets_c(model: Model) -> tuple[float, float]:
    """What the model's thermistors read above their faces (inner, outer)."""
    if not model.enabled("thermistor_offset"):
        return 0.0, 0.0
    offsets = model.terms["thermistor_offset"]["offset_c"]
    return float(offsets["inner"]), float(offsets["outer"])


def chamber_replay(
    measured: Measured, model: Model, start_shift_c: tuple[float, float] = (0.0, 0.0)
) -> dict[str, np.ndarray]:
    """The model's chamber driven open loop from one status frame to the
    next, the drive of each held until the next: at every row (its latest
    status) the inner and outer readings, and the inner face. It starts at
    rest where the first readings put the faces, moved by start_shift_c."""
    status = np.flatnonzero(measured.status)
    first = int(status[0])
    chamber = Chamber(model, float(measured.ambient_c[first]))
    chamber.start_at_readings(
        float(measured.chamber_c[first]) + start_shift_c[0], float(measured.outer_c[first]) + start_shift_c[1]
    )
    values = np.empty((3, len(status)))
    values[:, 0] = (*chamber.readings_c(), chamber.inner_c)
    held = status[:-1]
    values[:, 1:] = chamber.held(
        np.diff(measured.time_s[status]),
        measured.duty[held],
        measured.direction[held],
        measured.ambient_c[held],
    )
    latest = np.cumsum(measured.status) - 1
    inner, outer, face = values[:, latest]
    return {"inner": inner, "outer": outer, "face": face}


def _sensor_replay(measured: Measured, model: Model, grid: SampleGrid, inputs: str) -> dict[str, np.ndarray]:
    """The sensor, on the inner face its thermistor's reading implies, at
    the rows sensor_steps chooses, the firmware's filters on the 100 Hz grid
    between them: each channel's filter runs again only on a series it has
    not had on these inputs (a candidate on one axis leaves the others as
    they were)."""
    steps = sensor_steps(measured)
    reading_c = measured.chamber_c - reading_offsets_c(model)[0]
    face = replace(measured, chamber_c=inner_face_c(measured.time_s, reading_c, model, measured.status))
    values = sensor_values(face, deterministic(model), steps)
    knots = measured.time_s[steps]

    def filtered(channel: str, series: np.ndarray) -> dict[str, np.ndarray]:
        samples = grid.sample(knots, series)
        if channel == "temperature":
            # The register's 1/8 degC steps are part of the model, not noise:
            # at a hold they put the firmware's temperature on a step for good.
            samples = registered_temperature_c(model, samples)
        return {channel: native.kalman_estimates(samples, grid.reset, at=grid.row_index).astype(float)}

    predicted = {}
    for channel, series in zip(FIRMWARE_OUTPUTS, values):
        register = _register_key(model) if channel == "temperature" else ""
        digest = hashlib.blake2b(series.tobytes(), digest_size=16).hexdigest()
        key = ("filtered", inputs, channel, register, digest)
        predicted[channel] = _PARTS.get(key, functools.partial(filtered, channel, series))[channel]
    return predicted


def _register_key(model: Model) -> str:
    """What of the model registered_temperature_c depends on."""
    parts = {"quantised": model.enabled("temperature_quantisation"), "sensor": model.constants["sensor"]}
    return json.dumps(plain(parts), sort_keys=True)


def _sensor_key(model: Model) -> str:
    """What of the model the sensor replay depends on."""
    parts = {name: values for name, values in model.terms.items() if name in SENSOR_TERM_NAMES}
    parts.update(
        sensor=model.constants["sensor"], lag=model.terms["thermistor_lag"], offset=reading_offsets_c(model)[0]
    )
    return json.dumps(plain(parts), sort_keys=True)


def _chamber_key(model: Model) -> str:
    """What of the model the chamber replay may depend on: every term that
    is not the sensor's, and the constants but the sensor's."""
    parts = {
        "terms": {name: values for name, values in model.terms.items() if name not in SENSOR_TERM_NAMES},
        "constants": {name: values for name, values in model.constants.items() if name != "sensor"},
    }
    return json.dumps(plain(parts), sort_keys=True)


def _fingerprint(measured: Measured) -> str:
    """The replay's inputs of a run, as one digest."""
    digest = hashlib.blake2b(digest_size=16)
    for values in (
        measured.time_s,
        measured.chamber_c,
        measured.status,
        measured.incl_x_deg,
        measured.incl_y_deg,
        measured.mounting,
        *(getattr(measured, name) for name in CHAMBER_INPUTS),
    ):
        digest.update(np.ascontiguousarray(values).tobytes())
    return digest.hexdigest()


class _Parts:
    """Replayed parts (arrays per channel, read only) by the run's inputs
    and the part of the model they depend on, shared by every Replay in
    this process, the oldest dropped beyond BUDGET_BYTES: a search replays
    the same model many times (rounds, probes, every channel of a
    candidate), and a benchmark's runs on one base replay the same inputs."""

    BUDGET_BYTES = 256 * 2**20

    def __init__(self) -> None:
        self._parts: OrderedDict[tuple[str, ...], dict[str, np.ndarray]] = OrderedDict()
        self._bytes = 0

    def get(self, key: tuple[str, ...], make: Callable[[], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        if key in self._parts:
            self._parts.move_to_end(key)
            return self._parts[key]
        part = make()
        for values in part.values():
            values.flags.writeable = False
        self._parts[key] = part
        self._bytes += sum(values.nbytes for values in part.values())
        while self._bytes > self.BUDGET_BYTES and len(self._parts) > 1:
            _, dropped = self._parts.popitem(last=False)
            self._bytes -= sum(values.nbytes for values in dropped.values())
        return part


_PARTS = _Parts()


class Replay:
    """The replay of one measured run under any model, each part computed
    again only when the terms it depends on change (a chamber candidate
    leaves the sensor's replay as it was), and kept for other runs with the
    same inputs (_Parts)."""

    def __init__(self, measured: Measured) -> None:
        self.measured = measured
        self.grid = SampleGrid.of(measured.time_s, measured.mounting)
        self._inputs = _fingerprint(measured)
        self._chamber_wanted = any(channel in measured.used for channel in CHAMBER_CHANNELS)

    def __call__(self, model: Model) -> dict[str, np.ndarray]:
        """Each channel as the model predicts it at the measured rows, and
        the inner face ("face") where the chamber is replayed."""
        predicted = dict(
            _PARTS.get(
                ("sensor", self._inputs, _sensor_key(model)),
                lambda: _sensor_replay(self.measured, model, self.grid, self._inputs),
            )
        )
        if self._chamber_wanted:
            predicted.update(self._chamber(model))
        return predicted

    def _chamber(self, model: Model) -> dict[str, np.ndarray]:
        return _PARTS.get(("chamber", self._inputs, _chamber_key(model)), lambda: chamber_replay(self.measured, model))

    def chamber_start_response(self, model: Model) -> dict[str, np.ndarray]:
        """Per chamber channel, how its replay moves for 1 degC more on each
        face at the start (rows x 2: inner, outer): the start is not known
        better than the readings' offsets, so discovery takes these as
        nuisance columns. Kept as the replay's parts are: a search that
        finds nothing asks again for the model it started with."""
        return _PARTS.get(
            ("chamber start", self._inputs, _chamber_key(model)), lambda: self._chamber_start_response(model)
        )

    def _chamber_start_response(self, model: Model) -> dict[str, np.ndarray]:
        base = self._chamber(model)
        moved = [chamber_replay(self.measured, model, shift) for shift in ((1.0, 0.0), (0.0, 1.0))]
        return {channel: np.column_stack([m[channel] - base[channel] for m in moved]) for channel in CHAMBER_CHANNELS}


def replay(measured: Measured, model: Model) -> dict[str, np.ndarray]:
    """Each channel as the model predicts it at the measured rows (once;
    Replay keeps the parts for more models)."""
    return Replay(measured)(model)
