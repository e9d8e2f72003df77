"""The sensor integrator: the LSM9DS0 on the tilt table, running the bound
functions of its enabled terms stage by stage (terms.SENSOR_STAGES)."""

from __future__ import annotations

import math
import zlib
from typing import Any, NamedTuple

import numpy as np

from ..set_blend import SetBlend, blend, warming_shares
from .model import Model
from .terms import SENSOR_STAGES, SensorContext, SensorTerm
from .terms.lag import SeriesMemo
from .terms.sensor import INT16_MAX, INT16_MIN

# The LSM9DS0 temperature output is 12-bit two's complement.
_TEMPERATURE_RAW_MIN, _TEMPERATURE_RAW_MAX = -2048, 2047
_NOISE_BLOCK_SAMPLES = 4096
# The spawn key of the terms' own streams (noise and dither are 0 and 1).
_TERM_STREAMS = 2


class SensorSample(NamedTuple):
    """One LSM9DS0 sample: register contents and the model's intermediate values.
    A named tuple: made every 10 ms step, it costs a fifth of a frozen dataclass."""

    ax: int
    ay: int
    az: int
    temperature_raw: int
    die_c: float
    reported_c: float
    rate_c_per_s: float
    # The set the firmware's trend rule would pick on the die temperature.
    drift_set: str
    # How far the sensor itself is in its warming set (set_blend): 1 its
    # warming surfaces and offset, 0 its cooling ones.
    warming_share: float
    ideal_ax: float
    ideal_ay: float
    ideal_az: float
    drift_x: float
    drift_y: float
    drift_z: float
    # The table position's index, a new mounting at every move.
    mounting: int
    # The acceleration the registers were rounded from: ideal + drift + every
    # additive error, before clipping and rounding.
    unrounded_ax: float
    unrounded_ay: float
    unrounded_az: float
    # The temperature the drift surfaces were evaluated at: the reported one,
    # or the MEMS structure's lagged copy of it when sensor_lag is on.
    drift_temperature_c: float


def _clip_round(value: float, low: int, high: int) -> int:
    rounded = math.floor(value + 0.5)
    return low if rounded < low else high if rounded > high else rounded


def registered_temperature_c(model: Model, reported_c: np.ndarray) -> np.ndarray:
    """What the temperature register holds for these reported temperatures,
    in degC as the firmware decodes it: rounded to its 1/8 degC steps as
    Sensor.step rounds it, where the model's `temperature_quantisation` is
    on; as given where it is off (the register's dither averages away)."""
    if not model.enabled("temperature_quantisation"):
        return reported_c
    constants = model.constants["sensor"]
    lsb_per_c, zero_c = constants["temperature_lsb_per_c"], constants["temperature_zero_c"]
    raw = np.clip(np.floor((reported_c - zero_c) * lsb_per_c + 0.5), _TEMPERATURE_RAW_MIN, _TEMPERATURE_RAW_MAX)
    return raw / lsb_per_c + zero_c


class _BlockDraws:
    """Seeded draws handed out one at a time from pre-drawn numpy blocks, or
    n at a time from the same stream."""

    __slots__ = ("_draw", "_values", "_index")

    def __init__(self, draw: Any) -> None:
        self._draw = draw
        self._values: list[float] = []
        self._index = 0

    def next(self) -> float:
        if self._index == len(self._values):
            self._values = self._draw(_NOISE_BLOCK_SAMPLES).tolist()
            self._index = 0
        value = self._values[self._index]
        self._index += 1
        return value

    def take(self, count: int) -> np.ndarray:
        # A generator's draws are one stream however they are chunked.
        held = self._values[self._index : self._index + count]
        self._index += len(held)
        if len(held) == count:
            return np.array(held)
        return np.concatenate([held, self._draw(count - len(held))])


