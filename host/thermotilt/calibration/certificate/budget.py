"""The uncertainty budget of one band (GUM, JCGM 100:2008): its components,
Type A and Type B, each with its value, distribution, divisor, sensitivity
coefficient, contribution in degrees, degrees of freedom and source, and
their combination (u_c, Welch-Satterthwaite's nu_eff, G.4.1; Student's k
at p = 95 %, G.3; U to two significant digits, 7.2.6).

The Type B components (4.3) are listed even when negligible or not added,
with the reason. A Type B component taken as known bounds has infinite
degrees of freedom (G.4.2), written ``None`` in JSON.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats
from statsmodels.regression.linear_model import OLS
from statsmodels.tools import add_constant

from ...set_blend import FIRMWARE_TRANSITION_C
from ...surfaces import Surface
from ..dataset import reading_at_25
from ..fit import SurfaceFit, hac_lags
from ..newey_west import hac_panel_covariance
from .crossing import Crossing
from .errors import AxisErrors
from .stability import NOT_EVALUATED, PreviousCalibration

COVERAGE_PROBABILITY = 0.95
SQRT3 = math.sqrt(3.0)
# The change is a difference of two readings with independent rate and resolution errors.
TWO_READINGS = math.sqrt(2.0)
# The LSM9DS0's temperature output between calibration and field: the
# datasheet gives its scale (8 LSB/degC) but no accuracy or stability; the
# paper found an offset it corrected by a constant (section 2) and ~0.5 degC
# between programmed and measured face temperatures (section 3.1). Assumed:
# the reading's offset shifts by at most this much between the chamber and
# the field (soldering, mounting stress, supply); a lab confirms it with a
# reference thermometer at installation.
TEMPERATURE_SHIFT_C = 0.5
# Validity: the IMU temperature's rate in the field, at most this (the
# paper's sun-lit box rose 39 degC in 3 h, 0.22 degC/min; make demo's
# compressed warming day 0.65 degC/min).
FIELD_RATE_LIMIT_C_PER_MIN = 1.0
RESOLUTION_LSB = 1.0
# Not verified against DocID024763 here: ST gives the LSM9DS0's
# sensitivity (0.061 mg/LSB at +-2 g) as typical only; assumed tolerance
# of the conversion's scale, and the temperature coefficient ST's
# accelerometers of that generation state as typical.
SENSITIVITY_TOLERANCE = 0.05
SENSITIVITY_TEMPCO_PER_C = 1e-4


# The Type B components' sources, as the budget prints them.
SHIFT_SOURCE = (
    "assumed bound on the LSM9DS0 temperature output's offset shift between chamber and field (no "
    "datasheet accuracy figure; paper sections 2, 3.1): one shift moves both readings, so the change "
    "takes the difference of |df/dT| at the reading and at the installation (either set), largest in "
    "the cell, x d tilt/d a"
)
SET_SELECTION_SOURCE = (
    "after a warming/cooling reversal the device blends its sets' surfaces over w_d = "
    f"{FIRMWARE_TRANSITION_C:g} degC of its filtered temperature (lib/Compensation SetBlend) and the sensor "
    "crosses over its own width w: two stop operators crossing the same path from the same end differ "
    "by at most m = 1 - min(w, w_d) / max(w, w_d) of the way, so the error lies between 0 and "
    "m |f_W - f_C| (largest in the cell), its sign unknown; uncorrected, mean and spread together give "
    "half-width m |f_W - f_C| / sqrt(3); "
)
RESOLUTION_SOURCE = (
    "1 LSB of the 16-bit output (0.061 mg at +-2 g, LSM9DS0 datasheet): half-width 0.5 LSB (GUM F.2.2.1), "
    "in the reading and in the installation reading (sensitivity x sqrt(2))"
)
TOLERANCE_SOURCE = (
    "the LSB-to-degree conversion's nominal 0.061 mg/LSB (typical only in the LSM9DS0 datasheet; "
    f"+-{SENSITIVITY_TOLERANCE:.0%} assumed) scales the tilt error: sensitivity the cell's Type A u"
)
TEMPCO_SOURCE = (
    f"+-{SENSITIVITY_TEMPCO_PER_C:.2%}/degC (typical of ST's accelerometers; assumed for the LSM9DS0) "
    "x |T - T0| x |a|, largest in the cell: not added, the surfaces' T x a term (p11) compensates it "
    "and what they leave is in the between-positions component"
)


@dataclass(frozen=True)
class Component:
    name: str
    kind: str  # "A" or "B"
    value: float
    unit: str
    distribution: str
    divisor: float
    sensitivity: float  # degrees per unit of value
    degrees_of_freedom: float  # math.inf for a known bound
    source: str
    added: bool = True

    @property
    def contribution_deg(self) -> float:
        return abs(self.sensitivity) * self.value / self.divisor if self.added else 0.0

    def document(self) -> dict:
        entry = asdict(self)
        entry["contribution_deg"] = self.contribution_deg
        entry["degrees_of_freedom"] = None if math.isinf(self.degrees_of_freedom) else self.degrees_of_freedom
        return entry


@dataclass(frozen=True)
class Combined:
    standard_deg: float
    effective_dof: float
    coverage_factor: float
    expanded_deg: float  # k u_c, rounded up to two significant digits


def two_significant_up(value: float) -> float:
    """value rounded up to two significant digits (GUM 7.2.6; rounding a
    bound down would understate it)."""
    if not math.isfinite(value) or value <= 0.0:
        return value
    scale = 10.0 ** (math.floor(math.log10(value)) - 1)
    return round(math.ceil(value / scale - 1e-9) * scale, 12)


def two_significant_text(value: float) -> str:
    """value with two significant digits, trailing zeros kept: 0.40, 0.018, 1.2."""
    return f"{value:#.2g}".rstrip(".")


def combine(components: list[Component]) -> Combined:
    """u_c as the root sum of squares of the added contributions (GUM 5.1.2,
    uncorrelated inputs), nu_eff by Welch-Satterthwaite (G.4.1), k from
    Student's t at COVERAGE_PROBABILITY (G.3.4)."""
    added = [c for c in components if c.added and c.contribution_deg > 0.0]
    standard = math.sqrt(sum(c.contribution_deg**2 for c in added))
    finite = [c for c in added if math.isfinite(c.degrees_of_freedom)]
    denominator = sum(c.contribution_deg**4 / max(c.degrees_of_freedom, 1e-12) for c in finite)
    effective = standard**4 / denominator if denominator > 0.0 else math.inf
    factor = float(stats.norm.ppf(0.5 + COVERAGE_PROBABILITY / 2.0))
    if math.isfinite(effective):
        factor = float(stats.t.ppf(0.5 + COVERAGE_PROBABILITY / 2.0, effective))
    return Combined(standard, effective, factor, two_significant_up(factor * standard))


