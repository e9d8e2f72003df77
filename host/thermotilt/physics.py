"""The twin's physics: the thermal chamber, the tilt table and the LSM9DS0.

One model, loaded from a TOML file (``models/default.toml`` by default), in
which every physical effect is a named term that can be switched off. The
twin steps :class:`Chamber` and :class:`Sensor` every 10 ms of simulated time,
so the step methods use plain float arithmetic; numpy only pre-draws noise.
docs/physics-model.md explains each term and where its numbers come from.
"""

from __future__ import annotations

import math
import re
import reprlib
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from .coefficients import AXES, PAPER_DEFAULTS, SETS, CoefficientTable, Surface


class ModelError(ValueError):
    """A model file, term switch or fault that cannot be used."""


TERMS: tuple[str, ...] = (
    "peltier_pumping",
    "joule_heating",
    "ambient_leak",
    "heatsink",
    "thermistor_lag",
    "die_lag",
    "tilt",
    "drift",
    "rate_sensitivity",
    "temperature_offset",
    "temperature_quantisation",
    "sensitivity_loss",
    "noise",
)

FAULT_NAMES: tuple[str, ...] = (
    "sensor_absent",
    "sensor_stuck",
    "inner_open",
    "inner_short",
    "outer_open",
    "outer_short",
    "peltier_disconnected",
    "peltier_reversed",
    "inner_detached",
    "heatsink_failed",
    "chamber_hang",
    "imu_hang",
    "imu_uart_corrupt",
    "chamber_uart_corrupt",
)
_FAULTS_WITH_RATE = frozenset({"imu_uart_corrupt", "chamber_uart_corrupt"})
# What is left of the heatsink's conductance to ambient when its fan stops or
# its thermal joint dries: free convection from fins sized for forced air is
# of the order of a tenth of it or less (assumed; the cell overheats either way).
FAILED_HEATSINK_FRACTION = 0.05


@dataclass(frozen=True)
class Bounds:
    """The physically plausible range of a number in the model file;
    docs/physics-model.md gives the reason for each."""

    low: float
    high: float
    unit: str = ""
    # True: the value must lie above low, not on it.
    low_exclusive: bool = False

    def check(self, value: Any, where: str) -> float:
        number = _number(value, where)
        below = number <= self.low if self.low_exclusive else number < self.low
        if below or not number <= self.high:
            raise ModelError(f"{where}: must be {self}, got {reprlib.repr(value)}")
        return number

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"{'>' if self.low_exclusive else '>='} {self.low:g} and <= {self.high:g}{unit}"


@dataclass(frozen=True)
class PerAxis:
    """A table {x, y, z} of numbers within the same bounds."""

    bounds: Bounds


# The strings are "bool" (enabled) and "coefficients" ("paper" or a table
# of drift surfaces).
ParameterKind = Bounds | PerAxis | str

_INT16_MIN, _INT16_MAX = -32768, 32767
_INT16_SPAN = _INT16_MAX - _INT16_MIN + 1
# The LSM9DS0's operating temperature range (datasheet).
_OPERATING_C = Bounds(-40.0, 85.0, "degC")
_HEAT_CAPACITY = Bounds(4.0, 1e5, "J/K")
_HEATER_POWER = Bounds(0.0, 500.0, "W")
_RESISTOR = Bounds(100.0, 1e7, "ohm")

