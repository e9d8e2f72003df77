"""Measured-looking runs with an effect hidden in them, to test discovery on.

The chamber side of a run (the inner face its thermistor's reading implies,
as the replay takes it; table angles, program columns, the drive) is kept,
its chamber_c written as the inner thermistor reads that face (the model's
``thermistor_lag``), held from one chamber status frame to the next
(chamber_readings.py); a chamber effect changes the face and the readings
by what the chamber's replay with and without it gives. The sensor side is
generated again: the physics model's sensor, with one candidate term
changed, stepped on the IMU's 100 Hz grid with all its noise terms, and the
firmware's own processing (``thermotilt.native``) turning each sample into
filtered, compensated and decimated frames. The run folder gets a run.csv
without ``true_*`` columns; what was hidden goes to ``truth.json``, which
discovery never reads.

SNR is the effect's RMS over the noise's RMS on the channel it acts on, both
over the rows discovery compares (settled rows; about the mean on the
acceleration channels, whose constant offset discovery cannot see): the
effect is the replayed difference the changed term makes, the noise what
the random terms add to the firmware's output.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.optimize import brentq
from scipy.signal import lfilter

from .. import native
from ..physics import Model
from ..physics.document import with_values
from ..physics.sensor import SensorSeries, sensor_series
from ..run import SETTLE_S
from ..run import positions as run_positions
from ..run.folder import RunFolder, RunFolderError
from ..run.log import RunColumns, RunLogWriter, format_numbers
from ..surfaces import REFERENCE_C
from .candidates import BY_NAME, CANDIDATES, Candidate
from .chamber_readings import ChamberChange, adc_noise_c, frames_measured
from .channel import gap_rms
from .noise_families import NOISE_FAMILIES
from .replay import (
    CHAMBER_CHANNELS,
    SAMPLE_PERIOD_S,
    DiscoveryDataError,
    Measured,
    Replay,
    SampleGrid,
    inner_face_c,
    measured_of,
    read_columns,
    replay,
)

# "flicker": the model's flicker floor this many times larger.
FLICKER_FACTOR = 5.0
# "ar1-RHO": a bias wander per axis, RHO its correlation from one 10 Hz row
# to the next, its standard deviation the flicker family's Allan floor, so
# that it is as large as the undeclared part of that family.
WANDER_ROW_CORRELATION = {"ar1-0.99": 0.99, "ar1-0.999": 0.999}
# The families whose world differs from the model discovery is given in one
# declared noise term: (term, its per-axis parameter, the factor on it).
MISSPECIFIED = {
    "slope-0.5x": ("drift_repeatability", "sigma_lsb_per_c", 0.5),
    "slope-2x": ("drift_repeatability", "sigma_lsb_per_c", 2.0),
    "white-0.7x": ("noise", "sigma_lsb", 0.7),
    "white-1.3x": ("noise", "sigma_lsb", 1.3),
    "flicker-3x": ("bias_instability", "allan_floor_lsb", 3.0),
}
# "cubic": a drift term in (T - 25 degC)^3 on each axis, T the temperature
# the surfaces are evaluated at, whose part no quadratic in T fits has, over
# the paper's -10..45 degC (section 3.2), the RMS the paper's surfaces leave
# (Tables 2, 3): what the model declares as its drift-slope spread per
# mounting, sigma_lsb_per_c times the RMS of T - 25 degC over that span.
CUBIC_SPAN_C = (-10.0, 45.0)
# "temperature-noise": white noise on the temperature register, this many
# degC RMS per 100 Hz sample (4 register steps; assumed, the LSM9DS0
# datasheet gives none). The model declares only the register's rounding.
TEMPERATURE_NOISE_C = 0.5
# "temperature-coarse": the temperature register in steps of this many degC
# (the LSM9DS0's are 1/8 degC), the drift still following the fine one.
COARSE_TEMPERATURE_STEP_C = 1.0
REGISTER_FAMILIES = ("cubic", "temperature-noise", "temperature-coarse")
DEFAULT_SNR_RANGE = (0.5, 8.0)
# The chamber reports its readings to 0.01 degC (CHS, firmware/thermal_chamber).
CHS_DECIMALS = 2
# The firmware's frame cadence (firmware/imu_reader DEFAULT_DECIMATION).
DECIMATION = 10
# The chamber's columns, copied from the input run's nearest row.
_CHAMBER_COLUMNS = ("ambient_c", "setpoint_c", "chamber_c", "outer_c", "pwm", "direction", "phase", "chamber_fault")


@dataclass(frozen=True)
class Truth:
    effect: str  # a candidate's name, or "none"
    channel: str | None
    parameter: str | None
    value: float | None  # the parameter's value in the hidden model
    model_value: float | None  # its value in the model discovery is given
    snr: float | None
    effect_rms: float | None
    noise_rms: float
    noise: str
    seed: int
    inputs: str


def noisy(model: Model, noise: str) -> Model:
    """The model with the noise terms of this family (the AR(1) wander and
    the register families are added to the registers, _generate)."""
    if noise == "model" or noise in REGISTER_FAMILIES:
        return model
    if noise == "white" or noise in WANDER_ROW_CORRELATION:
        return model.with_terms({"bias_instability": False, "drift_repeatability": False})
    if noise in MISSPECIFIED:
        term, parameter, factor = MISSPECIFIED[noise]
        values = model.terms[term][parameter]
        return with_values(model, term, {parameter: {axis: factor * float(values[axis]) for axis in "xyz"}})
    if noise == "flicker":
        return with_values(
            model,
            "bias_instability",
            {"enabled": True, "allan_floor_lsb": _flicker_floors(model)},
        )
    raise ValueError(f"unknown noise {noise!r}; choose from {', '.join(NOISE_FAMILIES)}")


def _flicker_floors(model: Model) -> dict[str, float]:
    floors = model.terms["bias_instability"]["allan_floor_lsb"]
    return {axis: FLICKER_FACTOR * float(floors[axis]) for axis in "xyz"}


def _wander(model: Model, noise: str, count: int, seed: int) -> np.ndarray:
    """The AR(1) bias wander of an "ar1-" family on each axis (LSB, 3 x
    samples), stationary from the first sample."""
    phi = WANDER_ROW_CORRELATION[noise] ** (1.0 / DECIMATION)
    sd = np.array(list(_flicker_floors(model).values()))[:, None]
    rng = np.random.default_rng([seed, 1])
    shocks = rng.standard_normal((3, count)) * math.sqrt(1.0 - phi**2)
    shocks[:, 0] = rng.standard_normal(3)
    return sd * lfilter([1.0], [1.0, -phi], shocks, axis=-1)


def cubic_per_c3(model: Model) -> np.ndarray:
    """The "cubic" family's coefficient per axis (LSB per degC^3)."""
    excursion = np.linspace(*CUBIC_SPAN_C, 1101) - REFERENCE_C
    cubic = excursion**3
    unfitted = cubic - np.polyval(np.polyfit(excursion, cubic, 2), excursion)
    sigmas = model.terms["drift_repeatability"]["sigma_lsb_per_c"]
    left_rms = np.array([float(sigmas[axis]) for axis in "xyz"]) * math.sqrt(float(np.mean(excursion**2)))
    return left_rms / math.sqrt(float(np.mean(unfitted**2)))