def _stages(model: Model, seed: int, series: bool) -> dict[str, list[Any]]:
    """Each stage's functions of the model's enabled terms, in order: the
    scalar ones a Sensor steps, or their series forms."""
    constants = model.constants["sensor"]
    # Separate streams, so switching dither on or off leaves the noise as it was.
    noise_seed, dither_seed = np.random.SeedSequence(seed).spawn(2)

    def generator(name: str) -> np.random.Generator:
        key = (_TERM_STREAMS, zlib.crc32(name.encode()))
        return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))

    normal = _BlockDraws(np.random.default_rng(noise_seed).standard_normal)
    uniform = _BlockDraws(np.random.default_rng(dither_seed).random)
    context = SensorContext(
        lsb_per_g=constants["lsb_per_g"],
        normal=normal.next,
        uniform=uniform.next,
        normals=normal.take,
        uniforms=uniform.take,
        generator=generator,
    )
    stages: dict[str, list[Any]] = {stage: [] for stage in SENSOR_STAGES}
    for term in model.bound_terms(SensorTerm):
        function = term.bind_series(context) if series else term.bind(context)
        if function is not None:
            stages[term.stage].append(function)
    return stages


class Trend:
    """Which drift set applies: a Schmitt trigger on the die temperature's
    excursion from its running extreme, as the firmware's TrendDetector, so
    the model's set matches the firmware's choice whenever both see the
    same temperature. Starts warming, as the paper's cycles do."""

    __slots__ = ("_band_c", "drift_set", "extreme_c")

    def __init__(self, band_c: float, start_c: float) -> None:
        self._band_c = band_c
        self.drift_set = "W"
        self.extreme_c = start_c

    def update(self, die: float) -> str:
        if self.drift_set == "W":
            if die > self.extreme_c:
                self.extreme_c = die
            elif self.extreme_c - die > self._band_c:
                self.drift_set = "C"
                self.extreme_c = die
        else:
            if die < self.extreme_c:
                self.extreme_c = die
            elif die - self.extreme_c > self._band_c:
                self.drift_set = "W"
                self.extreme_c = die
        return self.drift_set


def drift_sets(band_c: float, start_c: float, die_c: np.ndarray) -> np.ndarray:
    """Trend(band_c, start_c) updated with each die temperature in turn, as
    an array of set letters: between two changes of set the extreme is the
    running maximum (warming) or minimum (cooling), so each stretch is
    found at once. The same comparisons of the same floats as Trend.update
    (test_physics: drift sets)."""
    sets = np.empty(len(die_c), dtype="<U1")
    drift_set, extreme, index = "W", float(start_c), 0
    while index < len(die_c):
        rest = die_c[index:]
        running = (np.fmax if drift_set == "W" else np.fmin).accumulate(np.concatenate([[extreme], rest]))[:-1]
        if drift_set == "W":
            change = np.flatnonzero(~(rest > running) & (running - rest > band_c))
        else:
            change = np.flatnonzero(~(rest < running) & (rest - running > band_c))
        if not len(change):
            sets[index:] = drift_set
            break
        first = int(change[0])
        sets[index : index + first] = drift_set
        drift_set, extreme = ("C" if drift_set == "W" else "W"), float(rest[first])
        sets[index + first] = drift_set
        index += first + 1
    return sets


