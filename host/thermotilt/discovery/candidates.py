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
from .replay import ACCELERATION_CHANNELS


@dataclass(frozen=True)
class Candidate:
    """A physics term as a candidate: `parameter` is what discovery fits.

    per_axis: the parameter is an {x, y, z} table and each axis is its own
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
    null: float = 0.0
    # Where a candidate that is not additive is searched (its declared
    # bounds may include values a log-scale search cannot start from).
    search: tuple[float, float] | None = None

    @property
    def bounds(self) -> tuple[float, float]:
        """(low, high) the value must lie in: the parameter's declared
        bounds, or the search range."""
        if self.search is not None:
            return self.search
        (kind,) = [p.kind for p in DECLARATIONS[self.name] if p.name == self.parameter]
        declared = kind.bounds if isinstance(kind, PerAxis) else kind
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
            table = {axis: (float(current[axis]) if model.enabled(self.name) else self.null)
                     for axis in "xyz"}
            for channel, value in values.items():
                table[channel.lower()] = value
            parameter: Any = table
        else:
            (parameter,) = set(values.values())
        return with_values(model, self.name, {"enabled": True, self.parameter: parameter})


CANDIDATES: tuple[Candidate, ...] = (
    Candidate("sensor_lag", "time_constant_s", "s", ACCELERATION_CHANNELS, per_axis=False,
              probe=2.0, additive=False, search=(0.1, 3600.0)),
    Candidate("rate_sensitivity", "lsb_per_c_per_s", "LSB per degC/s", ACCELERATION_CHANNELS,
              per_axis=True, probe=100.0),
    Candidate("hysteresis", "cooling_offset_lsb", "LSB", ACCELERATION_CHANNELS, per_axis=True,
              probe=10.0),
    Candidate("sensitivity_loss", "gain_loss_at_1g", "", ACCELERATION_CHANNELS, per_axis=False,
              probe=0.01),
    Candidate("scale_tempco", "ppm_per_c", "ppm/degC", ACCELERATION_CHANNELS, per_axis=True,
              probe=100.0),
    Candidate("cross_axis", "share", "", ACCELERATION_CHANNELS, per_axis=True, probe=0.001),
    Candidate("temperature_offset", "offset_c", "degC", ("temperature",), per_axis=False,
              probe=0.1),
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
}


def experiment(names: frozenset[str]) -> str:
    """The experiment that tells these candidates apart."""
    if names in _EXPERIMENTS:
        return _EXPERIMENTS[names]
    return ("a run that changes what the candidates depend on differently: other inclinations, "
            "other ramp rates, longer holds")