def _register_changes(model: Model, noise: str, series: SensorSeries, seed: int) -> np.ndarray:
    """What the family adds to the registers beyond the model's terms (ax,
    ay, az and temperature, 4 x samples, LSB): the AR(1) wander, the cubic
    drift, the temperature reading's noise or coarser steps. Its own
    generator, so the run with the effect gets the same."""
    count = len(series.ax)
    changes = np.zeros((4, count))
    lsb_per_c = float(model.constants["sensor"]["temperature_lsb_per_c"])
    if noise in WANDER_ROW_CORRELATION:
        changes[:3] = _wander(model, noise, count, seed)
    elif noise == "cubic":
        changes[:3] = cubic_per_c3(model)[:, None] * (series.drift_temperature_c - REFERENCE_C) ** 3
    elif noise == "temperature-noise":
        changes[3] = np.random.default_rng([seed, 2]).standard_normal(count) * TEMPERATURE_NOISE_C * lsb_per_c
    elif noise == "temperature-coarse":
        step = COARSE_TEMPERATURE_STEP_C * lsb_per_c
        raw = series.temperature_raw.astype(float)
        changes[3] = step * np.round(raw / step) - raw
    return changes


class _Inputs:
    """A run an effect is hidden in, as read once: its columns, its inputs
    and the cells a generated run copies from it, which depend only on the
    frames' times and table angles and so are the same for every effect
    hidden in it (a benchmark hides hundreds in one base run)."""

    def __init__(self, columns: RunColumns) -> None:
        self.columns = columns
        self.measured = measured_of(columns, inputs_only=True)
        self._cells: dict[bytes, dict[str, list[str]]] = {}

    def cells(self, time_s: np.ndarray, incl_x: np.ndarray, incl_y: np.ndarray) -> dict[str, list[str]]:
        """The chamber's cells of the input's row at or before each frame, as
        a logger holds the last CHS frame, and the frames' times and table
        positions."""
        digest = hashlib.blake2b(digest_size=16)
        for values in (time_s, incl_x, incl_y):
            digest.update(np.ascontiguousarray(values, dtype=float).tobytes())
        key = digest.digest()
        if key not in self._cells:
            self._cells = {key: self._formatted(time_s, incl_x, incl_y)}
        return self._cells[key]

    def _formatted(self, time_s: np.ndarray, incl_x: np.ndarray, incl_y: np.ndarray) -> dict[str, list[str]]:
        columns = self.columns
        input_time = columns.numbers["time_s"]
        known = np.isfinite(input_time)
        input_rows = np.flatnonzero(known)
        nearest = input_rows[
            np.minimum(np.searchsorted(input_time[known], time_s, side="right") - 1, len(input_rows) - 1)
        ]
        no_log = np.full(len(time_s), np.nan)
        since_move = run_positions.since_move(time_s, run_positions.mountings(incl_x, incl_y, no_log), no_log)
        cells = {
            column: (
                [columns.texts[column][row] for row in nearest.tolist()]
                if column in columns.texts
                else format_numbers(columns.numbers[column][nearest].tolist(), 3)
            )
            for column in _CHAMBER_COLUMNS
        }
        cells.update(
            time_s=format_numbers(time_s.tolist(), 3),
            incl_x_deg=format_numbers(incl_x.astype(float).tolist(), 3),
            incl_y_deg=format_numbers(incl_y.astype(float).tolist(), 3),
            since_move_s=format_numbers(since_move.tolist(), 3),
            coef_source=["D"] * len(time_s),
            imu_seq=[str(index % 65536) for index in range(len(time_s))],
        )
        return cells


