"""The drift surfaces: the paper's Equation (3),
``f(x, y) = p00 + p10*x + p01*y + p20*x**2 + p11*x*y + p02*y**2``, with x the
temperature and y the inclination term, one per set (W warming, C cooling)
and axis (X, Y, Z), the paper's own coefficients, and the ID of the sensor a
table is fitted for. Imports nothing of the serial protocol: the physics
model, the fit and the EEPROM block all use it.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import NamedTuple

SETS = ("W", "C")
SET_NAMES = {"W": "warming", "C": "cooling"}
# The manufacturer's reference temperature, at which the paper takes each
# position's reading as free of drift (section 3.3).
REFERENCE_C = 25.0
# The sensor a table is fitted for: an ID of up to 8 characters, which the
# EEPROM block carries and the board compares with its own.
SENSOR_ID_LENGTH = 8
_SENSOR_ID = re.compile(rf"[A-Za-z0-9_-]{{0,{SENSOR_ID_LENGTH}}}")
AXES = ("X", "Y", "Z")
# How the firmware holds a table: 36 float32 (lib/Compensation).
_FLOAT32_TABLE = struct.Struct("<36f")


class Surface(NamedTuple):
    p00: float
    p10: float
    p01: float
    p20: float
    p11: float
    p02: float

    def evaluate(self, x: float, y: float) -> float:
        return self.p00 + self.p10 * x + self.p01 * y + self.p20 * x * x + self.p11 * x * y + self.p02 * y * y


ZERO_SURFACE = Surface(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
COEFFICIENT_NAMES = Surface._fields


@dataclass(frozen=True)
class CoefficientTable:
    """Six surfaces keyed by (set, axis), e.g. ("W", "X")."""

    surfaces: Mapping[tuple[str, str], Surface]

    def __post_init__(self) -> None:
        expected = {(s, a) for s in SETS for a in AXES}
        if set(self.surfaces) != expected:
            raise ValueError(f"coefficient table needs exactly the surfaces {sorted(expected)}")
        for key, surface in self.surfaces.items():
            if not all(math.isfinite(value) for value in surface):
                raise ValueError(f"surface {key} has a non-finite coefficient")

    def surface(self, set_: str, axis: str) -> Surface:
        return self.surfaces[(set_, axis)]

    def values(self) -> list[float]:
        """The 36 coefficients in block order."""
        return [value for s in SETS for a in AXES for value in self.surfaces[(s, a)]]

    def to_float32(self) -> CoefficientTable:
        """The table as the firmware holds it (float32)."""
        return table_from_values(_FLOAT32_TABLE.unpack(_FLOAT32_TABLE.pack(*self.values())))


def table_from_values(values: Iterable[float]) -> CoefficientTable:
    values = [float(value) for value in values]
    if len(values) != 36:
        raise ValueError(f"need 36 coefficients, got {len(values)}")
    surfaces = {}
    for index, key in enumerate((s, a) for s in SETS for a in AXES):
        surfaces[key] = Surface(*values[6 * index : 6 * index + 6])
    return CoefficientTable(surfaces)


# Sensors 2018, 18, 2536: Table 2 (X axis) and Table 3 (Y axis), point
# estimates as printed. The X cooling p01 (7.23e-4) lies outside its own
# printed confidence bounds (7.535e-4, 7.91e-4); it is kept as printed. The
# paper gives Z against the X and Y inclinations (Tables 4, 5), which do not
# fit one Z surface, so Z defaults to no correction.
PAPER_DEFAULTS = CoefficientTable(
    {
        ("W", "X"): Surface(571.5, -20.23, 1.569e-3, -0.1044, -6.936e-5, 6.327e-9),
        ("C", "X"): Surface(582.9, -21.29, 7.23e-4, -7.898e-2, -6.362e-5, -7.354e-8),
        ("W", "Y"): Surface(354.0, -13.96, 5.747e-3, -2.931e-3, -1.915e-4, -5.363e-8),
        ("C", "Y"): Surface(338.1, -12.82, 4.439e-3, -3.299e-2, -1.579e-4, -1.455e-8),
        ("W", "Z"): ZERO_SURFACE,
        ("C", "Z"): ZERO_SURFACE,
    }
)


def sensor_id_problem(text: str) -> str | None:
    """Why text cannot be a sensor ID (None: it can). An ID is up to 8
    letters, digits, '_' or '-' (lib/Compensation's isValidSensorId); the
    empty text means none."""
    if _SENSOR_ID.fullmatch(text):
        return None
    if len(text) > SENSOR_ID_LENGTH:
        return f"sensor ID {text!r} has {len(text)} characters, at most {SENSOR_ID_LENGTH}"
    return f"sensor ID {text!r} may hold only letters, digits, '_' and '-'"
