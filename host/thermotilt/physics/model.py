"""The model: every registered term and hardware section with its values,
read from a TOML file and checked against the declarations."""

from __future__ import annotations

import reprlib
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any, TypeVar

from .batch import BatchSensor, population_entries, read_sensors
from .faults import Fault, read_faults, shown
from .parameters import ModelError, Parameter
from .terms import HARDWARE, REGISTRY, Section, Term

TERMS: tuple[str, ...] = tuple(REGISTRY)
AnyTerm = TypeVar("AnyTerm", bound=Term)
# A model file is a few kB; this stops a device file from being read forever.
_MAX_MODEL_BYTES = 1 << 20


def _declared(section: type[Section]) -> tuple[Parameter, ...]:
    return section.declared() if issubclass(section, Term) else section.parameters


# What each table of a model file may hold, enabled included.
DECLARATIONS: Mapping[str, tuple[Parameter, ...]] = MappingProxyType(
    {name: _declared(section) for name, section in {**HARDWARE, **REGISTRY}.items()}
)


@dataclass(frozen=True)
class Model:
    """The physical model: switchable terms, hardware constants and faults."""

    source: str
    terms: Mapping[str, Mapping[str, Any]]
    faults: tuple[Fault, ...] = ()
    # "chamber" and "sensor": properties of the hardware that no switch removes.
    constants: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    # A batch's sensors ([[sensors]]), each differing from the top level.
    sensors: tuple[BatchSensor, ...] = ()

    @classmethod
    def load(cls, path: str | Path | None = None) -> Model:
        """Read and validate a model file; None reads the packaged default."""
        if path is None:
            source = "default"
            text = resources.files("thermotilt").joinpath("models/default.toml").read_text("utf-8")
        else:
            source = str(path)
            text = _read_model_text(Path(path), source)
        try:
            document = tomllib.loads(text)
        except tomllib.TOMLDecodeError as error:
            raise ModelError(f"{source}: not valid TOML: {error}") from None
        except RecursionError:
            raise ModelError(f"{source}: not valid TOML: nested too deeply") from None
        return cls.from_document(document, source)

    @classmethod
    def from_document(cls, document: Mapping[str, Any], source: str) -> Model:
        """A model from a parsed model file: a table it omits takes its
        registered defaults; a table it has must be complete."""
        for section in document:
            if section not in DECLARATIONS and section not in ("faults", "sensors"):
                raise ModelError(f"{source}: unknown section [{shown(section)}]")
        tables = {name: _read_table(document, name, parameters, source) for name, parameters in DECLARATIONS.items()}
        terms = MappingProxyType({name: tables[name] for name in TERMS})
        return cls(
            source=source,
            terms=terms,
            faults=read_faults(document.get("faults", []), source),
            constants=MappingProxyType({name: tables[name] for name in HARDWARE}),
            sensors=read_sensors(document.get("sensors", []), terms, DECLARATIONS, source),
        )

    def with_population(self, count: int, seed: int) -> Model:
        """A copy whose batch is count sensors drawn about this model
        (batch.population_entries), in place of any [[sensors]] it had."""
        entries = population_entries(self.terms, self.constants["sensor"]["lsb_per_g"], count, seed)
        return replace(self, sensors=read_sensors(entries, self.terms, DECLARATIONS, f"{self.source} (drawn)"))

    @property
    def sensor_ids(self) -> tuple[str, ...]:
        return tuple(sensor.id for sensor in self.sensors)

    def for_sensor(self, sensor_id: str) -> Model:
        """The model of one sensor of the batch: its terms over the top
        level's, and no batch."""
        for sensor in self.sensors:
            if sensor.id == sensor_id:
                return replace(
                    self,
                    source=f"{self.source} (sensor {sensor_id})",
                    terms=MappingProxyType({**self.terms, **sensor.terms}),
                    sensors=(),
                )
        known = ", ".join(self.sensor_ids) or "none: the model has no [[sensors]]"
        raise ModelError(f"{self.source}: no sensor '{sensor_id}' (its sensors: {known})")

    def enabled(self, term: str) -> bool:
        self._check_term(term)
        return bool(self.terms[term]["enabled"])

    def with_terms(self, changes: Mapping[str, bool]) -> Model:
        """A copy with the named terms switched on (True) or off (False), in
        the batch's sensors too."""
        for term, enabled in changes.items():
            self._check_term(term)
            if not isinstance(enabled, bool):
                raise ModelError(f"{self.source}: [{term}] enabled must be true or false")

        def switched(terms: Mapping[str, Mapping[str, Any]]) -> MappingProxyType:
            return MappingProxyType(
                {
                    name: MappingProxyType({**values, "enabled": changes[name]}) if name in changes else values
                    for name, values in terms.items()
                }
            )

        sensors = tuple(replace(sensor, terms=switched(sensor.terms)) for sensor in self.sensors)
        return replace(self, terms=switched(self.terms), sensors=sensors)

    def with_faults(self, faults: Iterable[Fault]) -> Model:
        """A copy with these faults appended."""
        return replace(self, faults=self.faults + tuple(faults))

    def bound_terms(self, kind: type[AnyTerm]) -> list[AnyTerm]:
        """Every registered term of this kind (enabled or not), in registry
        order, as an object holding this model's values."""
        return [term(self.terms[name]) for name, term in REGISTRY.items() if issubclass(term, kind)]

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


def _read_table(
    document: Mapping[str, Any], section: str, parameters: tuple[Parameter, ...], source: str
) -> Mapping[str, Any]:
    if section not in document:
        return MappingProxyType({p.name: p.check(p.default, f"{source}: [{section}] {p.name}") for p in parameters})
    table = document[section]
    if not isinstance(table, dict):
        raise ModelError(f"{source}: [{section}] must be a table, got {reprlib.repr(table)}")
    expected = {p.name for p in parameters}
    for name in table:
        if name not in expected:
            raise ModelError(f"{source}: [{section}] unknown parameter '{shown(name)}'")
    values: dict[str, Any] = {}
    for parameter in parameters:
        if parameter.name not in table:
            raise ModelError(f"{source}: [{section}] missing parameter '{parameter.name}'")
        values[parameter.name] = parameter.check(table[parameter.name], f"{source}: [{section}] {parameter.name}")
    return MappingProxyType(values)
