"""A fit beside a reference: the paper's Tables 2-3 or the surfaces a twin
model was given (`thermotilt compare`).

Single coefficients of a polynomial are strongly collinear, so the measure
that matters is the difference of the two surfaces over the calibrated
domain (T -10..45 degC x the fit's acceleration range), in LSB. Both
surfaces are taken relative to their value at 25 degC, because that is all
a fit to residuals against the 25 degC reading can know (docs/calibration.md):
g(T, a) = f(T, a) - f(25, a). Per coefficient, the difference is also given
in units of a 95 % half-width: the paper's own bounds, or, against a model
(which has none), the fit's HAC bounds.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..physics import Model, ModelError
from ..physics.terms.sensor import coefficient_table_of
from ..surfaces import COEFFICIENT_NAMES, REFERENCE_C, Surface
from .dataset import CalibrationDataError
from .paper import PRINTING_ERRORS, TABLES

CALIBRATED_C = (-10.0, 45.0)
GRID_POINTS = 60


@dataclass(frozen=True)
class SurfaceComparison:
    key: str  # e.g. "WX"
    temperature_range_c: tuple[float, float]
    rms_lsb: float
    max_lsb: float
    coefficient_sigmas: dict[str, float]  # difference / 95 % half-width
    half_width_from: str  # "paper" or "fit"
    fit_rmse_lsb: float
    reference_rmse_lsb: float | None  # the paper's (Tables 2-3); a model states none


@dataclass(frozen=True)
class FittedSurface:
    """One surface of a coefficients.json, as `thermotilt fit` wrote it."""

    surface: Surface
    hac_half_widths: dict[str, float]
    temperature_range_c: tuple[float, float]
    acceleration_range_lsb: tuple[float, float]
    rmse_lsb: float


def domain_grid(
    temperature_c: tuple[float, float], acceleration_lsb: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """The GRID_POINTS x GRID_POINTS grid over a domain that surfaces are
    compared on: temperatures and accelerations, as meshgrid gives them."""
    return np.meshgrid(np.linspace(*temperature_c, GRID_POINTS), np.linspace(*acceleration_lsb, GRID_POINTS))


def calibrated_domain(fit: FittedSurface) -> tuple[float, float]:
    """-10..45 degC, narrowed to what the fit saw: a surface is not
    compared where it was extrapolated."""
    low, high = fit.temperature_range_c
    return max(CALIBRATED_C[0], low), min(CALIBRATED_C[1], high)


def expected_mounting_miss_lsb(
    sigma_lsb_per_c: float, temperature_range_c: tuple[float, float], accelerations_lsb: list[float]
) -> float:
    """The RMS by which a fit misses its sensor's drift, as compare measures
    it (relative to 25 degC, over the temperature range and the positions'
    span of acceleration), from the drift's slope changing with each
    mounting alone (the model's drift_repeatability: δ ~ N(0, sigma) per
    position, adding δ·(T - 25 degC)). The surface's T and T·a terms take
    the positions' slopes as a line in a, so the line through N points
    misses by sigma²·(1/N + (a - ā)²/Σ(a_m - ā)²) in variance at a; over
    T and a uniform in the domain that is expected
    sigma·R·sqrt(1/N + <(a - ā)²>/Σ(a_m - ā)²), R the RMS of T - 25 degC.
    Assumes the positions' rows alike in temperature (one program each)
    and so weighted alike; ``test_compare.py`` checks it on simulated fits."""
    accelerations = np.asarray(accelerations_lsb, dtype=float)
    low_c, high_c = temperature_range_c
    low_a, high_a = accelerations.min(), accelerations.max()
    centre = accelerations.mean()
    spread = float(np.sum((accelerations - centre) ** 2))
    mean_c = (low_c + high_c) / 2.0 - REFERENCE_C
    temperature_ms = (high_c - low_c) ** 2 / 12.0 + mean_c**2
    off_centre_ms = (high_a - low_a) ** 2 / 12.0 + ((low_a + high_a) / 2.0 - centre) ** 2
    line_variance = 1.0 / accelerations.size + (off_centre_ms / spread if spread > 0 else 0.0)
    return float(sigma_lsb_per_c * np.sqrt(temperature_ms * line_variance))


def _relative(surface: Surface, temperature: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
    return surface.evaluate(temperature, acceleration) - surface.evaluate(REFERENCE_C, acceleration)


def _pair(values) -> tuple[float, float]:
    low, high = values
    return float(low), float(high)


def _fitted_surface(fit: dict) -> FittedSurface:
    coefficients = fit["coefficients"]
    hac = {term: _pair(coefficients[term]["hac_95"]) for term in COEFFICIENT_NAMES}
    return FittedSurface(
        surface=Surface(*(float(coefficients[term]["value"]) for term in COEFFICIENT_NAMES)),
        hac_half_widths={term: (high - low) / 2 for term, (low, high) in hac.items()},
        temperature_range_c=_pair(fit["temperature_range_c"]),
        acceleration_range_lsb=_pair(fit["acceleration_range_lsb"]),
        rmse_lsb=float(fit["rmse_lsb"]),
    )


def read_fit(fit_dir: Path) -> dict[str, FittedSurface]:
    """The surfaces of FIT_DIR/coefficients.json by key ("WX", ...)."""
    path = fit_dir / "coefficients.json"
    try:
        fits = {key: _fitted_surface(fit) for key, fit in json.loads(path.read_text())["fits"].items()}
    except OSError as error:
        raise CalibrationDataError(f"{path}: cannot read: {error.strerror or error}") from None
    except (ValueError, KeyError, TypeError, IndexError, AttributeError):
        raise CalibrationDataError(f"{path}: not a coefficients.json written by thermotilt fit") from None
    return fits


def fitted_sensor_id(fit_dir: Path) -> str:
    """The sensor FIT_DIR's fit was made for ("" for none)."""
    try:
        sensor_id = json.loads((fit_dir / "coefficients.json").read_text()).get("sensor_id") or ""
    except (OSError, ValueError, AttributeError):
        return ""
    return sensor_id if isinstance(sensor_id, str) else ""


