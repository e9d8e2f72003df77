"""The paper's 2nd-order surfaces fitted with statsmodels, with the
statistics Matlab's cftool gave the paper (section 3.3, Tables 2-5).

f(T, a) = p00 + p10 T + p01 a + p20 T^2 + p11 T a + p02 a^2 per set and
axis, by ordinary least squares. The rows of a 10 Hz, Kalman-filtered log
are strongly autocorrelated, so OLS's textbook bounds are far too narrow;
next to them come Newey-West (HAC) bounds computed within each position
(statsmodels' ``hac-panel``, computed as ``newey_west`` does), with the lag window read off the residuals'
own autocorrelation (``hac_lags``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from statsmodels.regression.linear_model import OLS
from statsmodels.tsa.stattools import acf

from ..surfaces import AXES, COEFFICIENT_NAMES, SETS, ZERO_SURFACE, CoefficientTable, Surface
from ..wire.coefficients import SetDomain, encode_block
from .dataset import FIT_AXES, CalibrationDataError, Campaign, SetData
from .newey_west import hac_panel_bounds, hac_panel_covariance

# Powers of (T, a) for p00, p10, p01, p20, p11, p02.
_POWERS = ((0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2))
# The design is built on T / 10 degC and a / 10^4 LSB so that its columns
# are of similar size (a^2 reaches 2.7e8 LSB^2); coefficients and bounds are
# scaled back exactly.
_TEMPERATURE_SCALE = 10.0
_ACCELERATION_SCALE = 1e4
_RATE_SCALE = 60.0  # degC/s to degC/min
MIN_POINTS = 7 * len(COEFFICIENT_NAMES)
# A quadratic in the acceleration needs three distinct levels of it.
MIN_POSITIONS = 3
CONFIDENCE = 0.95
# The HAC window is twice the lag at which the residuals' autocorrelation
# first falls below ACF_CUTOFF: Newey-West's Bartlett weights halve the
# autocovariance in the middle of the window, and a window of just the
# decorrelation lag left 95 % bounds holding the truth 89 % of the time on
# synthetic filtered logs, twice it 93 % (host/tests/test_calibration_fit.py).
ACF_CUTOFF = 0.05
LAG_WINDOW_FACTOR = 2


@dataclass(frozen=True)
class SurfaceFit:
    set_name: str
    axis: str
    points: int
    surface: Surface
    ols_bounds: tuple[tuple[float, float], ...]  # per term, OLS 95 %
    hac_bounds: tuple[tuple[float, float], ...]  # per term, HAC 95 % within positions
    hac_lags: int
    # The HAC covariance of the coefficients on design()'s scaled columns.
    hac_covariance: np.ndarray
    sse: float
    r_squared: float
    adjusted_r_squared: float
    rmse: float
    temperature_range_c: tuple[float, float]
    acceleration_range_lsb: tuple[float, float]


def design(
    temperature_c: np.ndarray,
    acceleration: np.ndarray,
    powers: tuple[tuple[int, ...], ...] = _POWERS,
    rate_c_per_s: np.ndarray | None = None,
) -> np.ndarray:
    """Columns T^i a^j (and dT/dt^k for a third power) on scaled variables."""
    variables = [temperature_c / _TEMPERATURE_SCALE, acceleration / _ACCELERATION_SCALE]
    if rate_c_per_s is not None:
        variables.append(rate_c_per_s * _RATE_SCALE)
    # Each variable's powers once, by multiplication: the columns share them.
    highest = [max((power[index] if index < len(power) else 0) for power in powers) for index in range(len(variables))]
    tables = []
    for variable, top in zip(variables, highest):
        table = [np.ones_like(variable)]
        for _ in range(top):
            table.append(table[-1] * variable)
        tables.append(table)
    columns = np.empty((len(temperature_c), len(powers)))
    for column, power in enumerate(powers):
        product = tables[0][power[0]] * tables[1][power[1]]
        if len(power) > 2 and power[2]:
            product = product * tables[2][power[2]]
        columns[:, column] = product
    return columns


def _unscale() -> np.ndarray:
    return np.array([1.0 / (_TEMPERATURE_SCALE**i * _ACCELERATION_SCALE**j) for i, j in _POWERS])


def hac_lags(residuals: np.ndarray) -> int:
    """LAG_WINDOW_FACTOR times the first lag at which the residuals'
    autocorrelation drops below ACF_CUTOFF, within a tenth of the rows."""
    limit = max(1, min(len(residuals) // 10, 5000))
    correlations = acf(residuals, nlags=limit, fft=True)
    below = np.flatnonzero(correlations[1:] < ACF_CUTOFF)
    decorrelated = int(below[0] + 1) if below.size else limit
    return min(LAG_WINDOW_FACTOR * decorrelated, limit)


def fit_surface(data: SetData, set_name: str, axis: str) -> SurfaceFit:
    temperature = data.temperature_c
    acceleration = data.acceleration[axis]
    residual = data.residual[axis]
    points = len(residual)
    if points < MIN_POINTS:
        raise CalibrationDataError(
            f"{set_name} set, {axis} axis: {points} points, at least {MIN_POINTS} needed for six coefficients"
        )
    positions = np.unique(data.position).size
    if positions < MIN_POSITIONS:
        raise CalibrationDataError(
            f"{set_name} set, {axis} axis: {positions} position(s); a surface of 2nd order in the "
            f"acceleration needs at least {MIN_POSITIONS} inclinations"
        )
    columns = design(temperature, acceleration)
    # The scaled design is well conditioned, so its 6 x 6 normal matrix
    # shows a missing direction as well as the tall matrix itself, faster.
    if np.linalg.matrix_rank(columns.T @ columns) < len(COEFFICIENT_NAMES):
        raise CalibrationDataError(
            f"{set_name} set, {axis} axis: temperature and acceleration do not vary enough for "
            "six coefficients (the fit needs several temperatures at several inclinations)"
        )
    # pinv: one SVD of the design, which statsmodels computes for the qr method too.
    ols = OLS(residual, columns).fit(method="pinv")
    # Newey-West within a position cannot take lags beyond its rows; many
    # short positions (37 of them in a full campaign) reach that first.
    shortest = int(np.min(np.unique(data.position, return_counts=True)[1]))
    lags = min(hac_lags(ols.resid), max(1, shortest - 1))
    covariance = hac_panel_covariance(ols, data.position, lags)
    unscale = _unscale()

    def scaled_back(bounds: np.ndarray) -> tuple[tuple[float, float], ...]:
        return tuple((float(low * k), float(high * k)) for (low, high), k in zip(bounds, unscale, strict=True))

    return SurfaceFit(
        set_name=set_name,
        axis=axis,
        points=points,
        surface=Surface(*(float(value) for value in ols.params * unscale)),
        ols_bounds=scaled_back(ols.conf_int(1.0 - CONFIDENCE)),
        hac_bounds=scaled_back(hac_panel_bounds(ols, data.position, covariance, CONFIDENCE)),
        hac_lags=lags,
        hac_covariance=covariance,
        sse=float(ols.ssr),
        r_squared=float(ols.rsquared),
        adjusted_r_squared=float(ols.rsquared_adj),
        rmse=float(math.sqrt(ols.ssr / ols.df_resid)),
        temperature_range_c=(float(temperature.min()), float(temperature.max())),
        acceleration_range_lsb=(float(acceleration.min()), float(acceleration.max())),
    )


def fit_campaign(campaign: Campaign, axes: tuple[str, ...] = FIT_AXES) -> list[SurfaceFit]:
    return [fit_surface(campaign.sets[set_name], set_name, axis) for axis in axes for set_name in SETS]


def coefficient_table(fits: list[SurfaceFit]) -> CoefficientTable:
    """The fitted surfaces; the others stay uncorrected (zero): Z always, as
    the firmware's defaults leave it (the paper's Z fits explain little:
    R^2 0.03-0.66), and an axis the campaign did not tilt."""
    surfaces = {(s, a): ZERO_SURFACE for s in SETS for a in AXES}
    surfaces.update({(fit.set_name, fit.axis): fit.surface for fit in fits})
    return CoefficientTable(surfaces)


def calibrated_domain(fits: list[SurfaceFit]) -> dict[str, SetDomain]:
    """Per set, the range of the fitted rows: temperature, and acceleration
    per fitted axis (an axis not fitted has none), rounded outwards to the
    block's 1/100 degC and LSB."""
    domain = {}
    for set_name in SETS:
        fitted = [fit for fit in fits if fit.set_name == set_name]
        if not fitted:
            domain[set_name] = SetDomain()
            continue
        temperature = (
            min(fit.temperature_range_c[0] for fit in fitted),
            max(fit.temperature_range_c[1] for fit in fitted),
        )
        domain[set_name] = SetDomain.covering(temperature, {fit.axis: fit.acceleration_range_lsb for fit in fitted})
    return domain


