"""The LSM9DS0's effects and hardware, each acting on one stage of the
sensor (SENSOR_STAGES). "Paper" is Sensors 2018, 18, 2536."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.signal import lfilter

from ...set_blend import blend
from ...surfaces import AXES, PAPER_DEFAULTS, REFERENCE_C, SETS, CoefficientTable, Surface
from ..parameters import Bounds, Parameter, PerAxis, Surfaces
from . import Section, SensorContext, SensorTerm, hardware, register
from .lag import first_order, first_order_series

INT16_MIN, INT16_MAX = -32768, 32767
INT16_SPAN = INT16_MAX - INT16_MIN + 1
# The LSM9DS0's operating temperature range (datasheet).
OPERATING_C = Bounds(-40.0, 85.0, "degC")

# A drift surface term alone may add at most the int16 span anywhere the
# sensor works: over its operating range and at any int16 reading. p<i><j>
# multiplies T^i a^j.
_SURFACE_TERM_POWERS = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))
SURFACE_TERM_NAMES = tuple(f"p{t}{a}" for t, a in _SURFACE_TERM_POWERS)
_LARGEST_ABS_C = max(-OPERATING_C.low, OPERATING_C.high)
SURFACE_TERM_BOUNDS: tuple[Bounds, ...] = tuple(
    Bounds(-limit, limit)
    for limit in (INT16_SPAN / (_LARGEST_ABS_C**t * float(-INT16_MIN) ** a) for t, a in _SURFACE_TERM_POWERS)
)


@hardware
class SensorHardware(Section):
    name = "sensor"
    summary = "the accelerometer's scale and the temperature output's encoding"
    parameters = (
        Parameter(
            "lsb_per_g",
            Bounds(1000.0, INT16_MAX, "LSB"),
            16393.442622950820,
            "1 / 0.061 mg at ±2 g (LSM9DS0 datasheet; paper section 2)",
            "the LSM9DS0's ±16 g scale gives 1366 LSB/g, ±2 g 16393; an int16 register holds no more than 32767",
        ),
        Parameter(
            "temperature_lsb_per_c",
            Bounds(1.0, 256.0, "LSB"),
            8.0,
            "paper section 2",
            "the LSM9DS0 gives 8; MEMS temperature outputs use 1 to 256 LSB/°C",
        ),
        Parameter(
            "temperature_zero_c",
            OPERATING_C,
            21.0,
            "the firmware decodes raw / 8 + 21 (paper section 2)",
            "the LSM9DS0's operating range: code 0 stands for a temperature the part works at",
        ),
    )


@register
class DieLag(SensorTerm):
    name = "die_lag"
    stage = "die"
    summary = "τ of the die behind the chamber temperature it is given"
    parameters = (
        Parameter(
            "time_constant_s",
            Bounds(0.0, 3600.0, "s", low_exclusive=True),
            15.0,
            "assumed: a 4 × 4 × 1 mm LGA on a breakout inside the chamber",
            "as `[thermistor_lag]`; a packaged sensor inside a closed box lags minutes, not hours",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        return first_order(self.values["time_constant_s"])

    def bind_series(self, context: SensorContext) -> Callable[..., Any] | None:
        return first_order_series(self.values["time_constant_s"]) if self.enabled else None


@register
class Tilt(SensorTerm):
    name = "tilt"
    stage = "gravity"
    summary = "ax = g sin x, ay = g cos x sin y, az = g cos x cos y; disabled: the sensor lies flat"

    def bind(self, context: SensorContext) -> Callable[..., Any] | None:
        g = context.lsb_per_g
        if not self.enabled:
            return lambda incl_x_deg, incl_y_deg: (0.0, 0.0, g)

        def gravity(incl_x_deg: float, incl_y_deg: float) -> tuple[float, float, float]:
            x = math.radians(incl_x_deg)
            y = math.radians(incl_y_deg)
            return g * math.sin(x), g * math.cos(x) * math.sin(y), g * math.cos(x) * math.cos(y)

        return gravity


def coefficient_table_of(value: Any) -> CoefficientTable:
    """The drift term's coefficients parameter ("paper" or a table) as surfaces."""
    if value == "paper":
        return PAPER_DEFAULTS
    return CoefficientTable({(set_, axis): Surface(*value[set_][axis]) for set_ in SETS for axis in AXES})