TERM_PARAMETERS: Mapping[str, Mapping[str, ParameterKind]] = {
    "peltier_pumping": {"full_duty_w": _HEATER_POWER},
    "joule_heating": {
        "full_duty_w": _HEATER_POWER,
        "exponent": Bounds(1.0, 2.0),
        "inner_fraction": Bounds(0.0, 1.0),
    },
    "ambient_leak": {"conductance_w_per_k": Bounds(0.0, 10.0, "W/K")},
    "heatsink": {
        "heat_capacity_j_per_k": _HEAT_CAPACITY,
        "inner_conductance_w_per_k": Bounds(0.0, 10.0, "W/K"),
        "ambient_conductance_w_per_k": Bounds(0.0, 50.0, "W/K"),
    },
    "thermistor_lag": {"time_constant_s": Bounds(0.0, 600.0, "s", low_exclusive=True)},
    "die_lag": {"time_constant_s": Bounds(0.0, 3600.0, "s", low_exclusive=True)},
    "tilt": {},
    "drift": {"coefficients": "coefficients", "schmitt_band_c": Bounds(0.0, 10.0, "degC")},
    "rate_sensitivity": {
        "lsb_per_c_per_s": PerAxis(Bounds(-_INT16_SPAN, _INT16_SPAN, "LSB per degC/s"))
    },
    "temperature_offset": {"offset_c": Bounds(-20.0, 20.0, "degC")},
    "temperature_quantisation": {},
    "sensitivity_loss": {"gain_loss_at_1g": Bounds(0.0, 0.33)},
    "noise": {"sigma_lsb": PerAxis(Bounds(0.0, 1000.0, "LSB"))},
}

# Properties of the hardware that are not switchable effects.
CONSTANT_PARAMETERS: Mapping[str, Mapping[str, ParameterKind]] = {
    "chamber": {
        "inner_heat_capacity_j_per_k": _HEAT_CAPACITY,
        "supply_mv": Bounds(1800.0, 5500.0, "mV"),
        "divider_reference_ohm": _RESISTOR,
        "thermistor_r25_ohm": _RESISTOR,
        "thermistor_beta_k": Bounds(1000.0, 10000.0, "K"),
    },
    "sensor": {
        "lsb_per_g": Bounds(1000.0, _INT16_MAX, "LSB"),
        "temperature_lsb_per_c": Bounds(1.0, 256.0, "LSB"),
        "temperature_zero_c": _OPERATING_C,
    },
}

# A drift surface term alone may add at most the int16 span anywhere the
# sensor works: over its operating range and at any int16 reading. p<i><j>
# multiplies T^i a^j.
_SURFACE_TERM_POWERS = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))
SURFACE_TERM_NAMES = tuple(f"p{t}{a}" for t, a in _SURFACE_TERM_POWERS)
_LARGEST_ABS_C = max(-_OPERATING_C.low, _OPERATING_C.high)
SURFACE_TERM_BOUNDS: tuple[Bounds, ...] = tuple(
    Bounds(-limit, limit)
    for limit in (
        _INT16_SPAN / (_LARGEST_ABS_C**t * float(-_INT16_MIN) ** a) for t, a in _SURFACE_TERM_POWERS
    )
)
# A model file is a few kB; this stops a device file from being read forever.
_MAX_MODEL_BYTES = 1 << 20

_ZERO_CELSIUS_K = 273.15
# The LSM9DS0 temperature output is 12-bit two's complement.
_TEMPERATURE_RAW_MIN, _TEMPERATURE_RAW_MAX = -2048, 2047
_NOISE_BLOCK_SAMPLES = 4096


@dataclass(frozen=True)
class Fault:
    """A fault injected into the twin between start_s and end_s (None: to the
    end). rate is the probability per byte of the *_uart_corrupt faults."""

    name: str
    start_s: float = 0.0
    end_s: float | None = None
    rate: float | None = None

    def __post_init__(self) -> None:
        if self.name not in FAULT_NAMES:
            raise ModelError(f"unknown fault '{self.name}' (known: {', '.join(FAULT_NAMES)})")
        if not (math.isfinite(self.start_s) and self.start_s >= 0.0):
            raise ModelError(f"fault '{self.name}': start {self.start_s} s must be >= 0")
        if self.end_s is not None and not (math.isfinite(self.end_s) and self.end_s > self.start_s):
            raise ModelError(
                f"fault '{self.name}': end {self.end_s} s must be after start {self.start_s} s"
            )
        if self.name in _FAULTS_WITH_RATE:
            if self.rate is None or not (0.0 < self.rate <= 1.0):
                raise ModelError(
                    f"fault '{self.name}' needs a rate, a probability per byte in (0, 1]"
                )
        elif self.rate is not None:
            raise ModelError(f"fault '{self.name}' takes no rate")

    def active(self, time_s: float) -> bool:
        return self.start_s <= time_s and (self.end_s is None or time_s < self.end_s)