@functools.lru_cache(maxsize=2)
def _inputs_of(log: str, modified_ns: int, size: int) -> _Inputs:
    return _Inputs(read_columns(Path(log)))


def _read_inputs(path: Path) -> _Inputs:
    """The run folder's _Inputs, read again only when its run.csv changed."""
    try:
        log = RunFolder.of(path).log
        stat = log.stat()
    except (RunFolderError, OSError):
        return _Inputs(read_columns(path))
    return _inputs_of(str(log), stat.st_mtime_ns, stat.st_size)


def _generate(measured: Measured, model: Model, seed: int, noise: str = "model") -> dict[str, np.ndarray]:
    """The sensor stepped at 100 Hz through the run (with the bias wander
    of the noise family, if any, in its registers) and the firmware's
    processing of every sample: per-sample arrays on the grid."""
    grid = SampleGrid.of(measured.time_s, measured.mounting)
    chamber_c = grid.sample(measured.time_s, measured.chamber_c)
    row = np.minimum(np.searchsorted(measured.time_s, grid.time_s, side="right") - 1, len(measured.time_s) - 1)
    incl_x = measured.incl_x_deg[row]
    incl_y = measured.incl_y_deg[row]
    count = len(grid.time_s)
    series = sensor_series(model, seed, float(chamber_c[0]), np.full(count, SAMPLE_PERIOD_S), chamber_c, incl_x, incl_y)
    registers = np.stack([series.ax, series.ay, series.az, series.temperature_raw]).astype(np.int16)
    changes = np.rint(_register_changes(model, noise, series, seed)).astype(np.int32)
    registers = np.clip(registers + changes, -32768, 32767).astype(np.int16)
    processed = native.imu_process(
        registers[0], registers[1], registers[2], registers[3], grid.reset, decimation=DECIMATION
    )
    processed.update(
        raw_x=registers[0],
        raw_y=registers[1],
        raw_z=registers[2],
        grid_time_s=grid.time_s,
        incl_x=incl_x,
        incl_y=incl_y,
    )
    return processed


