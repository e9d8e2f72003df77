"""The chamber integrator: the inner face (capacity from [chamber]), the
outer face when a term adds it (the heatsink), and the room, with the heat
flows of every chamber term summed once at construction."""

from __future__ import annotations

import math

import numpy as np

from .faults import FAILED_HEATSINK_FRACTION
from .model import Model
from .terms import ChamberTerm, HeatFlows
from .terms.lag import LagFraction

_ZERO_CELSIUS_K = 273.15
# The AVR's ADC gives V_in * 1024 / V_ref, the reference the dividers'
# supply (datasheet; lib/Thermistor).
ADC_CODES = 1024
# The span of a central difference of the divider's voltage, degC.
_DIFFERENCE_C = 0.01
_LINKS = (("inner", "outer"), ("inner", "ambient"), ("outer", "ambient"))


def _summed(flows: list[HeatFlows]) -> tuple[dict[str, float], dict[tuple[str, str], float]]:
    nodes: dict[str, float] = {}
    links: dict[tuple[str, str], float] = {}
    for flow in flows:
        for node, capacity in flow.nodes.items():
            if node != "outer" or node in nodes:
                raise ValueError(f"the chamber has no place for a node '{node}'")
            nodes[node] = capacity
        for link, conductance in flow.conductances.items():
            if link not in _LINKS:
                raise ValueError(f"the chamber has no link {link}")
            links[link] = links.get(link, 0.0) + conductance
    return nodes, links