_FAULT_TEXT = re.compile(
    r"(?P<name>[a-z_]+)"
    r"(?:=(?P<rate>[^@]+))?"
    r"(?:@(?P<start>[0-9.eE+]+)(?:-(?P<end>[0-9.eE+]+))?)?"
)


def parse_fault(text: str) -> Fault:
    """A fault from the command-line syntax NAME[=RATE][@START[-END]] (seconds),
    e.g. "inner_open@120-180" or "imu_uart_corrupt=0.001"."""
    match = _FAULT_TEXT.fullmatch(text.strip())
    if match is None:
        raise ModelError(f"fault '{text}': expected NAME[=RATE][@START[-END]]")
    try:
        rate = None if match["rate"] is None else float(match["rate"])
        start = 0.0 if match["start"] is None else float(match["start"])
        end = None if match["end"] is None else float(match["end"])
    except ValueError:
        raise ModelError(f"fault '{text}': rate, start and end must be numbers") from None
    return Fault(match["name"], start, end, rate)


@dataclass(frozen=True)
class Model:
    """The physical model: switchable terms, hardware constants and faults."""

    source: str
    terms: Mapping[str, Mapping[str, Any]]
    faults: tuple[Fault, ...] = ()
    # "chamber" and "sensor": properties of the hardware that no switch removes.
    constants: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)

    @classmethod
    def load(cls, path: str | Path | None = None) -> Model:
        """Read and validate a model file; None reads the packaged default."""
        if path is None:
            source = "default"
            text = resources.files(__package__).joinpath("models/default.toml").read_text("utf-8")
        else:
            source = str(path)
            text = _read_model_text(Path(path), source)
        try:
            document = tomllib.loads(text)
        except tomllib.TOMLDecodeError as error:
            raise ModelError(f"{source}: not valid TOML: {error}") from None
        except RecursionError:
            raise ModelError(f"{source}: not valid TOML: nested too deeply") from None
        return _model_from_document(document, source)

    def enabled(self, term: str) -> bool:
        self._check_term(term)
        return bool(self.terms[term]["enabled"])

    def with_terms(self, changes: Mapping[str, bool]) -> Model:
        """A copy with the named terms switched on (True) or off (False)."""
        terms = dict(self.terms)
        for term, enabled in changes.items():
            self._check_term(term)
            if not isinstance(enabled, bool):
                raise ModelError(f"{self.source}: [{term}] enabled must be true or false")
            terms[term] = MappingProxyType({**self.terms[term], "enabled": enabled})
        return replace(self, terms=MappingProxyType(terms))

    def with_faults(self, faults: Iterable[Fault]) -> Model:
        """A copy with these faults appended."""
        return replace(self, faults=self.faults + tuple(faults))

    def _check_term(self, term: str) -> None:
        if term not in TERMS:
            raise ModelError(f"{self.source}: unknown term '{term}' (known: {', '.join(TERMS)})")