class _NotExcited(Exception):
    """The effect cannot reach the asked size on this channel within its
    parameter's bounds: the inputs hardly excite it there."""


def _scaled(
    candidate: Candidate, model: Model, frames: Measured, channel: str, target_rms: float, sign: float
) -> tuple[float, float]:
    """The parameter value whose replayed effect on the channel has this RMS,
    and that RMS."""
    used = frames.used[channel]
    predict = Replay(frames)
    base = predict(model)[channel][used]
    start = candidate.value(model, channel)
    low, high = candidate.bounds

    def effect_rms(value: float) -> float:
        changed = predict(candidate.changed(model, {channel: value}))[channel][used]
        return gap_rms(channel, changed - base)

    if candidate.additive:
        unit = effect_rms(start + candidate.probe) / candidate.probe
        for direction in (sign, -sign):
            value = start + direction * target_rms / unit if unit > 0 else math.inf
            if low <= value <= high:
                return value, effect_rms(value)
        raise _NotExcited
    # A value of its own (a time constant, a conductance) is moved from the
    # model's (or, for a term the model has off, from its least) towards
    # one bound, the effect growing on the way.
    start = start if model.enabled(candidate.name) else low

    def excess(log_value: float) -> float:
        return effect_rms(math.exp(log_value)) - target_rms

    for end in (high, low) if sign > 0 else (low, high):
        if end == start or effect_rms(end) < target_rms:
            continue
        near, far = math.log(start), math.log(end)
        if excess(near) >= 0.0:
            return start, effect_rms(start)
        # To 2^-33 of the bracket in log value: a relative precision of
        # about 1e-9 or finer on the parameter's value.
        value = math.exp(brentq(excess, near, far, xtol=abs(far - near) / 2**33))
        return value, effect_rms(value)
    raise _NotExcited


def _noise_rms(generated: Measured, model: Model, channel: str) -> float:
    used = generated.used[channel]
    return gap_rms(channel, (generated.observed[channel] - replay(generated, model)[channel])[used])