class Sensor:
    """The LSM9DS0 accelerometer and temperature sensor on the tilt table."""

    __slots__ = (
        "_temperature_lsb_per_c",
        "_temperature_zero_c",
        "_die",
        "_reported",
        "_structure",
        "_gravity",
        "_ideal",
        "_drift",
        "_scale",
        "_errors",
        "_register",
        "_die_c",
        "_structure_c",
        "_trend",
        "_set_state",
        "_angles",
        "_acceleration",
        "_mounting",
    )

    def __init__(self, model: Model, seed: int, environment_c: float, warming_share: float = 1.0) -> None:
        """warming_share: the sensor's set state at the start (set_blend),
        where its history put it: 1 warming, as the paper's cycles start, 0
        after hours of cooling."""
        constants = model.constants["sensor"]
        self._temperature_lsb_per_c = constants["temperature_lsb_per_c"]
        self._temperature_zero_c = constants["temperature_zero_c"]
        stages = _stages(model, seed, series=False)
        self._die = tuple(stages["die"])
        self._reported = tuple(stages["reported"])
        self._structure = tuple(stages["structure"])
        (self._gravity,) = stages["gravity"]
        self._ideal = tuple(stages["ideal"])
        self._drift = stages["drift"][0] if stages["drift"] else None
        self._scale = tuple(stages["scale"])
        self._errors = tuple(stages["error"])
        self._register = tuple(stages["register"])

        self._die_c = float(environment_c)
        # The MEMS structure starts at the temperature the sensor then
        # reports, as the die starts at the environment's.
        structure = self._die_c
        for offset in self._reported:
            structure = offset(structure)
        self._structure_c = structure
        # The warming/cooling choice runs whether or not the drift is on: the
        # sample always says which set the firmware would pick.
        self._trend = Trend(model.terms["drift"]["schmitt_band_c"], self._die_c)
        self._set_state = SetBlend(model.terms["drift"]["set_transition_c"], warming_share)
        self._angles: tuple[float, float] | None = None
        self._acceleration = (0.0, 0.0, 0.0)
        # A table move is a new mounting of the sensor; the first position is 0.
        self._mounting = -1

    def step(self, dt_s: float, environment_c: float, incl_x_deg: float, incl_y_deg: float) -> SensorSample:
        """Advance dt_s and return the sample the registers then hold."""
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        previous_die = self._die_c
        die = float(environment_c)
        for lag in self._die:
            die = lag(previous_die, die, dt_s)
        self._die_c = die
        rate = (die - previous_die) / dt_s
        drift_set = self._trend.update(die)
        warming_share = self._set_state.update(die - previous_die)
        reported = die
        for offset in self._reported:
            reported = offset(reported)
        if self._structure:
            previous_structure = self._structure_c
            structure = reported
            for lag in self._structure:
                structure = lag(previous_structure, structure, dt_s)
            self._structure_c = structure
        else:
            structure = reported

        if self._angles != (incl_x_deg, incl_y_deg):
            self._angles = (incl_x_deg, incl_y_deg)
            self._mounting += 1
            acceleration = self._gravity(incl_x_deg, incl_y_deg)
            for modify in self._ideal:
                acceleration = modify(*acceleration)
            self._acceleration = acceleration
        ideal_x, ideal_y, ideal_z = self._acceleration

        if self._drift is not None:
            drift_x, drift_y, drift_z = self._drift_at(warming_share, structure, ideal_x, ideal_y, ideal_z)
            raw_x, raw_y, raw_z = ideal_x + drift_x, ideal_y + drift_y, ideal_z + drift_z
        else:
            drift_x = drift_y = drift_z = 0.0
            raw_x, raw_y, raw_z = ideal_x, ideal_y, ideal_z
        for scale in self._scale:
            error_x, error_y, error_z = scale(reported, ideal_x, ideal_y, ideal_z)
            raw_x += error_x
            raw_y += error_y
            raw_z += error_z
        mounting = self._mounting
        for error in self._errors:
            error_x, error_y, error_z = error(warming_share, reported, rate, dt_s, mounting)
            raw_x += error_x
            raw_y += error_y
            raw_z += error_z

        temperature_lsb = (reported - self._temperature_zero_c) * self._temperature_lsb_per_c
        for register in self._register:
            temperature_lsb = register(temperature_lsb)

        # In SensorSample's field order: 19 keywords would cost 0.65 µs a step.
        return SensorSample(
            _clip_round(raw_x, INT16_MIN, INT16_MAX),
            _clip_round(raw_y, INT16_MIN, INT16_MAX),
            _clip_round(raw_z, INT16_MIN, INT16_MAX),
            _clip_round(temperature_lsb, _TEMPERATURE_RAW_MIN, _TEMPERATURE_RAW_MAX),
            die,
            reported,
            rate,
            drift_set,
            warming_share,
            ideal_x,
            ideal_y,
            ideal_z,
            drift_x,
            drift_y,
            drift_z,
            mounting,
            raw_x,
            raw_y,
            raw_z,
            structure,
        )

    def _drift_at(
        self, warming_share: float, temperature_c: float, ideal_x: float, ideal_y: float, ideal_z: float
    ) -> tuple[float, float, float]:
        if warming_share == 1.0:
            return self._drift("W", temperature_c, ideal_x, ideal_y, ideal_z)
        if warming_share == 0.0:
            return self._drift("C", temperature_c, ideal_x, ideal_y, ideal_z)
        warming_x, warming_y, warming_z = self._drift("W", temperature_c, ideal_x, ideal_y, ideal_z)
        cooling_x, cooling_y, cooling_z = self._drift("C", temperature_c, ideal_x, ideal_y, ideal_z)
        return (
            blend(warming_share, warming_x, cooling_x),
            blend(warming_share, warming_y, cooling_y),
            blend(warming_share, warming_z, cooling_z),
        )