@dataclass(frozen=True)
class AxisInputs:
    """What the Type B components of an axis rest on, from its campaign."""

    fits: dict[str, SurfaceFit]  # by set
    rate_bound_lsb: float  # half-width of the rate effect in the field, LSB
    rate_source: str
    offset_difference_u_lsb: float  # standard uncertainty of the W - C offset's estimate
    offset_difference_dof: float
    offset_source: str
    # m: the share of |f_W - f_C| the device's crossing can be off by after a reversal (crossing.py)
    set_mismatch: float
    set_mismatch_source: str
    # The long-term stability half-width in degrees (stability.py); None unevaluated.
    stability_deg: float | None = None
    stability_source: str = NOT_EVALUATED


def rate_bound(errors: AxisErrors) -> tuple[float, str]:
    """The in-sample error's dependence on dT/dt per set (OLS on the rate,
    Newey-West within positions), as a bound on the error a field rate up
    to FIELD_RATE_LIMIT_C_PER_MIN gives: each set's surface took up its
    chamber's mean rate, so sqrt(c^2 + u(c)^2) (|mean rate| + limit)."""
    limit = FIELD_RATE_LIMIT_C_PER_MIN / 60.0
    bounds, notes = [], []
    for set_name in dict.fromkeys(errors.set_name.tolist()):
        mine = (errors.set_name == set_name) & np.isfinite(errors.rate_c_per_s)
        if np.count_nonzero(mine) < 20 or np.ptp(errors.rate_c_per_s[mine]) == 0.0:
            continue
        rate, error, groups = errors.rate_c_per_s[mine], errors.in_sample_lsb[mine], errors.position[mine]
        ols = OLS(error, add_constant(rate, has_constant="add")).fit()
        shortest = int(np.min(np.unique(groups, return_counts=True)[1]))
        lags = min(hac_lags(ols.resid), max(1, shortest - 1))
        slope, slope_u = float(ols.params[1]), float(np.sqrt(hac_panel_covariance(ols, groups, lags)[1, 1]))
        bounds.append(math.hypot(slope, slope_u) * (abs(float(np.mean(rate))) + limit))
        notes.append(f"{set_name}: {slope / 60.0:.3g} +- {slope_u / 60.0:.2g} LSB per degC/min")
    if not bounds:
        return 0.0, "not evaluated: the campaign's rows have no temperature rate (time_s)"
    return max(bounds), (
        "in-sample error regressed on dT/dt (OLS, Newey-West within positions): "
        + "; ".join(notes)
        + f"; field |dT/dt| <= {FIELD_RATE_LIMIT_C_PER_MIN:g} degC/min plus the chamber's mean rate the surface took up"
    )