def _read_model_text(path: Path, source: str) -> str:
    try:
        with open(path, "rb") as stream:
            data = stream.read(_MAX_MODEL_BYTES + 1)
    except OSError as error:
        raise ModelError(f"{source}: cannot read: {error.strerror or error}") from None
    if len(data) > _MAX_MODEL_BYTES:
        raise ModelError(f"{source}: larger than {_MAX_MODEL_BYTES} bytes, not a model file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ModelError(f"{source}: not UTF-8 text (byte {error.start})") from None


def _shown(name: str) -> str:
    """A key from the file as one line of text: control characters escaped."""
    return name if name.isprintable() else name.encode("unicode_escape").decode("ascii")


def _model_from_document(document: Mapping[str, Any], source: str) -> Model:
    known_sections = set(TERMS) | set(CONSTANT_PARAMETERS) | {"faults"}
    for section in document:
        if section not in known_sections:
            raise ModelError(f"{source}: unknown section [{_shown(section)}]")
    constants = {
        section: _read_table(document, section, parameters, source, switchable=False)
        for section, parameters in CONSTANT_PARAMETERS.items()
    }
    terms = {
        term: _read_table(document, term, TERM_PARAMETERS[term], source, switchable=True)
        for term in TERMS
    }
    faults = _read_faults(document.get("faults", []), source)
    return Model(
        source=source,
        terms=MappingProxyType(terms),
        faults=faults,
        constants=MappingProxyType(constants),
    )


def _read_table(
    document: Mapping[str, Any],
    section: str,
    parameters: Mapping[str, ParameterKind],
    source: str,
    switchable: bool,
) -> Mapping[str, Any]:
    if section not in document:
        raise ModelError(f"{source}: missing section [{section}]")
    table = document[section]
    if not isinstance(table, dict):
        raise ModelError(f"{source}: [{section}] must be a table, got {reprlib.repr(table)}")
    expected: dict[str, ParameterKind] = dict(parameters)
    if switchable:
        expected["enabled"] = "bool"
    for name in table:
        if name not in expected:
            raise ModelError(f"{source}: [{section}] unknown parameter '{_shown(name)}'")
    values: dict[str, Any] = {}
    for name, kind in expected.items():
        if name not in table:
            raise ModelError(f"{source}: [{section}] missing parameter '{name}'")
        values[name] = _checked_value(table[name], kind, f"{source}: [{section}] {name}")
    return MappingProxyType(values)


def _number(value: Any, where: str) -> float:
    """A TOML integer or float as a float; integers beyond float's range are
    infinite."""
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        raise ModelError(f"{where}: expected a number, got {reprlib.repr(value)}")
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _finite_number(value: Any, where: str) -> float:
    number = _number(value, where)
    if not math.isfinite(number):
        raise ModelError(f"{where}: expected a finite number, got {reprlib.repr(value)}")
    return number


def _checked_value(value: Any, kind: ParameterKind, where: str) -> Any:
    if isinstance(kind, Bounds):
        return kind.check(value, where)
    if isinstance(kind, PerAxis):
        if not isinstance(value, dict) or set(value) != {"x", "y", "z"}:
            raise ModelError(
                f"{where}: expected a table {{x = .., y = .., z = ..}}, got {reprlib.repr(value)}"
            )
        return MappingProxyType(
            {axis: kind.bounds.check(value[axis], f"{where}.{axis}") for axis in "xyz"}
        )
    if kind == "coefficients":
        return _checked_coefficients(value, where)
    if not isinstance(value, bool):
        raise ModelError(f"{where}: expected true or false, got {reprlib.repr(value)}")
    return value


def _checked_coefficients(value: Any, where: str) -> Any:
    if value == "paper":
        return value
    if not isinstance(value, dict) or set(value) != set(SETS):
        raise ModelError(f'{where}: expected "paper" or a table with sets {", ".join(SETS)}')
    surfaces: dict[str, Any] = {}
    for set_ in SETS:
        per_axis = value[set_]
        if not isinstance(per_axis, dict) or set(per_axis) != set(AXES):
            raise ModelError(f"{where}.{set_}: expected a table with axes {', '.join(AXES)}")
        surfaces[set_] = {}
        for axis in AXES:
            terms = per_axis[axis]
            if not isinstance(terms, list) or len(terms) != len(SURFACE_TERM_NAMES):
                raise ModelError(
                    f"{where}.{set_}.{axis}: expected 6 numbers {', '.join(SURFACE_TERM_NAMES)}"
                )
            surfaces[set_][axis] = tuple(
                bounds.check(term, f"{where}.{set_}.{axis} {name}")
                for term, name, bounds in zip(terms, SURFACE_TERM_NAMES, SURFACE_TERM_BOUNDS)
            )
    return MappingProxyType(surfaces)


def _read_faults(entries: Any, source: str) -> tuple[Fault, ...]:
    if not isinstance(entries, list):
        raise ModelError(f"{source}: faults must be an array of tables [[faults]]")
    faults = []
    for index, entry in enumerate(entries):
        where = f"{source}: [[faults]] #{index + 1}"
        if not isinstance(entry, dict):
            raise ModelError(f"{where}: expected a table")
        unknown = set(entry) - {"name", "start_s", "end_s", "rate"}
        if unknown:
            raise ModelError(f"{where}: unknown key '{_shown(sorted(unknown)[0])}'")
        name = entry.get("name")
        if not isinstance(name, str):
            raise ModelError(f"{where}: missing name")
        numbers = {
            key: _finite_number(entry[key], f"{where} {key}")
            for key in ("start_s", "end_s", "rate")
            if key in entry
        }
        try:
            fault = Fault(
                _shown(name),
                numbers.get("start_s", 0.0),
                numbers.get("end_s"),
                numbers.get("rate"),
            )
        except ModelError as error:
            raise ModelError(f"{where}: {error}") from None
        faults.append(fault)
    return tuple(faults)


def _coefficient_table(value: Any) -> CoefficientTable:
    if value == "paper":
        return PAPER_DEFAULTS
    return CoefficientTable(
        {(set_, axis): Surface(*value[set_][axis]) for set_ in SETS for axis in AXES}
    )


class _LagFraction:
    """How far a first-order lag moves towards its input in one step,
    1 - exp(-dt/tau), recomputed only when the step length changes (the twin
    always steps 10 ms)."""

    __slots__ = ("_tau_s", "_dt_s", "_fraction")

    def __init__(self, tau_s: float) -> None:
        self._tau_s = tau_s
        self._dt_s = -1.0
        self._fraction = 1.0

    def of_step(self, dt_s: float) -> float:
        if dt_s != self._dt_s:
            self._dt_s = dt_s
            self._fraction = -math.expm1(-dt_s / self._tau_s)
        return self._fraction


def _lag_of(term: Mapping[str, Any]) -> _LagFraction | None:
    """The term's lag, or None when it is off (or has no time constant)."""
    tau_s = term["time_constant_s"] if term["enabled"] else 0.0
    return _LagFraction(tau_s) if tau_s > 0.0 else None


class Chamber:
    """Two faces of the Peltier cell as lumped thermal nodes, and the two
    thermistors that read them.

    The inner (reference) face carries what the chamber holds; the outer face
    is the heatsink. Heat into the inner face:
    pumped + Joule share + conduction through the cell + leak to ambient.
    """

    __slots__ = (
        "inner_c",
        "outer_c",
        "inner_thermistor_c",
        "outer_thermistor_c",
        "inner_thermistor_detached",
        "heatsink_failed",
        "_inner_capacity",
        "_pumping_w",
        "_joule_w",
        "_joule_exponent",
        "_joule_inner_fraction",
        "_leak",
        "_heatsink_enabled",
        "_outer_capacity",
        "_cell_conductance",
        "_heatsink_conductance",
        "_thermistor_lag",
        "_max_substep",
        "_supply_mv",
        "_reference_ohm",
        "_r25_ohm",
        "_beta_k",
    )

    def __init__(self, model: Model, ambient_c: float) -> None:
        terms = model.terms
        constants = model.constants["chamber"]
        self._inner_capacity = constants["inner_heat_capacity_j_per_k"]
        self._supply_mv = constants["supply_mv"]
        self._reference_ohm = constants["divider_reference_ohm"]
        self._r25_ohm = constants["thermistor_r25_ohm"]
        self._beta_k = constants["thermistor_beta_k"]

        pumping = terms["peltier_pumping"]
        self._pumping_w = pumping["full_duty_w"] if pumping["enabled"] else 0.0
        joule = terms["joule_heating"]
        self._joule_w = joule["full_duty_w"] if joule["enabled"] else 0.0
        self._joule_exponent = joule["exponent"]
        self._joule_inner_fraction = joule["inner_fraction"]
        leak = terms["ambient_leak"]
        self._leak = leak["conductance_w_per_k"] if leak["enabled"] else 0.0
        heatsink = terms["heatsink"]
        self._heatsink_enabled = bool(heatsink["enabled"])
        self._outer_capacity = heatsink["heat_capacity_j_per_k"]
        # Conduction through the cell stays when the heatsink is ideal.
        self._cell_conductance = heatsink["inner_conductance_w_per_k"]
        self._heatsink_conductance = heatsink["ambient_conductance_w_per_k"]
        self._thermistor_lag = _lag_of(terms["thermistor_lag"])

        # Explicit Euler is stable and accurate for steps well below the
        # shortest node time constant; longer steps are split.
        time_constants = [
            self._inner_capacity / max(self._leak + self._cell_conductance, 1e-12)
        ]
        if self._heatsink_enabled:
            time_constants.append(
                self._outer_capacity
                / max(self._cell_conductance + self._heatsink_conductance, 1e-12)
            )
        self._max_substep = 0.05 * min(time_constants)

        self.inner_c = float(ambient_c)
        self.outer_c = float(ambient_c)
        self.inner_thermistor_c = float(ambient_c)
        self.outer_thermistor_c = float(ambient_c)
        # Faults: the inner thermistor off its face, reading the room; the
        # heatsink's path to ambient (fan, thermal joint) down to a residue.
        self.inner_thermistor_detached = False
        self.heatsink_failed = False

    def step(self, dt_s: float, duty: float, direction: int, ambient_c: float) -> None:
        """Advance dt_s with the bridge at this mean duty (0..1); direction +1
        heats the inner face, -1 cools it, 0 lets no current flow."""
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        if not 0.0 <= duty <= 1.0:
            raise ValueError(f"duty must be within 0..1, got {duty}")
        if direction not in (-1, 0, 1):
            raise ValueError(f"direction must be -1, 0 or +1, got {direction}")
        if direction == 0:
            duty = 0.0
        pumped_w = direction * self._pumping_w * duty
        joule_w = self._joule_w * duty**self._joule_exponent if duty > 0.0 else 0.0
        inner_drive_w = pumped_w + joule_w * self._joule_inner_fraction
        outer_drive_w = joule_w * (1.0 - self._joule_inner_fraction) - pumped_w

        substeps = 1 if dt_s <= self._max_substep else math.ceil(dt_s / self._max_substep)
        h = dt_s / substeps
        inner = self.inner_c
        outer = self.outer_c if self._heatsink_enabled else ambient_c
        inner_capacity = self._inner_capacity
        outer_capacity = self._outer_capacity
        cell = self._cell_conductance
        leak = self._leak
        sink = self._heatsink_conductance
        if self.heatsink_failed:
            sink *= FAILED_HEATSINK_FRACTION
        for _ in range(substeps):
            through_cell_w = cell * (outer - inner)
            inner_w = inner_drive_w + through_cell_w + leak * (ambient_c - inner)
            if self._heatsink_enabled:
                outer_w = outer_drive_w - through_cell_w + sink * (ambient_c - outer)
                outer += h * outer_w / outer_capacity
            inner += h * inner_w / inner_capacity
        self.inner_c = inner
        self.outer_c = outer

        inner_sensed = ambient_c if self.inner_thermistor_detached else inner
        if self._thermistor_lag is not None:
            alpha = self._thermistor_lag.of_step(dt_s)
            self.inner_thermistor_c += alpha * (inner_sensed - self.inner_thermistor_c)
            self.outer_thermistor_c += alpha * (outer - self.outer_thermistor_c)
        else:
            self.inner_thermistor_c = inner_sensed
            self.outer_thermistor_c = outer

    def thermistor_millivolts(self) -> tuple[float, float]:
        """Divider voltages at A0 (inner) and A1 (outer): the NTC to ground
        under the reference resistor from the supply."""
        return (
            self._divider_millivolts(self.inner_thermistor_c),
            self._divider_millivolts(self.outer_thermistor_c),
        )

    def _divider_millivolts(self, celsius: float) -> float:
        kelvin = celsius + _ZERO_CELSIUS_K
        inverse_kelvin_from_25 = 1.0 / kelvin - 1.0 / (25.0 + _ZERO_CELSIUS_K)
        ohms = self._r25_ohm * math.exp(self._beta_k * inverse_kelvin_from_25)
        return self._supply_mv * ohms / (ohms + self._reference_ohm)


@dataclass(frozen=True, slots=True)
class SensorSample:
    """One LSM9DS0 sample: register contents and the model's intermediate values."""

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


def _clip_round(value: float, low: int, high: int) -> int:
    rounded = math.floor(value + 0.5)
    return low if rounded < low else high if rounded > high else rounded


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
        "_lsb_per_g",
        "_temperature_lsb_per_c",
        "_temperature_zero_c",
        "_die_lag",
        "_tilt",
        "_drift",
        "_surfaces",
        "_schmitt_band",
        "_rate_gains",
        "_offset_c",
        "_quantise",
        "_gain_loss",
        "_sigmas",
        "_noise",
        "_dither",
        "_die_c",
        "_trend_set",
        "_trend_extreme",
        "_angles",
        "_ideal",
    )

    def __init__(self, model: Model, seed: int, environment_c: float) -> None:
        terms = model.terms
        constants = model.constants["sensor"]
        self._lsb_per_g = constants["lsb_per_g"]
        self._temperature_lsb_per_c = constants["temperature_lsb_per_c"]
        self._temperature_zero_c = constants["temperature_zero_c"]

        self._die_lag = _lag_of(terms["die_lag"])
        self._tilt = bool(terms["tilt"]["enabled"])
        drift = terms["drift"]
        self._drift = bool(drift["enabled"])
        table = _coefficient_table(drift["coefficients"])
        self._surfaces = {
            set_: tuple(tuple(table.surface(set_, axis)) for axis in AXES) for set_ in SETS
        }
        self._schmitt_band = drift["schmitt_band_c"]
        rate = terms["rate_sensitivity"]
        gains = rate["lsb_per_c_per_s"]
        self._rate_gains = (
            (gains["x"], gains["y"], gains["z"]) if rate["enabled"] else (0.0, 0.0, 0.0)
        )
        offset = terms["temperature_offset"]
        self._offset_c = offset["offset_c"] if offset["enabled"] else 0.0
        self._quantise = bool(terms["temperature_quantisation"]["enabled"])
        loss = terms["sensitivity_loss"]
        self._gain_loss = loss["gain_loss_at_1g"] if loss["enabled"] else 0.0
        noise = terms["noise"]
        sigmas = noise["sigma_lsb"]
        self._sigmas = (sigmas["x"], sigmas["y"], sigmas["z"]) if noise["enabled"] else None

        # Separate streams, so switching dither on or off leaves the noise as it was.
        noise_seed, dither_seed = np.random.SeedSequence(seed).spawn(2)
        self._noise = _BlockDraws(np.random.default_rng(noise_seed).standard_normal)
        self._dither = _BlockDraws(np.random.default_rng(dither_seed).random)

        self._die_c = float(environment_c)
        # Like the firmware's TrendDetector: starts warming, as the paper's cycles do.
        self._trend_set = "W"
        self._trend_extreme = self._die_c
        self._angles: tuple[float, float] | None = None
        self._ideal = (0.0, 0.0, 0.0)

    def step(
        self, dt_s: float, environment_c: float, incl_x_deg: float, incl_y_deg: float
    ) -> SensorSample:
        """Advance dt_s and return the sample the registers then hold."""
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        previous_die = self._die_c
        if self._die_lag is not None:
            die = previous_die + self._die_lag.of_step(dt_s) * (environment_c - previous_die)
        else:
            die = float(environment_c)
        self._die_c = die
        rate = (die - previous_die) / dt_s
        drift_set = self._update_trend(die)
        reported = die + self._offset_c

        if self._angles != (incl_x_deg, incl_y_deg):
            self._angles = (incl_x_deg, incl_y_deg)
            self._ideal = self._ideal_acceleration(incl_x_deg, incl_y_deg)
        ideal_x, ideal_y, ideal_z = self._ideal

        if self._drift:
            surface_x, surface_y, surface_z = self._surfaces[drift_set]
            drift_x = _surface(surface_x, reported, ideal_x)
            drift_y = _surface(surface_y, reported, ideal_y)
            drift_z = _surface(surface_z, reported, ideal_z)
        else:
            drift_x = drift_y = drift_z = 0.0

        gain_x, gain_y, gain_z = self._rate_gains
        raw_x = ideal_x + drift_x + gain_x * rate
        raw_y = ideal_y + drift_y + gain_y * rate
        raw_z = ideal_z + drift_z + gain_z * rate
        if self._sigmas is not None:
            sigma_x, sigma_y, sigma_z = self._sigmas
            draw = self._noise.next
            raw_x += sigma_x * draw()
            raw_y += sigma_y * draw()
            raw_z += sigma_z * draw()

        temperature_lsb = (reported - self._temperature_zero_c) * self._temperature_lsb_per_c
        if not self._quantise:
            # Dither: each code is picked with a probability that keeps its
            # mean at the continuous value, so averaging sees no staircase.
            temperature_lsb += self._dither.next() - 0.5

        return SensorSample(
            ax=_clip_round(raw_x, _INT16_MIN, _INT16_MAX),
            ay=_clip_round(raw_y, _INT16_MIN, _INT16_MAX),
            az=_clip_round(raw_z, _INT16_MIN, _INT16_MAX),
            temperature_raw=_clip_round(
                temperature_lsb, _TEMPERATURE_RAW_MIN, _TEMPERATURE_RAW_MAX
            ),
            die_c=die,
            reported_c=reported,
            rate_c_per_s=rate,
            drift_set=drift_set,
            ideal_ax=ideal_x,
            ideal_ay=ideal_y,
            ideal_az=ideal_z,
            drift_x=drift_x,
            drift_y=drift_y,
            drift_z=drift_z,
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

    def _ideal_acceleration(
        self, incl_x_deg: float, incl_y_deg: float
    ) -> tuple[float, float, float]:
        g = self._lsb_per_g
        if self._tilt:
            x = math.radians(incl_x_deg)
            y = math.radians(incl_y_deg)
            ax = g * math.sin(x)
            ay = g * math.cos(x) * math.sin(y)
            az = g * math.cos(x) * math.cos(y)
        else:
            ax, ay, az = 0.0, 0.0, g
        loss = self._gain_loss
        return (
            ax * (1.0 - loss * (ax / g) ** 2),
            ay * (1.0 - loss * (ay / g) ** 2),
            az * (1.0 - loss * (az / g) ** 2),
        )


def _surface(p: tuple[float, ...], temperature_c: float, acceleration: float) -> float:
    # The paper's equation (3), f(T, a), in the firmware's grouping.
    return (
        p[0]
        + temperature_c * (p[1] + p[3] * temperature_c + p[4] * acceleration)
        + acceleration * (p[2] + p[5] * acceleration)
    )