@dataclass(frozen=True)
class _NullRun:
    """A base run with the noise of its family generated on it and nothing
    hidden: the run hide_effect writes for "none", and what a run with an
    effect is made from (the same seed, so the same noise)."""

    inputs: Measured  # the base run's, as read
    faces: Measured  # the inputs with the inner face their thermistor's reading implies
    model: Model  # the one discovery is given
    noisy_model: Model  # with the noise family's terms
    noise: str
    seed: int
    processed: dict[str, np.ndarray]
    frames: np.ndarray
    noise_c: np.ndarray
    measured: Measured

    @classmethod
    def of(cls, inputs: Measured, model: Model, noise: str, seed: int) -> _NullRun:
        faces = replace(inputs, chamber_c=inner_face_c(inputs.time_s, inputs.chamber_c, model, inputs.status))
        noisy_model = noisy(model, noise)
        processed = _generate(faces, noisy_model, seed, noise)
        frames = np.flatnonzero(processed["frame_due"])
        noise_c = adc_noise_c(faces, processed, frames, model, seed)
        measured = frames_measured(faces, processed, frames, model, noise_c)
        return cls(inputs, faces, model, noisy_model, noise, seed, processed, frames, noise_c, measured)

    def with_effect(self, candidate: Candidate, channel: str, value: float) -> tuple[dict[str, np.ndarray], Measured]:
        """The firmware's processing and the frames of this run with the
        candidate's value on the channel; a chamber effect also changes the
        faces the sensor follows and the chamber's readings."""
        hidden = candidate.changed(self.noisy_model, {channel: value})
        if channel not in CHAMBER_CHANNELS:
            return _generate(self.faces, hidden, self.seed, self.noise), self.measured
        change = ChamberChange.of(self.inputs, self.model, candidate.changed(self.model, {channel: value}))
        measured = frames_measured(self.faces, self.processed, self.frames, self.model, self.noise_c, change)
        faces = replace(self.faces, chamber_c=self.faces.chamber_c + change.face_c)
        return _generate(faces, hidden, self.seed, self.noise), measured


@dataclass(frozen=True)
class _Sizing:
    """Where an effect is hidden and how large: its channel, the
    parameter's value there, and the effect's and the noise's RMS on it."""

    channel: str
    value: float
    effect_rms: float
    noise_rms: float


def _sized(
    candidate: Candidate,
    run: _NullRun,
    channel: str | None,
    snr: float | None,
    rng: np.random.Generator,
    say: Callable[[str], None],
) -> _Sizing:
    """The effect sized to snr times the noise (a drawn SNR when None), in a
    drawn direction, on the channel asked or else on the first, in a drawn
    order, that the inputs excite enough."""
    effect = candidate.name
    generated = run.measured
    choices = [c for c in candidate.channels if c in generated.channels]
    if not choices:
        why = "; ".join(dict.fromkeys(generated.skipped_channels.get(c, f"no {c}") for c in candidate.channels))
        raise DiscoveryDataError(f"{effect} acts on {', '.join(candidate.channels)}: {why}")
    if channel is not None and channel not in choices:
        raise DiscoveryDataError(f"{effect} acts on {', '.join(choices)}, not {channel}")
    order = [channel] if channel else [choices[i] for i in rng.permutation(len(choices))]
    if snr is None:
        snr = float(np.exp(rng.uniform(*np.log(DEFAULT_SNR_RANGE))))
    sign = 1.0 if rng.random() < 0.5 else -1.0
    for option in order:
        noise_rms = _noise_rms(generated, run.model, option)
        say(f"sizing {effect} on {option} for SNR {snr:g}")
        try:
            value, effect_rms = _scaled(candidate, run.model, generated, option, snr * noise_rms, sign)
        except _NotExcited:
            continue
        return _Sizing(option, value, effect_rms, noise_rms)
    raise DiscoveryDataError(
        f"{effect} cannot reach SNR {snr:g} on {', '.join(order)} within its bounds "
        f"{candidate.bounds[0]:g}..{candidate.bounds[1]:g}: these inputs hardly excite it"
    )