class Chamber:
    """Two faces of the Peltier cell as lumped thermal nodes, and the two
    thermistors that read them.

    The inner (reference) face carries what the chamber holds; the outer face
    is the heatsink. Heat into the inner face: the terms' drive (pumped, Joule
    share) + conduction through the cell + leak to ambient.
    """

    __slots__ = (
        "inner_c",
        "outer_c",
        "inner_thermistor_c",
        "outer_thermistor_c",
        "inner_thermistor_detached",
        "heatsink_failed",
        "_inner_capacity",
        "_drives",
        "_seen_duties",
        "_reading_offsets",
        "_outer_node",
        "_outer_capacity",
        "_cell_conductance",
        "_leak",
        "_heatsink_conductance",
        "_thermistor_lag",
        "_max_substep",
        "_supply_mv",
        "_reference_ohm",
        "_r25_ohm",
        "_beta_k",
    )

    def __init__(self, model: Model, ambient_c: float) -> None:
        constants = model.constants["chamber"]
        self._inner_capacity = constants["inner_heat_capacity_j_per_k"]
        self._supply_mv = constants["supply_mv"]
        self._reference_ohm = constants["divider_reference_ohm"]
        self._r25_ohm = constants["thermistor_r25_ohm"]
        self._beta_k = constants["thermistor_beta_k"]

        terms = model.bound_terms(ChamberTerm)
        flows = [term.heat_flows() for term in terms]
        nodes, links = _summed(flows)
        self._drives = tuple(flow.drive for flow in flows if flow.drive is not None)
        self._seen_duties = tuple(flow.seen_duty for flow in flows if flow.seen_duty is not None)
        offsets = [offset for term in terms if (offset := term.reading_offsets_c()) is not None]
        self._reading_offsets = (sum(o[0] for o in offsets), sum(o[1] for o in offsets)) if offsets else None
        self._outer_node = "outer" in nodes
        self._outer_capacity = nodes.get("outer", 0.0)
        self._cell_conductance = links.get(("inner", "outer"), 0.0)
        self._leak = links.get(("inner", "ambient"), 0.0)
        self._heatsink_conductance = links.get(("outer", "ambient"), 0.0)
        lags = [lag for term in terms if (lag := term.thermistor_lag_s()) is not None]
        self._thermistor_lag = LagFraction(lags[0]) if lags else None

        # Explicit Euler is stable and accurate for steps well below the
        # shortest node time constant; longer steps are split.
        time_constants = [self._inner_capacity / max(self._leak + self._cell_conductance, 1e-12)]
        if self._outer_node:
            time_constants.append(
                self._outer_capacity / max(self._cell_conductance + self._heatsink_conductance, 1e-12)
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

    def start_at_readings(self, inner_reading_c: float, outer_reading_c: float) -> None:
        """Both faces and their thermistors at rest where these readings
        (as readings_c gives them) put them."""
        inner_offset, outer_offset = self._reading_offsets or (0.0, 0.0)
        self.inner_c = self.inner_thermistor_c = inner_reading_c - inner_offset
        self.outer_c = self.outer_thermistor_c = outer_reading_c - outer_offset

    def step(self, dt_s: float, duty: float, direction: int, ambient_c: float) -> None:
        """Advance dt_s with the bridge at this mean duty (0..1); direction +1
        heats the inner face, -1 cools it, 0 lets no current flow."""
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        if not 0.0 <= duty <= 1.0:
            raise ValueError(f"duty must be within 0..1, got {duty}")
        if direction not in (-1, 0, 1):
            raise ValueError(f"direction must be -1, 0 or +1, got {direction}")
        inner_drive_w, outer_drive_w = self._drive_w(0.0 if direction == 0 else duty, direction)

        substeps = self.substeps(dt_s)
        h = dt_s / substeps
        inner = self.inner_c
        outer_node = self._outer_node
        outer = self.outer_c if outer_node else ambient_c
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
            if outer_node:
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

    def held(
        self, dt_s: np.ndarray, duty: np.ndarray, direction: np.ndarray, ambient_c: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """step() through a series of intervals, each with its own drive and
        ambient: the inner and outer readings (readings_c) and the inner face
        after each. The same Euler substeps as step() takes, composed as
        affine maps by a prefix scan instead of one Python call per
        interval, so the same values to rounding (test_physics)."""
        dt_s, duty, ambient_c = (np.asarray(values, dtype=float) for values in (dt_s, duty, ambient_c))
        direction = np.asarray(direction, dtype=int)
        if not np.all(dt_s > 0.0):
            raise ValueError(f"dt_s must be > 0, got {dt_s.min()}")
        if not np.all((duty >= 0.0) & (duty <= 1.0)):
            raise ValueError("duty must be within 0..1")
        if not np.all(np.isin(direction, (-1, 0, 1))):
            raise ValueError("direction must be -1, 0 or +1")
        duty = np.where(direction == 0, 0.0, duty)
        # The terms' drives are functions of one duty and direction: asked
        # once per pair (direction * 2 + duty tells the pairs apart).
        _, first, which = np.unique(direction * 2.0 + duty, return_index=True, return_inverse=True)
        drives = np.array([self._drive_w(float(duty[k]), int(direction[k])) for k in first.tolist()]).reshape(-1, 2)[
            which
        ]

        substeps = np.where(dt_s <= self._max_substep, 1, np.ceil(dt_s / self._max_substep)).astype(int)
        h = np.repeat(dt_s / substeps, substeps)
        ambient = np.repeat(ambient_c, substeps)
        inner_drive_w, outer_drive_w = np.repeat(drives, substeps, axis=0).T
        inner_capacity = self._inner_capacity
        cell = self._cell_conductance
        leak = self._leak
        sink = self._heatsink_conductance * (FAILED_HEATSINK_FRACTION if self.heatsink_failed else 1.0)
        if self._outer_node:
            outer_capacity = self._outer_capacity
            maps = np.empty((len(h), 2, 2))
            maps[:, 0, 0] = 1.0 - h * (cell + leak) / inner_capacity
            maps[:, 0, 1] = h * cell / inner_capacity
            maps[:, 1, 0] = h * cell / outer_capacity
            maps[:, 1, 1] = 1.0 - h * (cell + sink) / outer_capacity
            shifts = np.stack(
                [
                    h * (inner_drive_w + leak * ambient) / inner_capacity,
                    h * (outer_drive_w + sink * ambient) / outer_capacity,
                ],
                axis=1,
            )
            faces = _affine_scan(maps, shifts, np.array([self.inner_c, self.outer_c]))
        else:
            maps = (1.0 - h * (cell + leak) / inner_capacity)[:, None]
            shifts = (h * (inner_drive_w + (cell + leak) * ambient) / inner_capacity)[:, None]
            inner = _affine_scan(maps, shifts, np.array([self.inner_c]))
            faces = np.concatenate([inner, ambient[:, None]], axis=1)
        inner, outer = faces[np.cumsum(substeps) - 1].T

        inner_sensed = np.broadcast_to(ambient_c, inner.shape) if self.inner_thermistor_detached else inner
        if self._thermistor_lag is not None:
            fraction = -np.expm1(-dt_s / self._thermistor_lag.tau_s)[:, None]
            sensed = _affine_scan(
                np.repeat(1.0 - fraction, 2, axis=1),
                fraction * np.stack([inner_sensed, outer], axis=1),
                np.array([self.inner_thermistor_c, self.outer_thermistor_c]),
            )
        else:
            sensed = np.stack([inner_sensed, outer], axis=1)
        self.inner_c, self.outer_c = float(inner[-1]), float(outer[-1])
        self.inner_thermistor_c, self.outer_thermistor_c = (float(value) for value in sensed[-1])
        offsets = np.array(self._reading_offsets or (0.0, 0.0))
        readings = sensed + offsets
        return readings[:, 0], readings[:, 1], inner

    def _drive_w(self, duty: float, direction: int) -> tuple[float, float]:
        for seen in self._seen_duties:
            duty = seen(duty)
        inner_drive_w = outer_drive_w = 0.0
        for drive in self._drives:
            inner_w, outer_w = drive(duty, direction)
            inner_drive_w += inner_w
            outer_drive_w += outer_w
        return inner_drive_w, outer_drive_w

    def substeps(self, dt_s: float) -> int:
        """How many Euler steps step() splits dt_s into."""
        return 1 if dt_s <= self._max_substep else math.ceil(dt_s / self._max_substep)

    def readings_c(self) -> tuple[float, float]:
        """The temperatures the inner and outer thermistors stand for: their
        own, shifted by any term's reading offset (a part off its nominal
        curve reads as if it were that much warmer)."""
        if self._reading_offsets is None:
            return self.inner_thermistor_c, self.outer_thermistor_c
        inner_offset, outer_offset = self._reading_offsets
        return self.inner_thermistor_c + inner_offset, self.outer_thermistor_c + outer_offset

    def thermistor_millivolts(self) -> tuple[float, float]:
        """Divider voltages at A0 (inner) and A1 (outer): the NTC to ground
        under the reference resistor from the supply."""
        inner_c, outer_c = self.readings_c()
        return self._divider_millivolts(inner_c), self._divider_millivolts(outer_c)

    def celsius_per_adc_code(self, celsius: float) -> float:
        """How many degC one ADC code spans at a thermistor temperature."""
        millivolts_per_c = (
            self._divider_millivolts(celsius - _DIFFERENCE_C) - self._divider_millivolts(celsius + _DIFFERENCE_C)
        ) / (2.0 * _DIFFERENCE_C)
        return self._supply_mv / ADC_CODES / millivolts_per_c

    def _divider_millivolts(self, celsius: float) -> float:
        kelvin = celsius + _ZERO_CELSIUS_K
        inverse_kelvin_from_25 = 1.0 / kelvin - 1.0 / (25.0 + _ZERO_CELSIUS_K)
        ohms = self._r25_ohm * math.exp(self._beta_k * inverse_kelvin_from_25)
        return self._supply_mv * ohms / (ohms + self._reference_ohm)


def _affine_scan(maps: np.ndarray, shifts: np.ndarray, start: np.ndarray) -> np.ndarray:
    """x_k = maps[k] x_(k-1) + shifts[k] from x_0 = start, for every k; maps
    (n, m, m) matrices, or (n, m) the diagonals of diagonal ones. The maps
    are composed in log2(n) passes (Hillis and Steele's prefix scan), each a
    few array operations however long the series."""
    diagonal = maps.ndim == 2
    maps, shifts = maps.copy(), shifts.copy()
    span = 1
    while span < len(maps):
        later = maps[span:]
        if diagonal:
            shifts[span:] += later * shifts[:-span]
            maps[span:] = later * maps[:-span]
        else:
            shifts[span:] += np.einsum("kij,kj->ki", later, shifts[:-span])
            maps[span:] = later @ maps[:-span]
        span *= 2
    return (maps * start if diagonal else maps @ start) + shifts
