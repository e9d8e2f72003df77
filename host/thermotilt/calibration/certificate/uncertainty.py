"""U per axis as a function of IMU temperature and nominal tilt: a table
of bands (``domain``), each band's budget (``budget``) and its expanded
uncertainty; the certificate's headline is the table's maximum.

The dominant component, each mounting's drift, is evaluated out of sample:
each position's rows are compensated with surfaces fitted without it
(``errors.left_out_predictions``). In a band, per position and set, the
mean of those errors is one draw of the mounting-to-mounting component
and the rows' scatter about it the within-position component (GUM H.5,
analysis of variance):

- between positions: the RMS over positions of their sets' mean errors,
  on positions - 1 degrees of freedom (F.1.1.2): the autocorrelated rows
  within a position add none to it;
- within position: the rows' pooled scatter about their position's mean,
  on the rows' effective count less one per position (the rows' variance
  over the Newey-West variance of their mean, the fit's lag rule).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from statsmodels.regression.linear_model import OLS

from ..fit import hac_lags
from ..newey_west import hac_panel_covariance
from .budget import AxisInputs, Combined, Component, combine, type_b_components
from .domain import TILT_BAND_EDGES_DEG, band_index, temperature_bands
from .errors import AxisErrors

# A tilt band of fewer positions is merged with its neighbour (the outer
# one where there is one): two positions give 1 degree of freedom, k = 12.7.
MIN_BAND_POSITIONS = 3
# A position's set counts in a band with at least this many rows there.
MIN_CELL_ROWS = 10


@dataclass(frozen=True)
class Cell:
    axis: str
    temperature_band_c: tuple[float, float]
    tilt_band_deg: tuple[float, float]
    positions: int
    components: tuple[Component, ...]
    combined: Combined
    type_a: Combined  # the between and within components alone

    @property
    def expanded_deg(self) -> float:
        return self.combined.expanded_deg


def tilt_bands(nominal_deg: np.ndarray, present: np.ndarray) -> list[tuple[float, float]]:
    """|nominal tilt| bands of TILT_BAND_EDGES_DEG up to the largest angle,
    a band of fewer than MIN_BAND_POSITIONS positions (of those present)
    merged with its outer neighbour (its inner one at the end)."""
    largest = float(np.max(np.abs(nominal_deg[present])))
    edges = [edge for edge in TILT_BAND_EDGES_DEG if edge < largest] + [largest]
    if len(edges) < 2:
        return [(0.0, largest)]
    sizes = np.abs(nominal_deg[present])

    def count(low: float, high: float) -> int:
        return int(np.count_nonzero(((sizes > low) | (low == 0.0)) & (sizes <= high)))

    while len(edges) > 2:
        counts = [count(low, high) for low, high in zip(edges[:-1], edges[1:])]
        sparse = next((i for i, c in enumerate(counts) if c < MIN_BAND_POSITIONS), None)
        if sparse is None:
            break
        # Drop the edge between the sparse band and its outer neighbour (inner at the end).
        del edges[sparse + 1 if sparse + 1 < len(edges) - 1 else sparse]
    return [(float(low), float(high)) for low, high in zip(edges[:-1], edges[1:])]


def effective_count(errors: np.ndarray) -> float:
    """How many independent values a run of autocorrelated rows is worth for
    its mean: their variance over the Newey-West variance of the mean (the
    fit's lag rule), at most their count."""
    ols = OLS(errors, np.ones((len(errors), 1))).fit()
    lags = min(hac_lags(ols.resid), max(1, len(errors) - 1))
    variance_of_mean = float(hac_panel_covariance(ols, np.zeros(len(errors), dtype=int), lags)[0, 0])
    spread = float(np.var(errors, ddof=1))
    return float(len(errors)) if variance_of_mean <= 0.0 else min(float(len(errors)), spread / variance_of_mean)


def _effective_shares(errors: AxisErrors) -> dict[tuple[int, str], float]:
    """Per position and set, its rows' effective count over their count."""
    shares = {}
    for position in np.unique(errors.position):
        for set_name in np.unique(errors.set_name):
            mine = (errors.position == position) & (errors.set_name == set_name)
            if np.count_nonzero(mine) >= MIN_CELL_ROWS:
                values = errors.out_of_sample_deg[mine]
                shares[int(position), str(set_name)] = effective_count(values) / len(values)
    return shares


def type_a_components(
    errors: AxisErrors, cell: np.ndarray, shares: dict[tuple[int, str], float]
) -> tuple[list[Component], int]:
    """The between- and within-position components of the rows in cell,
    and how many positions they rest on."""
    means_squared: dict[int, list[float]] = {}
    scatter = dof_rows = effective = 0.0
    for position in np.unique(errors.position[cell]):
        for set_name in np.unique(errors.set_name[cell]):
            mine = cell & (errors.position == position) & (errors.set_name == set_name)
            values = errors.out_of_sample_deg[mine]
            if len(values) < MIN_CELL_ROWS:
                continue
            mean = float(np.mean(values))
            means_squared.setdefault(int(position), []).append(mean**2)
            scatter += float(np.sum((values - mean) ** 2))
            dof_rows += len(values) - 1
            effective += max(shares[int(position), str(set_name)] * len(values) - 1.0, 0.0)
    positions = len(means_squared)
    if positions < 2:
        return [], positions
    in_sample = sum(not errors.evaluable[position] for position in means_squared)
    note = (
        f" ({in_sample} in sample: a fold without them keeps fewer than three angles, too few for the quadratic in a)"
        if in_sample
        else ""
    )
    between = math.sqrt(float(np.mean([np.mean(squares) for squares in means_squared.values()])))
    within = math.sqrt(scatter / dof_rows)
    return [
        Component(
            "between positions (out of sample)",
            "A",
            between,
            "deg",
            "normal",
            1.0,
            1.0,
            positions - 1.0,
            f"RMS over {positions} positions of each one's mean error in the band, its rows compensated with "
            f"surfaces fitted without it (leave-one-position-out){note}; GUM H.5, F.1.1.2",
        ),
        Component(
            "within position (single reading)",
            "A",
            within,
            "deg",
            "normal",
            1.0,
            1.0,
            max(effective, 1.0),
            "the rows' pooled scatter about their position's mean in the band; degrees of freedom from the "
            "rows' effective count (Newey-West variance of the mean)",
        ),
    ], positions


def axis_cells(errors: AxisErrors, inputs: AxisInputs, temperature_c: tuple[float, float]) -> list[Cell]:
    """The axis's table, row by row (temperature bands) and band by band
    (tilt); a cell resting on fewer than two positions is left out."""
    t_bands = temperature_bands(*temperature_c)
    tilt = tilt_bands(errors.nominal_deg, np.isfinite(errors.reference_lsb))
    shares = _effective_shares(errors)
    row_t = band_index(errors.temperature_c, [list(b) for b in t_bands], closed_above=False)
    row_tilt = band_index(np.abs(errors.nominal_deg[errors.position]), [list(b) for b in tilt], closed_above=True)
    cells = []
    for t_index, t_band in enumerate(t_bands):
        for tilt_index, tilt_band in enumerate(tilt):
            cell = (row_t == t_index) & (row_tilt == tilt_index)
            type_a, positions = type_a_components(errors, cell, shares)
            if not type_a:
                continue
            type_a_combined = combine(type_a)
            components = type_a + type_b_components(
                inputs,
                errors.temperature_c[cell],
                errors.acceleration_lsb[cell],
                errors.deg_per_lsb[cell],
                type_a_combined.standard_deg,
            )
            cells.append(
                Cell(errors.axis, t_band, tilt_band, positions, tuple(components), combine(components), type_a_combined)
            )
    return cells


def table(cells: list[Cell], temperature_c: tuple[float, float], errors: AxisErrors) -> dict:
    """certificate.json's uncertainty_table entry of an axis (``domain.u95_at``
    reads it): U per temperature band (rows) and tilt band (columns),
    null where no cell could be evaluated."""
    t_bands, tilt = temperature_bands(*temperature_c), tilt_bands(errors.nominal_deg, np.isfinite(errors.reference_lsb))
    grid = [[None] * len(tilt) for _ in t_bands]
    dof = [[None] * len(tilt) for _ in t_bands]
    factor = [[None] * len(tilt) for _ in t_bands]
    positions = [[0] * len(tilt) for _ in t_bands]
    for cell in cells:
        i, j = t_bands.index(cell.temperature_band_c), tilt.index(cell.tilt_band_deg)
        grid[i][j] = cell.expanded_deg
        dof[i][j] = None if math.isinf(cell.combined.effective_dof) else round(cell.combined.effective_dof, 1)
        factor[i][j] = round(cell.combined.coverage_factor, 2)
        positions[i][j] = cell.positions
    return {
        "temperature_bands_c": [list(band) for band in t_bands],
        "tilt_bands_deg": [list(band) for band in tilt],
        "u95_deg": grid,
        "effective_dof": dof,
        "coverage_factor": factor,
        "positions": positions,
    }
