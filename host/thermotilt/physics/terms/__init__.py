"""The registry of physical effects: every term is a class declaring its
parameters once (see ..parameters) and what it contributes — a chamber term
its heat flows into the chamber's nodes, a sensor term the stage of the
sensor it acts on. Registration order is the order of TERMS, of the model
file and of the docs tables; within a sensor stage terms act in that order.

Importing this package registers the chamber terms and then the sensor terms.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from ..parameters import SWITCH, Parameter


class Section:
    """A table of the model file: a name and its declared parameters."""

    name: ClassVar[str]
    summary: ClassVar[str]
    parameters: ClassVar[tuple[Parameter, ...]] = ()

    def __init__(self, values: Mapping[str, Any]) -> None:
        self.values = values


class Term(Section):
    """A switchable physical effect; `enabled` is its first parameter."""

    enabled_by_default: ClassVar[bool] = True

    def __init__(self, values: Mapping[str, Any]) -> None:
        super().__init__(values)
        self.enabled: bool = values["enabled"]

    @classmethod
    def declared(cls) -> tuple[Parameter, ...]:
        switch = Parameter(
            "enabled",
            SWITCH,
            cls.enabled_by_default,
            "on by default" if cls.enabled_by_default else "a candidate: off by default",
        )
        return (switch, *cls.parameters)


@dataclass(frozen=True)
class HeatFlows:
    """What a chamber term adds to the chamber's heat balance.

    nodes: heat capacity (J/K) of a node the term adds; conductances: W/K
    between two nodes ("inner", "outer", "ambient"); drive: W into the inner
    and outer nodes at a mean duty (0..1) and direction (+1 heats the inner
    face, -1 cools it), constant over a step; seen_duty: the duty the cell
    sees for the one the bridge is given, before any drive acts on it."""

    nodes: Mapping[str, float] = field(default_factory=dict)
    conductances: Mapping[tuple[str, str], float] = field(default_factory=dict)
    drive: Callable[[float, int], tuple[float, float]] | None = None
    seen_duty: Callable[[float], float] | None = None


class ChamberTerm(Term):
    """A chamber effect: its heat flows, or how the thermistors read."""

    def heat_flows(self) -> HeatFlows:
        return self.flows() if self.enabled else self.flows_when_off()

    def flows(self) -> HeatFlows:
        """The term's heat flows while it is enabled."""
        return HeatFlows()

    def flows_when_off(self) -> HeatFlows:
        return HeatFlows()

    def thermistor_lag_s(self) -> float | None:
        """The thermistors' first-order time constant, if this term sets one."""
        return None

    def reading_offsets_c(self) -> tuple[float, float] | None:
        """What the inner and outer thermistors read above their own
        temperature, if this term shifts them."""
        return None


# The sensor's stages in the order it runs them, with what a term bound to
# each stage is called with and returns.
SENSOR_STAGES: Mapping[str, str] = {
    "die": "(previous die degC, target degC, dt s) -> die degC",
    "reported": "(die degC) -> the temperature the sensor reports, degC",
    "structure": "(previous structure degC, reported degC, dt s) -> structure degC, the "
    "temperature the drift is evaluated at; with no term here the reported one",
    "gravity": "(incl x deg, incl y deg) -> acceleration (x, y, z) LSB",
    "ideal": "(acceleration x, y, z) -> ideal acceleration (x, y, z) LSB",
    "drift": "(set, structure degC, ideal x, y, z) -> thermal drift (x, y, z) LSB",
    "scale": "(reported degC, ideal x, y, z) -> additive error (x, y, z) LSB of a temperature-dependent scale factor",
    "error": "(set, reported degC, rate degC/s, dt s, mounting) -> additive error (x, y, z) "
    "LSB; mounting counts the table's positions from 0, one more at every move",
    "register": "(temperature LSB, unrounded) -> temperature LSB",
}


@dataclass(frozen=True)
class SensorContext:
    """What a sensor term may need to bind: hardware constants, the seeded
    streams of draws shared by noise and dither (normal() and uniform() give
    the next draw, normals(n) and uniforms(n) the next n), and a term's own
    seeded generator by name, so that switching one term leaves every other
    term's draws as they were."""

    lsb_per_g: float
    normal: Callable[[], float]
    uniform: Callable[[], float]
    normals: Callable[[int], np.ndarray]
    uniforms: Callable[[int], np.ndarray]
    generator: Callable[[str], np.random.Generator]


class SensorTerm(Term):
    """A sensor effect acting on one stage of SENSOR_STAGES."""

    stage: ClassVar[str]

    def bind(self, context: SensorContext) -> Callable[..., Any] | None:
        """The stage function of this term, or None when it does nothing."""
        return self.bound(context) if self.enabled else None

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        """The stage function of this term while it is enabled."""
        raise NotImplementedError

    def bind_series(self, context: SensorContext) -> Callable[..., Any] | None:
        """The stage function for a series of steps (sensor_series): called
        with arrays over steps that share their set and mounting. The scalar
        function serves as it is, numpy broadcasting its arithmetic; a term
        that draws a number per step overrides this to draw one per element,
        and a lag ("die", "structure") to take (start, targets, dt_s) and
        give the value after every step."""
        return self.bind(context)


HARDWARE: dict[str, type[Section]] = {}
REGISTRY: dict[str, type[Term]] = {}


def hardware(cls: type[Section]) -> type[Section]:
    HARDWARE[cls.name] = cls
    return cls


def register(cls: type[Term]) -> type[Term]:
    if cls.name in REGISTRY or cls.name in HARDWARE:
        raise ValueError(f"term {cls.name} registered twice")
    if isinstance(cls, type) and issubclass(cls, SensorTerm) and cls.stage not in SENSOR_STAGES:
        raise ValueError(f"term {cls.name}: unknown stage {cls.stage}")
    REGISTRY[cls.name] = cls
    return cls


from . import chamber, sensor, sensor_candidates  # noqa: E402,F401  (registers the terms)