def hide_effect(  # noqa: PLR0913 - hide-effect's options, passed by name by the CLI, the benchmark and the tests
    inputs_path: Path,
    out_dir: Path,
    effect: str,
    seed: int,
    snr: float | None = None,
    channel: str | None = None,
    noise: str = "model",
    model: Model | None = None,
    progress: Callable[[str], None] | None = None,
) -> Truth:
    """Write out_dir/run.csv with the effect hidden and out_dir/truth.json."""
    say = progress or (lambda message: None)
    model = Model.load() if model is None else model
    rng = np.random.default_rng(seed)
    if effect == "random":
        effect = CANDIDATES[int(rng.integers(len(CANDIDATES)))].name
    if effect != "none" and effect not in BY_NAME:
        raise DiscoveryDataError(f"unknown effect {effect!r}; choose none, random or one of {', '.join(BY_NAME)}")
    source = _read_inputs(inputs_path)
    say("generating the noise")
    run = _NullRun.of(source.measured, model, noise, seed)
    hidden: dict[str, object] = dict.fromkeys(("channel", "parameter", "value", "model_value", "snr", "effect_rms"))
    if effect == "none":
        noise_rms = _noise_rms(run.measured, model, channel or "X")
        processed, generated = run.processed, run.measured
    else:
        candidate = BY_NAME[effect]
        sizing = _sized(candidate, run, channel, snr, rng, say)
        noise_rms = sizing.noise_rms
        say("generating the run with the effect")
        processed, generated = run.with_effect(candidate, sizing.channel, sizing.value)
        hidden = {
            "channel": sizing.channel,
            "parameter": candidate.parameter,
            "value": sizing.value,
            "model_value": candidate.value(model, sizing.channel),
            "snr": sizing.effect_rms / noise_rms,
            "effect_rms": sizing.effect_rms,
        }
    out_dir.mkdir(parents=True, exist_ok=True)
    _write_run(RunFolder.at(out_dir).log, source, processed, run.frames, generated.chamber_c, generated.outer_c)
    truth = Truth(effect=effect, noise_rms=noise_rms, noise=noise, seed=seed, inputs=str(inputs_path), **hidden)  # type: ignore[arg-type]
    (out_dir / "truth.json").write_text(json.dumps(vars(truth), indent=2) + "\n", encoding="utf-8")
    return truth


def _write_run(
    path: Path,
    inputs: _Inputs,
    processed: Mapping[str, np.ndarray],
    frames: np.ndarray,
    chamber_c: np.ndarray,
    outer_c: np.ndarray,
) -> None:
    """run.csv of the frames: chamber_c and outer_c the generated readings
    (the inner one of the face the sensor saw), the other chamber cells the
    input's (_Inputs.cells)."""
    cells = dict(
        inputs.cells(processed["grid_time_s"][frames], processed["incl_x"][frames], processed["incl_y"][frames])
    )

    def numbers(values: np.ndarray, decimals: int) -> list[str]:
        return format_numbers(values.astype(float).tolist(), decimals)

    def integers(values: np.ndarray) -> list[str]:
        return [str(value) for value in values.astype(np.int64).tolist()]

    cells.update(
        chamber_c=numbers(chamber_c, CHS_DECIMALS),
        outer_c=numbers(outer_c, CHS_DECIMALS),
        imu_temp_c=numbers(processed["temp_c"][frames], 3),
        ax_raw=integers(processed["raw_x"][frames]),
        ay_raw=integers(processed["raw_y"][frames]),
        az_raw=integers(processed["raw_z"][frames]),
        ax_filt=numbers(processed["ax_filt"][frames], 1),
        ay_filt=numbers(processed["ay_filt"][frames], 1),
        az_filt=numbers(processed["az_filt"][frames], 1),
        ax_comp=numbers(processed["ax_comp"][frames], 1),
        ay_comp=numbers(processed["ay_comp"][frames], 1),
        az_comp=numbers(processed["az_comp"][frames], 1),
        comp_set=["C" if value else "W" for value in processed["set"][frames].tolist()],
    )
    with open(path, "w", newline="", encoding="utf-8") as stream:
        RunLogWriter(stream, with_truth=False, flush_each_row=False).write_columns(cells)


