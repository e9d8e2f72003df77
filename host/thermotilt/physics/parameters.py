"""Parameter declarations: what a model file may hold, checked once at load.

A term or a hardware section declares each parameter once with its kind
(bounds, a per-axis table, drift surfaces or a switch), its default, where
that default comes from and why its bounds are what they are; model-file
validation and the docs/physics-model.md tables both read these declarations.
"""

from __future__ import annotations

import math
import reprlib
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from ..surfaces import AXES, SETS


class ModelError(ValueError):
    """A model file, term switch or fault that cannot be used."""


def number(value: Any, where: str) -> float:
    """A TOML integer or float as a float; integers beyond float's range are
    infinite."""
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        raise ModelError(f"{where}: expected a number, got {reprlib.repr(value)}")
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def finite_number(value: Any, where: str) -> float:
    checked = number(value, where)
    if not math.isfinite(checked):
        raise ModelError(f"{where}: expected a finite number, got {reprlib.repr(value)}")
    return checked


@dataclass(frozen=True)
class Bounds:
    """The physically plausible range of a number in the model file."""

    low: float
    high: float
    unit: str = ""
    # True: the value must lie above low, not on it.
    low_exclusive: bool = False

    def check(self, value: Any, where: str) -> float:
        checked = number(value, where)
        below = checked <= self.low if self.low_exclusive else checked < self.low
        if below or not checked <= self.high:
            raise ModelError(f"{where}: must be {self}, got {reprlib.repr(value)}")
        return checked

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"{'>' if self.low_exclusive else '>='} {self.low:g} and <= {self.high:g}{unit}"


@dataclass(frozen=True)
class PerAxis:
    """A table of numbers within the same bounds, one per key: the sensor's
    axes {x, y, z} unless the parameter names other keys (the chamber's
    faces {inner, outer})."""

    bounds: Bounds
    keys: tuple[str, ...] = ("x", "y", "z")

    def check(self, value: Any, where: str) -> Any:
        if not isinstance(value, dict) or set(value) != set(self.keys):
            shape = ", ".join(f"{key} = .." for key in self.keys)
            raise ModelError(f"{where}: expected a table {{{shape}}}, got {reprlib.repr(value)}")
        return MappingProxyType({key: self.bounds.check(value[key], f"{where}.{key}") for key in self.keys})


class Switch:
    """A term's `enabled`: true or false."""

    def check(self, value: Any, where: str) -> bool:
        if not isinstance(value, bool):
            raise ModelError(f"{where}: expected true or false, got {reprlib.repr(value)}")
        return value


@dataclass(frozen=True)
class Surfaces:
    """ "paper" or a table of drift surfaces per set and axis, each term
    p<i><j> (multiplying T^i a^j) within its own bounds."""

    term_names: tuple[str, ...]
    term_bounds: tuple[Bounds, ...]

    def check(self, value: Any, where: str) -> Any:
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
                if not isinstance(terms, list) or len(terms) != len(self.term_names):
                    raise ModelError(f"{where}.{set_}.{axis}: expected 6 numbers {', '.join(self.term_names)}")
                surfaces[set_][axis] = tuple(
                    bounds.check(term, f"{where}.{set_}.{axis} {name}")
                    for term, name, bounds in zip(terms, self.term_names, self.term_bounds)
                )
        return MappingProxyType(surfaces)


ParameterKind = Bounds | PerAxis | Surfaces | Switch


@dataclass(frozen=True)
class Parameter:
    """One number (or table) of the model file: its kind, its default, where
    the default comes from, and why the bounds are what they are."""

    name: str
    kind: ParameterKind
    default: Any
    source: str
    why: str = ""

    def check(self, value: Any, where: str) -> Any:
        return self.kind.check(value, where)


SWITCH = Switch()