def reference_surfaces(
    reference: str, sensor_id: str = ""
) -> tuple[dict[str, Surface], dict[str, dict[str, float]] | None]:
    """Surfaces by key ("WX", ...) and, for the paper, each coefficient's
    95 % half-width; `reference` is "paper" or a model file, whose sensor
    sensor_id is the reference when the file lists a batch."""
    if reference == "paper":
        surfaces, widths = {}, {}
        for (axis, set_name), published in TABLES.items():
            if axis not in ("X", "Y"):
                continue

            def part(term: str, name: str) -> float:
                printed = getattr(published.coefficients[term], name)
                return PRINTING_ERRORS.get((axis, set_name, term, name), printed)

            key = f"{set_name}{axis}"
            surfaces[key] = Surface(*(part(term, "value") for term in COEFFICIENT_NAMES))
            widths[key] = {term: (part(term, "upper") - part(term, "lower")) / 2 for term in COEFFICIENT_NAMES}
        return surfaces, widths
    try:
        model = Model.load(reference)
        if model.sensors:
            if not sensor_id:
                raise CalibrationDataError(
                    f"{reference} lists a batch ({', '.join(model.sensor_ids)}) and the fit names no sensor"
                )
            model = model.for_sensor(sensor_id)
    except ModelError as error:
        raise CalibrationDataError(str(error)) from None
    table = coefficient_table_of(model.terms["drift"]["coefficients"])
    return {f"{s}{a}": table.surfaces[(s, a)] for s in ("W", "C") for a in ("X", "Y")}, None


def compare(fits: dict[str, FittedSurface], reference: str, sensor_id: str = "") -> list[SurfaceComparison]:
    """The fit of sensor_id ("" none) against the reference (reference_surfaces)."""
    surfaces, widths = reference_surfaces(reference, sensor_id)
    comparisons = []
    for key, fit in fits.items():
        if key not in surfaces:
            continue
        fitted = fit.surface
        domain = calibrated_domain(fit)
        temperature, acceleration = domain_grid(domain, fit.acceleration_range_lsb)
        difference = _relative(fitted, temperature, acceleration) - _relative(surfaces[key], temperature, acceleration)
        half = widths[key] if widths is not None else fit.hac_half_widths
        sigmas = {
            term: (getattr(fitted, term) - getattr(surfaces[key], term)) / half[term]
            if half[term] > 0
            else float("inf")
            for term in COEFFICIENT_NAMES
        }
        published = TABLES[(key[1], key[0])].rmse if widths is not None else None
        comparisons.append(
            SurfaceComparison(
                key,
                domain,
                float(np.sqrt(np.mean(difference**2))),
                float(np.max(np.abs(difference))),
                sigmas,
                "paper" if widths is not None else "fit",
                fit.rmse_lsb,
                published,
            )
        )
    if not comparisons:
        raise CalibrationDataError("the fit has no X or Y surface to compare")
    return comparisons


def format_comparison(comparisons: list[SurfaceComparison], reference: str) -> str:
    lines = [
        f"against {reference}: surfaces relative to 25 degC over the fit's acceleration range and "
        f"its part of {CALIBRATED_C[0]:g}..{CALIBRATED_C[1]:g} degC",
        f"  {'fit':<4}{'degC':>14}{'RMS LSB':>10}{'max LSB':>10}   coefficient difference / 95 % half-width",
    ]
    for comparison in comparisons:
        sigmas = "  ".join(f"{term} {value:+.1f}" for term, value in comparison.coefficient_sigmas.items())
        span = "{:.1f}..{:.1f}".format(*comparison.temperature_range_c)
        lines.append(
            f"  {comparison.key:<4}{span:>14}{comparison.rms_lsb:>10.2f}{comparison.max_lsb:>10.2f}   "
            f"{sigmas} (half-widths: {comparison.half_width_from})"
        )
    published = [c for c in comparisons if c.reference_rmse_lsb is not None]
    if published:
        lines.append("the scatter the surfaces leave: the fit's RMSE / Tables 2-3's, LSB")
        lines.append(
            "  "
            + "   ".join(
                f"{c.key} {c.fit_rmse_lsb:.2f} / {c.reference_rmse_lsb:.2f} "
                f"({c.fit_rmse_lsb / c.reference_rmse_lsb:.2f}x)"
                for c in published
            )
        )
    return "\n".join(lines)


@dataclass(frozen=True)
class FitComparison:
    """``thermotilt compare``'s workflow: a fit beside its reference."""

    comparisons: list[SurfaceComparison]
    reference: str

    def summary(self) -> str:
        return format_comparison(self.comparisons, self.reference)


def compare_fit(fit_dir: Path, reference: str) -> FitComparison:
    return FitComparison(compare(read_fit(fit_dir), reference, fitted_sensor_id(fit_dir)), reference)