def staircase_inputs(  # noqa: PLR0913 - the staircase's shape, set by name by the tests and bench_discovery
    path: Path,
    positions: tuple[tuple[float, float], ...] = ((30.0, 0.0), (-30.0, 0.0), (0.0, 30.0)),
    low_c: float = 0.0,
    high_c: float = 40.0,
    step_c: float = 5.0,
    hold_s: float = 40.0,
    chamber_time_constant_s: float = 8.0,
    ramp_c_per_s: float = 0.3,
    settle_s: float = SETTLE_S,
) -> Path:
    """A run.csv of inputs only (time, chamber temperature, table angles),
    for tests and benchmarks where the twin's minutes per run do not fit: at
    every position a staircase low..high..low in step_c steps held hold_s,
    the inner face following the setpoint at most ramp_c_per_s and through a
    first-order lag, sampled at the IMU's 10 Hz frames."""
    steps_up = int(round((high_c - low_c) / step_c))
    up = [low_c + step_c * k for k in range(1, steps_up + 1)]
    # Each position: settle at the low end, then up and back down.
    segments = [(low_c, settle_s)] + [(level, hold_s) for level in up + up[-2::-1] + [low_c]]
    period_s = DECIMATION * SAMPLE_PERIOD_S
    lag = 1.0 - math.exp(-period_s / chamber_time_constant_s)
    rows = []
    time_s, driven_c, face_c = 0.0, low_c, low_c
    for incl_x, incl_y in positions:
        moved = time_s
        for level, hold in segments:
            duration = abs(level - driven_c) / ramp_c_per_s + hold
            for _ in range(int(round(duration / period_s))):
                driven_c += float(np.clip(level - driven_c, -ramp_c_per_s * period_s, ramp_c_per_s * period_s))
                face_c += (driven_c - face_c) * lag
                rows.append((time_s, level, face_c, incl_x, incl_y, time_s - moved))
                time_s += period_s
    return _write_inputs(path, rows)


def _write_inputs(path: Path, rows: list[tuple[float, float, float, float, float, float]]) -> Path:
    """An inputs-only run.csv of rows (time, setpoint, chamber, incl_x,
    incl_y, since_move)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as stream:
        writer = RunLogWriter(stream, with_truth=False, flush_each_row=False)
        for time_s, setpoint, chamber, incl_x, incl_y, since_move in rows:
            values = {
                "time_s": f"{time_s:.3f}",
                "ambient_c": "22.000",
                "setpoint_c": f"{setpoint:.3f}",
                "chamber_c": f"{chamber:.3f}",
                "incl_x_deg": f"{incl_x:.3f}",
                "incl_y_deg": f"{incl_y:.3f}",
                "since_move_s": f"{since_move:.3f}",
            }
            writer.write_row(values)
    return path


def wave_inputs(
    path: Path,
    middle_c: float = 25.0,
    amplitude_c: float = 10.0,
    period_s: float = 2000.0,
    cycles: float = 1.5,
    settle_s: float = SETTLE_S,
    incl_x_deg: float = 30.0,
) -> Path:
    """A slow temperature wave, middle -/+ amplitude, at one inclination
    (inputs only): its rate changes smoothly, so a lag of the drift
    (sensor_lag, the drift at T - tau dT/dt to first order) and a rate term
    (rate_sensitivity, k dT/dt) differ by about 2 pi tau / period of the
    effect. An effect of a given size needs a tau inversely proportional to
    the amplitude, so a wide wave leaves less of that difference: at 5 degC
    the data told the two apart in 9 runs of 29 at SNR 4 (taus up to
    110 s), at 10 degC in 1 of the 3 runs of those tried."""
    frame_s = DECIMATION * SAMPLE_PERIOD_S
    rows = []
    for index in range(int(round((settle_s + cycles * period_s) / frame_s))):
        time_s = index * frame_s
        phase = 2.0 * math.pi * max(time_s - settle_s, 0.0) / period_s
        chamber_c = middle_c - amplitude_c * math.cos(phase)
        rows.append((time_s, chamber_c, chamber_c, incl_x_deg, 0.0, time_s))
    return _write_inputs(path, rows)