def offset_difference(errors: AxisErrors) -> tuple[float, float, str]:
    """The W - C difference of each position's 25 degC readings about its
    reference (dataset.reading_at_25 on each set's residuals); the standard
    uncertainty of their mean, s / sqrt(P), on P - 1 degrees of freedom."""
    differences = []
    for position in np.unique(errors.position):
        readings = []
        for set_name in ("W", "C"):
            mine = (errors.position == position) & (errors.set_name == set_name)
            readings.append(
                reading_at_25(errors.temperature_c[mine], errors.residual_lsb[mine]) if mine.any() else None
            )
        if None not in readings:
            differences.append(readings[0] - readings[1])
    if len(differences) < 2:
        return 0.0, math.inf, "not evaluated: fewer than two positions with both sets at 25 degC"
    values = np.array(differences)
    u = float(np.std(values, ddof=1) / math.sqrt(len(values)))
    return (
        u,
        float(len(values) - 1),
        (
            f"W - C at 25 degC over {len(values)} positions: mean {np.mean(values):.1f} LSB, "
            f"s {np.std(values, ddof=1):.1f} LSB; u = s / sqrt(P); each set carries half the difference"
        ),
    )


def axis_inputs(
    errors: AxisErrors, fits: list[SurfaceFit], crossing: Crossing, previous: PreviousCalibration | None = None
) -> AxisInputs:
    """The axis's campaign-level inputs; crossing, the campaign's
    set-crossing estimate over all its axes (crossing.estimate_crossing);
    previous, the sensor's calibration before this one, if any."""
    rate_lsb, rate_source = rate_bound(errors)
    offset_u, offset_dof, offset_source = offset_difference(errors)
    stability_deg, stability_source = (
        (None, NOT_EVALUATED) if previous is None else previous.stability(fits, errors.axis)
    )
    return AxisInputs(
        {fit.set_name: fit for fit in fits if fit.axis == errors.axis},
        rate_lsb,
        rate_source,
        offset_u,
        offset_dof,
        offset_source,
        crossing.mismatch(FIELD_RATE_LIMIT_C_PER_MIN / 60.0),
        crossing.source(FIELD_RATE_LIMIT_C_PER_MIN / 60.0),
        stability_deg,
        stability_source,
    )


def _corners(*ranges: np.ndarray) -> list[np.ndarray]:
    """Every corner of the box the values' ranges span, one array per range."""
    grids = np.meshgrid(*[np.array([np.min(values), np.max(values)]) for values in ranges], indexing="ij")
    return [grid.ravel() for grid in grids]


