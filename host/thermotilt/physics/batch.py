"""Several sensors in one model file: ``[[sensors]]`` tables, each an ``id``
and any sensor term's parameters in the top level's layout, overriding the
top level's values for that sensor alone (docs/physics-model.md, "A batch
of sensors")."""

from __future__ import annotations

import reprlib
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from ..surfaces import REFERENCE_C, sensor_id_problem
from .parameters import ModelError, Parameter
from .terms import REGISTRY, SensorTerm

SENSOR_TERMS = frozenset(name for name, term in REGISTRY.items() if issubclass(term, SensorTerm))


@dataclass(frozen=True)
class BatchSensor:
    """One sensor of a batch: its ID and the term tables it overrides,
    complete (the top level's values where it gives none)."""

    id: str
    terms: Mapping[str, Mapping[str, Any]]


def check_sensor_id(text: Any, where: str) -> str:
    """An ID the IMU can store (wire.coefficients' rule, lib/Compensation's)."""
    if not isinstance(text, str) or not text:
        raise ModelError(f"{where}: a sensor table needs an id, got {reprlib.repr(text)}")
    problem = sensor_id_problem(text)
    if problem:
        raise ModelError(f"{where}: {problem}")
    return text


def read_sensors(
    entries: Any,
    terms: Mapping[str, Mapping[str, Any]],
    declarations: Mapping[str, tuple[Parameter, ...]],
    source: str,
) -> tuple[BatchSensor, ...]:
    """The [[sensors]] tables over the top level's term tables."""
    if not isinstance(entries, list) or not all(isinstance(entry, dict) for entry in entries):
        raise ModelError(f"{source}: sensors must be an array of tables [[sensors]]")
    sensors: list[BatchSensor] = []
    for number, entry in enumerate(entries, start=1):
        where = f"{source}: [[sensors]] #{number}"
        sensor_id = check_sensor_id(entry.get("id"), where)
        where = f"{source}: [[sensors]] {sensor_id}"
        if any(sensor.id == sensor_id for sensor in sensors):
            raise ModelError(f"{where}: listed twice")
        tables = {}
        for name, override in entry.items():
            if name == "id":
                continue
            if name not in SENSOR_TERMS:
                known = "a chamber term or hardware section" if name in declarations else "not a term"
                raise ModelError(
                    f"{where}: [{name}] is {known}; a sensor's table overrides sensor terms only "
                    f"({', '.join(sorted(SENSOR_TERMS))})"
                )
            if not isinstance(override, dict):
                raise ModelError(f"{where}: [{name}] must be a table, got {reprlib.repr(override)}")
            parameters = {parameter.name: parameter for parameter in declarations[name]}
            unknown = [key for key in override if key not in parameters]
            if unknown:
                raise ModelError(f"{where}: [{name}] unknown parameter '{unknown[0]}'")
            values = dict(terms[name])
            for key, value in override.items():
                values[key] = parameters[key].check(value, f"{where}: [{name}] {key}")
            tables[name] = MappingProxyType(values)
        sensors.append(BatchSensor(sensor_id, MappingProxyType(tables)))
    return tuple(sensors)


# A drawn population's spread from one unit to the next, per sensor and axis:
# - the drift's temperature dependence scaled by 1 + N(0, DRIFT_SHAPE_SPREAD):
#   assumed; 250 MPU-9250 on a Peltier rig fell in 6 clusters of thermal
#   profile (Reginya et al., CEUR-WS Vol-2278), not one shape;
# - a further linear tempco N(0, TEMPCO_SPREAD_MG_PER_C) on X and Y: assumed,
#   a third of the largest bias tempco Martinez et al. found in six LIS3DSH
#   (Sensors 2021, 21, 3117: up to 1.3 mg/degC);
# - the zero-g offset N(0, ZERO_G_SPREAD_MG) per axis: the LSM9DS0 datasheet's
#   typical zero-g level offset accuracy, which ST defines as the population's
#   standard deviation;
# - the temperature output's offset N(0, TEMPERATURE_OFFSET_SPREAD_C) about the
#   model's: assumed; the die sensor is not calibrated (paper section 3.1).
# Each change keeps the drift zero at 25 degC, where the paper references it.
DRIFT_SHAPE_SPREAD = 0.25
TEMPCO_SPREAD_MG_PER_C = 0.43
ZERO_G_SPREAD_MG = 60.0
TEMPERATURE_OFFSET_SPREAD_C = 1.0
DRAWN_ID_PREFIX = "TT-"


def population_entries(terms: Mapping[str, Mapping[str, Any]], lsb_per_g: float, count: int, seed: int) -> list[dict]:
    """[[sensors]] tables for count sensors drawn about the model's (IDs
    TT-01, TT-02, ...), seeded: the same seed draws the same batch."""
    from .terms.sensor import coefficient_table_of

    table = coefficient_table_of(terms["drift"]["coefficients"])
    lsb_per_mg = lsb_per_g / 1000.0
    entries = []
    for index in range(count):
        rng = np.random.default_rng([seed, index])
        coefficients: dict[str, dict[str, list[float]]] = {set_name: {} for set_name in ("W", "C")}
        shapes = 1.0 + DRIFT_SHAPE_SPREAD * rng.standard_normal(3)
        tempcos = TEMPCO_SPREAD_MG_PER_C * lsb_per_mg * rng.standard_normal(3) * np.array([1.0, 1.0, 0.0])
        for set_name in coefficients:
            for axis, shape, tempco in zip("XYZ", shapes.tolist(), tempcos.tolist()):
                p00, p10, p01, p20, p11, p02 = table.surface(set_name, axis)
                scaled = (p10 * shape + tempco, p20 * shape, p11 * shape)
                coefficients[set_name][axis] = [
                    p00 - REFERENCE_C * (scaled[0] - p10) - REFERENCE_C**2 * (scaled[1] - p20),
                    scaled[0],
                    p01 - REFERENCE_C * (scaled[2] - p11),
                    scaled[1],
                    scaled[2],
                    p02,
                ]
        offsets = ZERO_G_SPREAD_MG * lsb_per_mg * rng.standard_normal(3)
        measuring = terms["measuring_offset"]
        entries.append(
            {
                "id": f"{DRAWN_ID_PREFIX}{index + 1:02d}",
                "drift": {"coefficients": coefficients},
                "measuring_offset": {
                    kind: {axis: measuring[kind][axis] + offset for axis, offset in zip("xyz", offsets.tolist())}
                    for kind in ("warming_lsb", "cooling_lsb")
                },
                "temperature_offset": {
                    "offset_c": terms["temperature_offset"]["offset_c"]
                    + TEMPERATURE_OFFSET_SPREAD_C * float(rng.standard_normal())
                },
            }
        )
    return entries
