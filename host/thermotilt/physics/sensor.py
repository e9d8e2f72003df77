"""The sensor integrator: the LSM9DS0 on the tilt table, running the bound
functions of its enabled terms stage by stage (terms.SENSOR_STAGES)."""

from __future__ import annotations

import math
import zlib
from typing import Any, NamedTuple

import numpy as np

from .model import Model
from .terms import SENSOR_STAGES, SensorContext, SensorTerm
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
    drift_set: str
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
    """Seeded draws handed out one at a time from pre-drawn numpy blocks."""

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


class Sensor:
    """The LSM9DS0 accelerometer and temperature sensor on the tilt table."""

    __slots__ = (
        "_temperature_lsb_per_c",
        "_temperature_zero_c",
        "_schmitt_band",
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
        "_trend_set",
        "_trend_extreme",
        "_angles",
        "_acceleration",
        "_mounting",
    )

    def __init__(self, model: Model, seed: int, environment_c: float) -> None:
        constants = model.constants["sensor"]
        self._temperature_lsb_per_c = constants["temperature_lsb_per_c"]
        self._temperature_zero_c = constants["temperature_zero_c"]
        # The warming/cooling choice runs whether or not the drift is on: the
        # sample always says which set the firmware would pick.
        self._schmitt_band = model.terms["drift"]["schmitt_band_c"]

        # Separate streams, so switching dither on or off leaves the noise as it was.
        noise_seed, dither_seed = np.random.SeedSequence(seed).spawn(2)

        def generator(name: str) -> np.random.Generator:
            key = (_TERM_STREAMS, zlib.crc32(name.encode()))
            return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=key))

        context = SensorContext(
            lsb_per_g=constants["lsb_per_g"],
            normal=_BlockDraws(np.random.default_rng(noise_seed).standard_normal).next,
            uniform=_BlockDraws(np.random.default_rng(dither_seed).random).next,
            generator=generator,
        )
        stages: dict[str, list[Any]] = {stage: [] for stage in SENSOR_STAGES}
        for term in model.bound_terms(SensorTerm):
            function = term.bind(context)
            if function is not None:
                stages[term.stage].append(function)
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
        # Like the firmware's TrendDetector: starts warming, as the paper's cycles do.
        self._trend_set = "W"
        self._trend_extreme = self._die_c
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
        drift_set = self._update_trend(die)
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
            drift_x, drift_y, drift_z = self._drift(drift_set, structure, ideal_x, ideal_y, ideal_z)
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
            error_x, error_y, error_z = error(drift_set, reported, rate, dt_s, mounting)
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

    def _update_trend(self, die: float) -> str:
        # Schmitt trigger on the excursion from the running extreme, as the
        # firmware's TrendDetector, so the model's set matches the firmware's
        # choice whenever both see the same temperature.
        if self._trend_set == "W":
            if die > self._trend_extreme:
                self._trend_extreme = die
            elif self._trend_extreme - die > self._schmitt_band:
                self._trend_set = "C"
                self._trend_extreme = die
        else:
            if die < self._trend_extreme:
                self._trend_extreme = die
            elif die - self._trend_extreme > self._schmitt_band:
                self._trend_set = "W"
                self._trend_extreme = die
        return self._trend_set