def _surface(p: tuple[float, ...], temperature_c: float, acceleration: float) -> float:
    # The paper's equation (3), f(T, a), in the firmware's grouping.
    return (
        p[0]
        + temperature_c * (p[1] + p[3] * temperature_c + p[4] * acceleration)
        + acceleration * (p[2] + p[5] * acceleration)
    )


@register
class Drift(SensorTerm):
    name = "drift"
    stage = "drift"
    summary = (
        "f(T, a) per set and axis, warming set W or cooling set C, T the reported temperature "
        "(with `sensor_lag` on, the MEMS structure's lagged copy of it)"
    )
    parameters = (
        Parameter(
            "coefficients",
            Surfaces(SURFACE_TERM_NAMES, SURFACE_TERM_BOUNDS),
            "paper",
            "paper Tables 2 and 3; Z zero",
            "each term alone may add at most the int16 span (65536 LSB) anywhere the sensor "
            "works: −40…85 °C and any int16 reading, i.e. 65536 / (85^i · 32768^j) for p_ij",
        ),
        Parameter(
            "schmitt_band_c",
            Bounds(0.0, 10.0, "degC"),
            0.5,
            "as the firmware's TrendDetector",
            "the firmware uses 0.5; a band wider than the paper's ±6 °C field swings would never switch",
        ),
        Parameter(
            "set_transition_c",
            Bounds(0.05, 20.0, "degC"),
            1.5,
            "assumed: after a reversal the sensor moves from one set's surfaces and measuring "
            "offset to the other's linearly over this much die temperature, as the stress of an "
            "elastic–perfectly-plastic die attach (Prandtl's stop operator: Krasnosel'skii and "
            "Pokrovskii, Systems with Hysteresis, 1989); less than the calibration's 2 °C step "
            "(paper section 3.2), after which the paper's plateaus show each set whole",
            "20 °C is a third of the paper's −10…45 °C cycle; wider, the sets would never be seen whole",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        table = coefficient_table_of(self.values["coefficients"])
        surfaces = {set_: tuple(tuple(table.surface(set_, axis)) for axis in AXES) for set_ in SETS}

        def drift(
            drift_set: str, temperature_c: float, ideal_x: float, ideal_y: float, ideal_z: float
        ) -> tuple[float, float, float]:
            surface_x, surface_y, surface_z = surfaces[drift_set]
            return (
                _surface(surface_x, temperature_c, ideal_x),
                _surface(surface_y, temperature_c, ideal_y),
                _surface(surface_z, temperature_c, ideal_z),
            )

        return drift


@register
class RateSensitivity(SensorTerm):
    name = "rate_sensitivity"
    stage = "error"
    summary = "k·(dT_die/dt) per axis"
    parameters = (
        Parameter(
            "lsb_per_c_per_s",
            PerAxis(Bounds(-INT16_SPAN, INT16_SPAN, "LSB per degC/s")),
            {"x": 0.0, "y": 0.0, "z": 1200.0},
            "tuned: ~110 LSB peaks in 2 °C/60 s staircase steps and ~47 LSB RMS over a "
            "−10…45 °C cycle, the order of the Z fits' RMS errors (paper section 4.1, "
            "Tables 4, 5: 34–87 LSB)",
            "at 1 °C/s, faster than the chamber moves, more would swing the whole int16 span",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        gains = self.values["lsb_per_c_per_s"]
        gain_x, gain_y, gain_z = gains["x"], gains["y"], gains["z"]

        def error(
            warming_share: float, reported_c: float, rate: float, dt_s: float, mounting: int
        ) -> tuple[float, float, float]:
            return gain_x * rate, gain_y * rate, gain_z * rate

        return error


@register
class TemperatureOffset(SensorTerm):
    name = "temperature_offset"
    stage = "reported"
    summary = "reported = die + offset"
    parameters = (
        Parameter(
            "offset_c",
            Bounds(-20.0, 20.0, "degC"),
            -1.0,
            "assumed: the paper reports a consistent negative offset (section 3.1) without a value",
            "an uncalibrated die sensor; the paper saw about −1 °C",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        offset_c = self.values["offset_c"]
        return lambda die_c: die_c + offset_c


@register
class TemperatureQuantisation(SensorTerm):
    name = "temperature_quantisation"
    stage = "register"
    summary = (
        "1/8 °C register steps; disabled: the last bit is dithered so averages carry no "
        "staircase (a register is an integer either way)"
    )

    def bind(self, context: SensorContext) -> Callable[..., Any] | None:
        if self.enabled:
            return None
        uniform = context.uniform
        # Each code is picked with a probability that keeps its mean at the
        # continuous value.
        return lambda temperature_lsb: temperature_lsb + (uniform() - 0.5)

    def bind_series(self, context: SensorContext) -> Callable[..., Any] | None:
        if self.enabled:
            return None
        uniforms = context.uniforms
        return lambda temperature_lsb: temperature_lsb + (uniforms(len(temperature_lsb)) - 0.5)


@register
class SensitivityLoss(SensorTerm):
    name = "sensitivity_loss"
    stage = "ideal"
    summary = "a → a (1 − k (a/g)²)"
    parameters = (
        Parameter(
            "gain_loss_at_1g",
            Bounds(0.0, 0.33),
            0.01,
            "assumed: paper section 4.1 notes shrinking line spacing at high inclination without a number",
            "a (1 − k a²) must still grow up to 1 g, which needs k < 1/3",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        g = context.lsb_per_g
        loss = self.values["gain_loss_at_1g"]

        def ideal(ax: float, ay: float, az: float) -> tuple[float, float, float]:
            return (
                ax * (1.0 - loss * (ax / g) ** 2),
                ay * (1.0 - loss * (ay / g) ** 2),
                az * (1.0 - loss * (az / g) ** 2),
            )

        return ideal


@register
class Noise(SensorTerm):
    name = "noise"
    stage = "error"
    summary = "Gaussian, per axis, seeded (numpy.random.Generator, blocks of 4096 pre-drawn)"
    parameters = (
        Parameter(
            "sigma_lsb",
            PerAxis(Bounds(0.0, 1000.0, "LSB")),
            {"x": 17.4, "y": 17.4, "z": 17.4},
            "150 µg/√Hz (LSM9DS0 datasheet, ±2 g) over the 50 Hz anti-alias bandwidth = 1.06 mg = 17.4 LSB",
            "57 times the datasheet's 17.4 LSB; more is a unit slip (mg or µg/√Hz)",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        sigmas = self.values["sigma_lsb"]
        sigma_x, sigma_y, sigma_z = sigmas["x"], sigmas["y"], sigmas["z"]
        draw = context.normal

        def error(
            warming_share: float, reported_c: float, rate: float, dt_s: float, mounting: int
        ) -> tuple[float, float, float]:
            return sigma_x * draw(), sigma_y * draw(), sigma_z * draw()

        return error

    def bind_series(self, context: SensorContext) -> Callable[..., Any] | None:
        if not self.enabled:
            return None
        sigmas = self.values["sigma_lsb"]
        sigma = np.array([sigmas["x"], sigmas["y"], sigmas["z"]])
        normals = context.normals

        def error(
            warming_share: np.ndarray, reported_c: np.ndarray, rate: np.ndarray, dt_s: np.ndarray, mounting: int
        ) -> np.ndarray:
            # x, y, z per step, the order the scalar form draws them in.
            return sigma[:, None] * normals(3 * len(dt_s)).reshape(-1, 3).T

        return error


# An offset larger than ±2 g would hold a level sensor's ±2 g register at
# one of its ends.
OFFSET_BOUNDS = PerAxis(Bounds(-INT16_SPAN / 2, INT16_SPAN / 2, "LSB"))
OFFSET_WHY = "±2 g at the ±2 g scale: a larger offset would hold a level sensor's register at one of its ends"


@register
class MeasuringOffset(SensorTerm):
    name = "measuring_offset"
    stage = "error"
    summary = (
        "a constant offset of the reading per axis, one while warming (W), one while cooling "
        "(C), and between them after a reversal as far as the sensor's warming share "
        "(`[drift] set_transition_c`); the paper's drift surfaces do not remove it"
    )
    parameters = (
        Parameter(
            "warming_lsb",
            OFFSET_BOUNDS,
            {"x": -1823.0, "y": -143.0, "z": 0.0},
            "paper section 4.1: the shift of Figure 10's lines, X −1823 and Y −143 LSB while warming; Z none given",
            OFFSET_WHY,
        ),
        Parameter(
            "cooling_lsb",
            OFFSET_BOUNDS,
            {"x": -1857.0, "y": -110.0, "z": 0.0},
            "paper section 4.1: X −1857 and Y −110 LSB while cooling; Z none given",
            OFFSET_WHY,
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        warming_x, warming_y, warming_z = (self.values["warming_lsb"][axis] for axis in "xyz")
        cooling_x, cooling_y, cooling_z = (self.values["cooling_lsb"][axis] for axis in "xyz")

        def error(
            warming_share: float, reported_c: float, rate: float, dt_s: float, mounting: int
        ) -> tuple[float, float, float]:
            return (
                blend(warming_share, warming_x, cooling_x),
                blend(warming_share, warming_y, cooling_y),
                blend(warming_share, warming_z, cooling_z),
            )

        return error


@register
class DriftRepeatability(SensorTerm):
    name = "drift_repeatability"
    stage = "error"
    summary = (
        "per mounting (a run; in a campaign run every table position) the drift's slope in "
        "temperature differs by δ ~ N(0, σ) per axis, adding δ·(T − 25 °C), T the reported "
        "temperature; seeded, a new δ at every table move"
    )
    parameters = (
        Parameter(
            "sigma_lsb_per_c",
            PerAxis(Bounds(0.0, 100.0, "LSB per degC")),
            {"x": 0.55, "y": 0.8, "z": 0.0},
            "paper Tables 2, 3: the quadratic mean of each axis's two RMS errors (X 6.26, "
            "12.32; Y 17.37, 10.03 LSB) over the RMS of T − 25 °C across the −10…45 °C "
            "staircase (18.1 °C) and √(1 − 2/37) (the fit takes up the slope's mean and its "
            "trend in a over 37 positions); Z none given",
            "100 LSB/°C (6.1 mg/°C) is five times the paper's whole X drift slope (20 LSB/°C); "
            "more is a unit slip (mg for LSB)",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        sigmas = self.values["sigma_lsb_per_c"]
        scale = np.array([sigmas["x"], sigmas["y"], sigmas["z"]])
        rng = context.generator(self.name)
        drawn = -1
        slope_x = slope_y = slope_z = 0.0

        def error(
            warming_share: float, reported_c: float, rate: float, dt_s: float, mounting: int
        ) -> tuple[float, float, float]:
            nonlocal drawn, slope_x, slope_y, slope_z
            # Mounting k always takes the k-th draw, however many were skipped.
            while drawn < mounting:
                slope_x, slope_y, slope_z = (scale * rng.standard_normal(3)).tolist()
                drawn += 1
            excursion = reported_c - REFERENCE_C
            return slope_x * excursion, slope_y * excursion, slope_z * excursion

        return error


# Flicker noise as a sum of first-order Gauss-Markov processes, one per
# decade of time constant. Their one-sided spectrum is s^2 / (f ln r) between
# the shortest and longest (s^2 each process's variance, r the spacing), and
# the Allan variance of h/f noise is 2 ln 2 h: so s^2 = floor^2 ln r / (2 ln 2).
# 1 s to 10^5 s (28 h) spans every scenario; below 1 s the white noise rules.
FLICKER_TIME_CONSTANTS_S = tuple(10.0**k for k in range(6))
_FLICKER_SPACING = 10.0
FLICKER_VARIANCE_PER_FLOOR = math.log(_FLICKER_SPACING) / (2.0 * math.log(2.0))
_FLICKER_BLOCK_STEPS = 4096


class _FlickerBlocks:
    """The three axes' flicker, one step at a time, made in numpy blocks for
    a step length; a new length continues from the state reached."""

    __slots__ = ("_rng", "_sigma", "_taus", "_state", "_processes", "_block", "_sums", "_index", "_dt_s")

    def __init__(self, floors: np.ndarray, rng: np.random.Generator) -> None:
        self._rng = rng
        self._sigma = floors * math.sqrt(FLICKER_VARIANCE_PER_FLOOR)
        self._taus = np.array(FLICKER_TIME_CONSTANTS_S)
        # Stationary from the first step: a run starts mid-life, not at a zero bias.
        self._state = rng.standard_normal((3, len(self._taus))) * self._sigma[:, None]
        self._processes: list[np.ndarray] = []
        self._block = np.empty((3, 0))
        # The block as per-step tuples, made when next() first needs them:
        # take() copies from the block, and a 4096-step list costs more
        # than its draws.
        self._sums: list[tuple[float, float, float]] | None = None
        self._index = 0
        self._dt_s = -1.0

    def next(self, dt_s: float) -> tuple[float, float, float]:
        if dt_s != self._dt_s or self._index == self._block.shape[1]:
            self._refill(dt_s)
        if self._sums is None:
            self._sums = list(zip(*self._block.tolist()))
        value = self._sums[self._index]
        self._index += 1
        return value

    def take(self, dt_s: np.ndarray) -> np.ndarray:
        """The next len(dt_s) steps at once (3 x steps), as next() would give them."""
        values = np.empty((3, len(dt_s)))
        step = 0
        while step < len(dt_s):
            length = float(dt_s[step])
            if length != self._dt_s or self._index == self._block.shape[1]:
                self._refill(length)
            window = dt_s[step : step + self._block.shape[1] - self._index]
            other = np.flatnonzero(window != length)
            count = int(other[0]) if len(other) else len(window)
            values[:, step : step + count] = self._block[:, self._index : self._index + count]
            self._index += count
            step += count
        return values

    def _refill(self, dt_s: float) -> None:
        if self._index:
            self._state = np.stack([p[:, self._index - 1] for p in self._processes], axis=1)
        shocks = self._rng.standard_normal((len(self._taus), 3, _FLICKER_BLOCK_STEPS))
        processes = []
        for k, tau in enumerate(self._taus):
            phi = math.exp(-dt_s / tau)
            gain = self._sigma * math.sqrt(-math.expm1(-2.0 * dt_s / tau))
            initial = (phi * self._state[:, k])[:, None]
            values, _ = lfilter([1.0], [1.0, -phi], shocks[k] * gain[:, None], axis=-1, zi=initial)
            processes.append(values)
        self._processes = processes
        self._block = np.sum(processes, axis=0)
        self._sums = None
        self._index = 0
        self._dt_s = dt_s


@register
class BiasInstability(SensorTerm):
    name = "bias_instability"
    stage = "error"
    summary = (
        "flicker (1/f) noise of the zero-g level per axis: one first-order Gauss–Markov "
        "process per decade of time constant, 1 s … 10⁵ s, whose Allan deviation is flat "
        "at the floor; seeded, stationary from the start"
    )
    parameters = (
        Parameter(
            "allan_floor_lsb",
            PerAxis(Bounds(0.0, 1000.0, "LSB")),
            {"x": 0.82, "y": 0.82, "z": 0.82},
            "assumed: 0.05 mg (0.664 × the IEEE 952 bias instability), the order of consumer "
            "MEMS accelerometers' Allan floors; the LSM9DS0 datasheet gives none",
            "as `[noise] sigma_lsb`: far beyond any MEMS accelerometer's floor",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        floors = self.values["allan_floor_lsb"]
        blocks = _FlickerBlocks(np.array([floors["x"], floors["y"], floors["z"]]), context.generator(self.name))
        step = blocks.next

        def error(
            warming_share: float, reported_c: float, rate: float, dt_s: float, mounting: int
        ) -> tuple[float, float, float]:
            return step(dt_s)

        return error

    def bind_series(self, context: SensorContext) -> Callable[..., Any] | None:
        if not self.enabled:
            return None
        floors = self.values["allan_floor_lsb"]
        blocks = _FlickerBlocks(np.array([floors["x"], floors["y"], floors["z"]]), context.generator(self.name))

        def error(
            warming_share: np.ndarray, reported_c: np.ndarray, rate: np.ndarray, dt_s: np.ndarray, mounting: int
        ) -> np.ndarray:
            return blocks.take(dt_s)

        return error