def _domain_json(domain: SetDomain) -> dict:
    return {
        "temperature_c": list(domain.temperature_c) if domain.temperature_c is not None else None,
        "acceleration_lsb": {
            axis: list(bounds) if bounds is not None else None for axis, bounds in domain.acceleration_lsb.items()
        },
    }


def _fit_json(fit: SurfaceFit) -> dict:
    return {
        "points": fit.points,
        "coefficients": {
            term: {"value": value, "ols_95": list(ols), "hac_95": list(hac)}
            for term, value, ols, hac in zip(
                COEFFICIENT_NAMES, fit.surface, fit.ols_bounds, fit.hac_bounds, strict=True
            )
        },
        "hac_lags_rows": fit.hac_lags,
        "sse": fit.sse,
        "r_squared": fit.r_squared,
        "adjusted_r_squared": fit.adjusted_r_squared,
        "rmse_lsb": fit.rmse,
        "temperature_range_c": list(fit.temperature_range_c),
        "acceleration_range_lsb": list(fit.acceleration_range_lsb),
    }


def c_header(table: CoefficientTable) -> str:
    lines = [
        "// Thermal-drift surfaces fitted by `thermotilt fit` (docs/calibration.md).",
        "// f(T, a) = p00 + p10 T + p01 a + p20 T^2 + p11 T a + p02 a^2, LSB;",
        "// order: set (W, C) x axis (X, Y, Z) x (p00, p10, p01, p20, p11, p02).",
        "#ifndef THERMOTILT_FITTED_COEFFICIENTS_H",
        "#define THERMOTILT_FITTED_COEFFICIENTS_H",
        "",
        "static const float FITTED_COEFFICIENTS[2][3][6] = {",
    ]
    for set_name in SETS:
        lines.append("    {")
        for axis in AXES:
            values = ", ".join(f"{value:.9g}f" for value in table.surfaces[(set_name, axis)])
            lines.append(f"        {{{values}}},  // {set_name} {axis}")
        lines.append("    },")
    lines += ["};", "", "#endif", ""]
    return "\n".join(lines)


