"""The candidate effects discovery can name: each one a registered term of
the physics model (``thermotilt.physics.terms``), so the effect found is the
effect the twin then simulates. A candidate says which parameter it moves,
which channels it acts on and how large a change probes it; its effect on a
run is always computed by replaying the model with the term changed, never
by a formula of its own."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..physics import DECLARATIONS, Model, PerAxis
from ..physics.document import with_values
from .replay import ACCELERATION_CHANNELS, CHAMBER_CHANNELS


@dataclass(frozen=True)
class Candidate:
    """A physics term as a candidate: `parameter` is what discovery fits.

    per_axis: the parameter is a table keyed by channel ({x, y, z} for the
    axes, {inner, outer} for the thermistors) and each key is its own
    hypothesis on its own channel; otherwise one number acts on every
    channel. additive: the parameter adds to the model's value (a term the
    model has off starts from `null`); otherwise it is fitted as a value of
    its own (a time constant). probe: the change whose replayed effect is the
    candidate's regressor (small enough to stay linear, large enough to
    stand above float rounding)."""

    name: str
    parameter: str
    unit: str
    channels: tuple[str, ...]
    per_axis: bool
    probe: float
    additive: bool = True
    # False: the effect is not proportional to the change (a dead zone), so
    # an additive fit goes on from the linear one by Gauss-Newton steps.
    linear: bool = True
    null: float = 0.0
    # Where a candidate that is not additive is searched (its declared
    # bounds may include values a log-scale search cannot start from).
    search: tuple[float, float] | None = None

    @property
    def kind(self) -> Any:
        (kind,) = [p.kind for p in DECLARATIONS[self.name] if p.name == self.parameter]
        return kind

    @property
    def bounds(self) -> tuple[float, float]:
        """(low, high) the value must lie in: the parameter's declared
        bounds, or the search range."""
        if self.search is not None:
            return self.search
        declared = self.kind.bounds if isinstance(self.kind, PerAxis) else self.kind
        return declared.low, declared.high

    def value(self, model: Model, channel: str) -> float:
        """The parameter's value in the model on this channel's axis (`null`
        while the term is off)."""
        if not model.enabled(self.name):
            return self.null
        value = model.terms[self.name][self.parameter]
        return float(value[channel.lower()]) if self.per_axis else float(value)

    def changed(self, model: Model, values: Mapping[str, float]) -> Model:
        """The model with the term on and the parameter set, per channel
        (per-axis candidates) or to the one value given."""
        current = model.terms[self.name][self.parameter]
        if self.per_axis:
            table = {key: (float(current[key]) if model.enabled(self.name) else self.null) for key in self.kind.keys}
            for channel, value in values.items():
                table[channel.lower()] = value
            parameter: Any = table
        else:
            (parameter,) = set(values.values())
        return with_values(model, self.name, {"enabled": True, self.parameter: parameter})


CANDIDATES: tuple[Candidate, ...] = (
    Candidate(
        "sensor_lag",
        "time_constant_s",
        "s",
        ACCELERATION_CHANNELS,
        per_axis=False,
        probe=2.0,
        additive=False,
        search=(0.1, 3600.0),
    ),
    Candidate(
        "rate_sensitivity", "lsb_per_c_per_s", "LSB per degC/s", ACCELERATION_CHANNELS, per_axis=True, probe=100.0
    ),
    Candidate("hysteresis", "cooling_offset_lsb", "LSB", ACCELERATION_CHANNELS, per_axis=True, probe=10.0),
    Candidate("sensitivity_loss", "gain_loss_at_1g", "", ACCELERATION_CHANNELS, per_axis=False, probe=0.01),
    Candidate("scale_tempco", "ppm_per_c", "ppm/degC", ACCELERATION_CHANNELS, per_axis=True, probe=100.0),
    Candidate("cross_axis", "share", "", ACCELERATION_CHANNELS, per_axis=True, probe=0.001),
    Candidate("temperature_offset", "offset_c", "degC", ("temperature",), per_axis=False, probe=0.1),
    Candidate("drive_dead_zone", "threshold_duty", "", CHAMBER_CHANNELS, per_axis=False, probe=0.02, linear=False),
    # From a small passive heatsink (5 K/W) to the declared cold plate.
    Candidate(
        "heatsink",
        "ambient_conductance_w_per_k",
        "W/K",
        CHAMBER_CHANNELS,
        per_axis=False,
        probe=-0.5,
        additive=False,
        search=(0.2, 50.0),
    ),
    Candidate("thermistor_offset", "offset_c", "degC", CHAMBER_CHANNELS, per_axis=True, probe=0.1),
    Candidate(
        "joule_heating", "exponent", "", CHAMBER_CHANNELS, per_axis=False, probe=-0.1, additive=False, search=(1.0, 2.0)
    ),
)
BY_NAME: Mapping[str, Candidate] = {candidate.name: candidate for candidate in CANDIDATES}

# What separates two candidates that explain the same residual on one run.
_EXPERIMENTS: Mapping[frozenset[str], str] = {
    frozenset({"sensor_lag", "rate_sensitivity"}): (
        "a run with holds after each temperature change (a staircase, `simulate cycle`) or "
        "with a second ramp rate: a lag goes on acting for its time constant after the "
        "temperature stops, a rate term stops with it"
    ),
    frozenset({"hysteresis", "rate_sensitivity"}): (
        "a run with long holds while warming and while cooling: an offset between the sets "
        "stays through a hold, a rate term vanishes in it"
    ),
    frozenset({"scale_tempco", "sensitivity_loss"}): (
        "positions at several inclinations on the same axis through the same temperatures"
    ),
    frozenset({"heatsink", "joule_heating"}): (
        "holds at several duties in both directions with the outer face logged: the heatsink "
        "acts on the outer face through the room, Joule heat on both faces and the same way "
        "heating and cooling"
    ),
    frozenset({"drive_dead_zone", "joule_heating"}): (
        "holds near the room's temperature (small duties) and far from it (large duties): a "
        "dead zone takes the same share off every duty, Joule heating matters at large ones"
    ),
    frozenset({"temperature_offset", "thermistor_offset"}): (
        "a long run from rest through large temperature changes with both faces logged "
        "(`simulate cycle`): the inner reading's own offset then shows against the chamber's "
        "dynamics, which a temperature offset of the sensor leaves alone; or a reference "
        "thermometer on the sensor's face"
    ),
    frozenset({"drive_dead_zone", "heatsink"}): (
        "holds near the room's temperature (small duties) and far from it: a dead zone acts "
        "at small duties, the heatsink where the outer face is far from the room"
    ),
}


def experiment(names: frozenset[str]) -> str:
    """The experiment that tells these candidates apart."""
    if names in _EXPERIMENTS:
        return _EXPERIMENTS[names]
    return (
        "a run that changes what the candidates depend on differently: other inclinations, "
        "other ramp rates, longer holds"
    )