def _largest_slope_change(inputs: AxisInputs, t: np.ndarray, t0: np.ndarray, a: np.ndarray) -> float:
    """max over every pairing of sets of the change of df/dT = p10 + 2 p20 T
    + p11 a between the installation reading (T0, either set) and the
    reading (T, either set), LSB/degC, at the corners of the ranges of T, T0
    and a (``_corners``): linear in each, it is largest at one of them."""

    def slope(surface: Surface, temperature: np.ndarray) -> np.ndarray:
        return surface.p10 + 2.0 * surface.p20 * temperature + surface.p11 * a

    surfaces = [fit.surface for fit in inputs.fits.values()]
    return max(float(np.max(np.abs(slope(late, t) - slope(early, t0)))) for late in surfaces for early in surfaces)


def _largest_set_difference(inputs: AxisInputs, temperature: np.ndarray, acceleration: np.ndarray) -> float:
    if len(inputs.fits) < 2:
        return 0.0
    warming, cooling = inputs.fits["W"].surface, inputs.fits["C"].surface
    return float(
        np.max(np.abs(warming.evaluate(temperature, acceleration) - cooling.evaluate(temperature, acceleration)))
    )


def rectangular(
    name: str, half_width: float, unit: str, sensitivity: float, source: str, added: bool = True
) -> Component:
    """A Type B component known as bounds +-half_width: rectangular,
    divisor sqrt(3) (GUM 4.3.7), infinite degrees of freedom (G.4.2)."""
    return Component(name, "B", half_width, unit, "rectangular", SQRT3, sensitivity, math.inf, source, added)


def type_b_components(
    inputs: AxisInputs,
    temperature: np.ndarray,
    installation_c: np.ndarray,
    acceleration: np.ndarray,
    deg_per_lsb: np.ndarray,
    type_a_deg: float,
) -> list[Component]:
    """The cell's Type B components (and the Type A W - C offset estimate)
    for a change from an installation reading at installation_c (its band's
    rows' temperatures) to a reading at its rows' conditions: each a bound
    over them (its largest value), so that the cell's U is a bound too.
    The installation reading is taken once the set is known (tilt_change),
    so the set selection's component is the reading's alone; rate, lag and
    resolution act on both readings independently."""
    slope = float(np.max(deg_per_lsb))
    t, t0, a = _corners(temperature, installation_c, acceleration)
    offset_reach = float(np.max(np.abs(t - t0) * np.abs(a)))
    return [
        rectangular(
            "temperature reading shift",
            TEMPERATURE_SHIFT_C,
            "degC",
            _largest_slope_change(inputs, t, t0, a) * slope,
            SHIFT_SOURCE,
        ),
        rectangular(
            "rate and lag",
            inputs.rate_bound_lsb,
            "LSB",
            TWO_READINGS * slope,
            inputs.rate_source + "; a lag of the die behind its reading shows as this rate dependence; "
            "the reading's and the installation reading's, independent (sensitivity x sqrt(2))",
        ),
        rectangular(
            "set selection at turnarounds",
            inputs.set_mismatch * _largest_set_difference(inputs, temperature, acceleration),
            "LSB",
            slope,
            SET_SELECTION_SOURCE + inputs.set_mismatch_source,
        ),
        Component(
            "set offset estimate",
            "A",
            inputs.offset_difference_u_lsb,
            "LSB",
            "normal",
            1.0,
            0.5 * slope,
            inputs.offset_difference_dof,
            inputs.offset_source,
        ),
        rectangular(
            "resolution",
            RESOLUTION_LSB / 2.0,
            "LSB",
            TWO_READINGS * slope,
            RESOLUTION_SOURCE,
        ),
        rectangular(
            "sensitivity tolerance",
            SENSITIVITY_TOLERANCE,
            "relative",
            type_a_deg,
            TOLERANCE_SOURCE,
        ),
        rectangular(
            "sensitivity change with temperature",
            SENSITIVITY_TEMPCO_PER_C * offset_reach,
            "LSB",
            slope,
            TEMPCO_SOURCE,
            added=False,
        ),
        _stability(inputs),
    ]


def _stability(inputs: AxisInputs) -> Component:
    """The long-term stability component: listed, not added, for a first calibration."""
    added = inputs.stability_deg is not None
    return rectangular(
        "long-term stability", inputs.stability_deg or 0.0, "deg", 1.0, inputs.stability_source, added=added
    )