def write_outputs(fits: list[SurfaceFit], campaign: Campaign, out_dir: Path, sensor_id: str = "") -> CoefficientTable:
    """coefficients.json, coefficients.bin (the firmware's EEPROM block) and
    coefficients.h in out_dir, for the sensor sensor_id ("" for none, which
    `upload` accepts only on a board without an ID)."""
    table = coefficient_table(fits)
    domain = calibrated_domain(fits)
    block = encode_block(table, sensor_id, domain)
    document = {
        "sensor_id": sensor_id,
        "positions": list(campaign.positions),
        "skipped_rows": campaign.skipped_rows,
        "stabilizing_rows": campaign.stabilizing_rows,
        "bounds": {
            "ols_95": "ordinary least squares: assumes independent rows, too narrow for filtered logs",
            "hac_95": "Newey-West within each position, lag window hac_lags_rows (statsmodels hac-panel)",
        },
        "fits": {f"{fit.set_name}{fit.axis}": _fit_json(fit) for fit in fits},
        "uncorrected_axes": [axis for axis in AXES if axis not in {fit.axis for fit in fits}],
        # What coefficients.bin and the upload carry: the fitted rows' ranges
        # in the block's units (1/100 degC, LSB), rounded outwards.
        "calibrated_domain": {set_name: _domain_json(domain[set_name]) for set_name in SETS},
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "coefficients.json").write_text(json.dumps(document, indent=2) + "\n")
    (out_dir / "coefficients.bin").write_bytes(block)
    (out_dir / "coefficients.h").write_text(c_header(table))
    return table


def format_table(fits: list[SurfaceFit]) -> str:
    """The fits shaped like the paper's Tables 2 and 3."""
    lines = []
    for axis in dict.fromkeys(fit.axis for fit in fits):
        pair = [fit for fit in fits if fit.axis == axis]
        lines.append(
            f"{axis} axis" + "".join(f"  | {('warming' if f.set_name == 'W' else 'cooling'):<44}" for f in pair)
        )
        for index, term in enumerate(COEFFICIENT_NAMES):
            cells = "".join(
                f"  | {f.surface[index]:>11.4g} (HAC {f.hac_bounds[index][0]:.4g}, {f.hac_bounds[index][1]:.4g})".ljust(
                    47
                )
                for f in pair
            )
            lines.append(f"  {term:<6}{cells}")
        for label, getter in (
            ("SSE", lambda f: f"{f.sse:.4g}"),
            ("R2", lambda f: f"{f.r_squared:.4f}"),
            ("adj R2", lambda f: f"{f.adjusted_r_squared:.4f}"),
            ("RMSE", lambda f: f"{f.rmse:.3f} LSB"),
            ("points", lambda f: str(f.points)),
            ("T range", lambda f: "{:.1f} .. {:.1f} degC".format(*f.temperature_range_c)),
            ("a range", lambda f: "{:.0f} .. {:.0f} LSB".format(*f.acceleration_range_lsb)),
        ):
            lines.append(f"  {label:<6}" + "".join(f"  | {getter(f):<44}" for f in pair))
    return "\n".join(lines)
