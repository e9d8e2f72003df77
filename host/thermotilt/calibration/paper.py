"""The published fits of Sensors 2018, 18, 2536 (Tables 2-5, section 4.3), as
data, once: tests, make demo's paper comparison and `thermotilt compare` read them from here.

Each coefficient comes with the 95 % confidence bounds Matlab's cftool
printed. Two entries of Table 2's cooling column are misprinted and kept as
printed, with the reading that makes them consistent in ``PRINTING_ERRORS``:
p01 = 7.23e-4 lies outside its own bounds (7.535e-4, 7.91e-4), whose
midpoint 7.723e-4 is the likely value; p02's upper bound is printed
"-7144 x 10^-8" for -7.144e-8.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from ..surfaces import COEFFICIENT_NAMES


@dataclass(frozen=True)
class Coefficient:
    value: float
    lower: float
    upper: float


@dataclass(frozen=True)
class PublishedFit:
    """One column of Tables 2-5: a surface with its goodness of fit."""

    coefficients: Mapping[str, Coefficient]
    sse: float
    r_squared: float
    adjusted_r_squared: float
    rmse: float


def _fit(terms: list[tuple[float, float, float]], sse: float, r2: float, adjusted: float, rmse: float) -> PublishedFit:
    coefficients = {name: Coefficient(*values) for name, values in zip(COEFFICIENT_NAMES, terms, strict=True)}
    return PublishedFit(MappingProxyType(coefficients), sse, r2, adjusted, rmse)


# (table axis, set) -> fit. "X" and "Y" are Tables 2 and 3; "ZX" and "ZY"
# (Tables 4, 5) fit Z against the X and Y inclinations.
TABLES: Mapping[tuple[str, str], PublishedFit] = MappingProxyType(
    {
        ("X", "W"): _fit(
            [
                (571.5, 571.5, 571.6),
                (-20.23, -20.24, -20.23),
                (1.569e-3, 1.56e-3, 1.579e-3),
                (-0.1044, -0.1045, -0.1042),
                (-6.936e-5, -6.972e-5, -6.9e-5),
                (6.327e-9, 5.275e-9, 7.38e-9),
            ],
            2.739e6,
            0.9998,
            0.9998,
            6.256,
        ),
        ("X", "C"): _fit(
            [
                (582.9, 582.7, 583.1),
                (-21.29, -21.3, -21.27),
                (7.23e-4, 7.535e-4, 7.91e-4),
                (-7.898e-2, -7.933e-2, -7.863e-2),
                (-6.362e-5, -6.435e-5, -6.29e-5),
                (-7.354e-8, -7.563e-8, -7144e-8),
            ],
            1.043e7,
            0.9992,
            0.9992,
            12.32,
        ),
        ("Y", "W"): _fit(
            [
                (354.0, 353.8, 354.2),
                (-13.96, -13.98, -13.95),
                (5.747e-3, 5.724e-3, 5.77e-3),
                (-2.931e-3, -3.369e-3, -2.493e-3),
                (-1.915e-4, -1.925e-4, -1.91e-4),
                (-5.363e-8, -5.633e-8, -5.09e-8),
            ],
            2.381e7,
            0.9954,
            0.9954,
            17.37,
        ),
        ("Y", "C"): _fit(
            [
                (338.1, 337.9, 338.2),
                (-12.82, -12.83, -12.81),
                (4.439e-3, 4.426e-3, 4.453e-3),
                (-3.299e-2, -3.325e-2, -3.27e-2),
                (-1.579e-4, -1.584e-4, -1.57e-4),
                (-1.455e-8, -1.613e-8, -1.29e-8),
            ],
            7.744e6,
            0.9984,
            0.9984,
            10.03,
        ),
        ("ZX", "W"): _fit(
            [
                (1166.0, 1131.0, 1201.0),
                (1.856, 1.659, 2.052),
                (-0.1738, -0.1788, -0.1688),
                (-0.06327, -0.06462, -0.06192),
                (-1.532e-5, -2.831e-5, -2.32e-6),
                (6.387e-6, 6.212e-6, 6.562e-6),
            ],
            1.675e8,
            0.456,
            0.456,
            48.92,
        ),
        ("ZX", "C"): _fit(
            [
                (1499.0, 1453.0, 1546.0),
                (-1.729, -1.994, -1.463),
                (-0.2198, -0.2264, -0.2132),
                (0.02335, 0.02152, 0.02518),
                (1.106e-5, -6.469e-6, 2.858e-5),
                (7.801e-6, 7.569e-6, 8.033e-6),
            ],
            2.895e8,
            0.03082,
            0.03074,
            64.9,
        ),
        ("ZY", "W"): _fit(
            [
                (-195.6, -250.4, -140.7),
                (-1.516, -1.832, -1.201),
                (0.04766, 0.0399, 0.05543),
                (-0.05595, -0.05815, -0.05375),
                (1.354e-4, 1.145e-4, 1.563e-4),
                (-2.013e-6, -2.28e-6, -1.74e-6),
            ],
            6.002e8,
            0.1251,
            0.125,
            87.21,
        ),
        ("ZY", "C"): _fit(
            [
                (-53.65, -76.05, -31.26),
                (-4.726, -4.855, -4.597),
                (0.009953, 0.006769, 0.01314),
                (0.03852, 0.03763, 0.03941),
                (8.257e-5, 7.409e-5, 9.104e-5),
                (-3.241e-7, -4.363e-7, -2.12e-7),
            ],
            8.949e7,
            0.6632,
            0.6632,
            34.11,
        ),
    }
)

# (table axis, set, term, part) -> the consistent reading of a misprint.
PRINTING_ERRORS: Mapping[tuple[str, str, str, str], float] = MappingProxyType(
    {
        ("X", "C", "p01", "value"): 7.723e-4,
        ("X", "C", "p02", "upper"): -7.144e-8,
    }
)

# Section 4.3: RMS error against the 25 degC value, LSB, before -> after.
FIELD_RMS_LSB: Mapping[tuple[str, str], tuple[float, float]] = MappingProxyType(
    {
        ("field-warming", "X"): (284.0, 11.0),
        ("field-warming", "Y"): (161.0, 8.0),
        ("field-cooling", "X"): (122.0, 4.0),
        ("field-cooling", "Y"): (70.0, 4.0),
    }
)
# Which set's surfaces compensated each field test (section 4.3).
FIELD_TEST_SET: Mapping[str, str] = MappingProxyType({"field-warming": "W", "field-cooling": "C"})


def field_rms_lsb(scenario: str | None) -> dict[tuple[str, str], tuple[float, float]] | None:
    """Section 4.3's RMS (before, after) by (set, axis) for a twin run of
    that field test, or None for any other run."""
    if scenario not in FIELD_TEST_SET:
        return None
    return {
        (FIELD_TEST_SET[scenario], axis): FIELD_RMS_LSB[(scenario, axis)]
        for axis in ("X", "Y")
        if (scenario, axis) in FIELD_RMS_LSB
    }