class SensorSeries(NamedTuple):
    """SensorSample's fields over a series of steps, one array each."""

    ax: np.ndarray
    ay: np.ndarray
    az: np.ndarray
    temperature_raw: np.ndarray
    die_c: np.ndarray
    reported_c: np.ndarray
    rate_c_per_s: np.ndarray
    drift_set: np.ndarray
    warming_share: np.ndarray
    ideal_ax: np.ndarray
    ideal_ay: np.ndarray
    ideal_az: np.ndarray
    drift_x: np.ndarray
    drift_y: np.ndarray
    drift_z: np.ndarray
    mounting: np.ndarray
    unrounded_ax: np.ndarray
    unrounded_ay: np.ndarray
    unrounded_az: np.ndarray
    drift_temperature_c: np.ndarray


def _lagged(lags: list[Any], start: float, targets: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """A lag stage's series: each of its terms steps from the same previous
    value in Sensor.step, which one series form cannot chain, so a stage
    has at most one (every registered lag stands alone in its stage)."""
    if len(lags) > 1:
        raise ValueError(f"sensor_series takes at most one lag per stage, not {len(lags)}")
    return lags[0](start, targets, dt_s) if lags else targets


def _clip_round_array(values: np.ndarray, low: int, high: int) -> np.ndarray:
    return np.clip(np.floor(values + 0.5), low, high).astype(np.int64)


def sensor_series(  # noqa: PLR0913 - Sensor's arguments and the steps' inputs, each by name
    model: Model,
    seed: int,
    start_c: float,
    dt_s: np.ndarray,
    environment_c: np.ndarray,
    incl_x_deg: np.ndarray,
    incl_y_deg: np.ndarray,
    warming_share: float = 1.0,
) -> SensorSeries:
    """Sensor(model, seed, start_c, warming_share) stepped through every (dt_s,
    environment_c, incl_x_deg, incl_y_deg), as arrays: the same samples as
    the steps (test_sensor_series), each stage run on whole arrays but the
    lags and the trend, which go step by step."""
    dt_s, environment_c = np.asarray(dt_s, dtype=float), np.asarray(environment_c, dtype=float)
    incl_x_deg, incl_y_deg = np.asarray(incl_x_deg, dtype=float), np.asarray(incl_y_deg, dtype=float)
    if not np.all(dt_s > 0.0):
        raise ValueError(f"dt_s must be > 0, got {dt_s[~(dt_s > 0.0)][0]}")
    constants = model.constants["sensor"]
    stages = _stages(model, seed, series=True)

    die = _lagged(stages["die"], float(start_c), environment_c, dt_s)
    rate = np.diff(die, prepend=float(start_c)) / dt_s
    drift_set, shares = _set_series(model, float(start_c), die, warming_share)
    reported, structure_start = die, float(start_c)
    for offset in stages["reported"]:
        reported = offset(reported)
        structure_start = offset(structure_start)
    structure = _lagged(stages["structure"], structure_start, reported, dt_s)

    moved = np.ones(len(dt_s), dtype=bool)
    moved[1:] = (incl_x_deg[1:] != incl_x_deg[:-1]) | (incl_y_deg[1:] != incl_y_deg[:-1])
    mounting = np.cumsum(moved) - 1
    ideal = _ideal_series(stages, incl_x_deg, incl_y_deg, moved, mounting)
    drift = _drift_series(stages, shares, structure, ideal)
    raw = _raw_series(stages, _mountings(moved), ideal, drift, (shares, reported, rate, dt_s))

    temperature_lsb = (reported - constants["temperature_zero_c"]) * constants["temperature_lsb_per_c"]
    for register in stages["register"]:
        temperature_lsb = register(temperature_lsb)
    ax, ay, az = (_clip_round_array(values, INT16_MIN, INT16_MAX) for values in raw)
    return SensorSeries(
        ax,
        ay,
        az,
        _clip_round_array(temperature_lsb, _TEMPERATURE_RAW_MIN, _TEMPERATURE_RAW_MAX),
        die,
        reported,
        rate,
        drift_set,
        shares,
        *ideal,
        *drift,
        mounting,
        *raw,
        structure,
    )


# A search replays many models on one die: few candidates change it.
_SET_SERIES = SeriesMemo(32 * 2**20)


def _set_series(model: Model, start_c: float, die: np.ndarray, warming_share: float) -> tuple[np.ndarray, np.ndarray]:
    """The die's drift sets and warming shares (read only), kept for the
    same die and drift parameters: they go step by step."""
    band_c, transition_c = model.terms["drift"]["schmitt_band_c"], model.terms["drift"]["set_transition_c"]
    return _SET_SERIES.get(
        (band_c, transition_c, start_c, warming_share, die),
        lambda: (drift_sets(band_c, start_c, die), warming_shares(transition_c, start_c, die, warming_share)),
    )


def _ideal_series(
    stages: dict[str, list[Any]],
    incl_x_deg: np.ndarray,
    incl_y_deg: np.ndarray,
    moved: np.ndarray,
    mounting: np.ndarray,
) -> np.ndarray:
    """The ideal acceleration of every step, x, y and z by rows, worked out
    once per mounting, at the step that moved the table there."""
    (gravity,) = stages["gravity"]
    accelerations = []
    for first in np.flatnonzero(moved).tolist():
        acceleration = gravity(float(incl_x_deg[first]), float(incl_y_deg[first]))
        for modify in stages["ideal"]:
            acceleration = modify(*acceleration)
        accelerations.append(acceleration)
    return np.array(accelerations, dtype=float).reshape(-1, 3)[mounting].T


# Steps on one mounting: which steps, the mounting. The per-mounting terms
# take them whole.
_Mounting = tuple[slice, int]


def _mountings(moved: np.ndarray) -> list[_Mounting]:
    starts = np.flatnonzero(moved)
    return [
        (slice(start, end), index)
        for index, (start, end) in enumerate(zip(starts.tolist(), [*starts[1:].tolist(), len(moved)]))
    ]


def _drift_series(
    stages: dict[str, list[Any]],
    warming_share: np.ndarray,
    structure: np.ndarray,
    ideal: np.ndarray,
) -> np.ndarray:
    """The drift of every step, x, y and z by rows; zero with the drift off.
    Both sets' drift blended as Sensor._drift_at blends it, which at a share
    of 1 or 0 is exactly that set's."""
    if not stages["drift"]:
        return np.zeros(ideal.shape)
    (surfaces,) = stages["drift"]
    arguments = (structure, *ideal)
    return blend(warming_share, np.array(surfaces("W", *arguments)), np.array(surfaces("C", *arguments)))


def _raw_series(
    stages: dict[str, list[Any]],
    mountings: list[_Mounting],
    ideal: np.ndarray,
    drift: np.ndarray,
    conditions: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> np.ndarray:
    """The acceleration the registers are rounded from: ideal, drift and
    every additive error, x, y and z by rows, summed in Sensor.step's order
    so that every sum is the same float. conditions: each step's warming
    share, reported temperature, rate and dt_s."""
    warming_share, reported, rate, dt_s = conditions
    ideal_x, ideal_y, ideal_z = ideal
    raw = np.stack([ideal_x, ideal_y, ideal_z]) + drift
    for scale in stages["scale"]:
        raw += np.stack(np.broadcast_arrays(*scale(reported, ideal_x, ideal_y, ideal_z)))
    for part, mounting_here in mountings:
        for error in stages["error"]:
            error_x, error_y, error_z = error(
                warming_share[part], reported[part], rate[part], dt_s[part], mounting_here
            )
            raw[0, part] += error_x
            raw[1, part] += error_y
            raw[2, part] += error_z
    return raw
