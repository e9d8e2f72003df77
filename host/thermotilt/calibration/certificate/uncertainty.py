"""U per axis as a function of the installation reading's IMU temperature,
the reading's and the nominal tilt: a table of bands (``domain``), each
cell's budget (``budget``) and its expanded uncertainty; the certificate's
headline is the table's maximum.

The measurand is what a monitoring user reads: a reading's change from
the installation reading. The dominant component, each mounting's drift,
is evaluated out of sample: each position's rows are compensated with
surfaces fitted without it (``errors.left_out_predictions``). Per position
and set, the mean of those errors in a temperature band is its drift
there; the difference between its means in the reading's band and in the
installation's band is one draw of the mounting-to-mounting component of
the change, and the rows' scatter about each mean the within-position
component of each reading (GUM H.5, analysis of variance):

- between positions: the RMS over positions of those differences, on
  positions - 1 degrees of freedom (F.1.1.2): the autocorrelated rows
  within a position add none to it;
- within position, for the reading and for the installation reading: the
  rows' pooled scatter about their position's mean, on the rows' effective
  count less one per position (the rows' variance over the Newey-West
  variance of their mean, the fit's lag rule).

A drift common to the two readings cancels in the change: a reading
installed and read at one temperature carries none of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from statsmodels.regression.linear_model import OLS

from ...surfaces import SETS
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
    installation_band_c: tuple[float, float]
    temperature_band_c: tuple[float, float]
    tilt_band_deg: tuple[float, float]
    positions: int
    components: tuple[Component, ...]
    combined: Combined
    type_a: Combined  # the between and within components alone

    @property
    def expanded_deg(self) -> float:
        return self.combined.expanded_deg


@dataclass(frozen=True)
class _Group:
    """One position's rows of one set in one band: their mean error, their
    squared scatter about it, their count and effective count."""

    mean: float
    scatter: float
    rows: int
    effective: float


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


def _groups(errors: AxisErrors, band: np.ndarray, shares: dict[tuple[int, str], float]) -> dict:
    """Per position and set, its rows in the band (a row mask), if at least MIN_CELL_ROWS."""
    groups = {}
    for position in np.unique(errors.position[band]):
        for set_name in np.unique(errors.set_name[band]):
            values = errors.out_of_sample_deg[band & (errors.position == position) & (errors.set_name == set_name)]
            if len(values) < MIN_CELL_ROWS:
                continue
            mean = float(np.mean(values))
            groups[int(position), str(set_name)] = _Group(
                mean,
                float(np.sum((values - mean) ** 2)),
                len(values),
                max(shares[int(position), str(set_name)] * len(values) - 1.0, 0.0),
            )
    return groups


def _within(groups: dict, which: str) -> Component:
    scatter = sum(group.scatter for group in groups.values())
    dof_rows = sum(group.rows - 1 for group in groups.values())
    return Component(
        f"within position ({which})",
        "A",
        math.sqrt(scatter / dof_rows),
        "deg",
        "normal",
        1.0,
        1.0,
        max(sum(group.effective for group in groups.values()), 1.0),
        f"the {which}'s scatter: the rows' pooled scatter about their position's mean in its band; degrees of "
        "freedom from the rows' effective count (Newey-West variance of the mean)",
    )


def type_a_components(
    errors: AxisErrors, reading: dict, installation: dict, positions_in_band: np.ndarray
) -> tuple[list[Component], int]:
    """The between- and within-position components of a change from an
    installation reading (its band's groups) to a reading (its band's
    groups), and how many positions they rest on. A position's draw of the
    change is the difference of its mean errors in the two bands, over
    every pairing of the sets it was read in: the installation may have
    been in either set and the reading in either."""
    squares = {}
    for position in positions_in_band:
        differences = [
            reading[position, late].mean - installation[position, early].mean
            for late in SETS
            for early in SETS
            if (position, late) in reading and (position, early) in installation
        ]
        if differences:
            squares[int(position)] = float(np.mean(np.square(differences)))
    positions = len(squares)
    if positions < 2:
        return [], positions
    in_sample = sum(not errors.evaluable[position] for position in squares)
    note = (
        f" ({in_sample} in sample: a fold without them keeps fewer than three angles, too few for the quadratic in a)"
        if in_sample
        else ""
    )
    used = {key: group for key, group in reading.items() if key[0] in squares}
    used_installation = {key: group for key, group in installation.items() if key[0] in squares}
    return [
        Component(
            "between positions (out of sample)",
            "A",
            math.sqrt(float(np.mean(list(squares.values())))),
            "deg",
            "normal",
            1.0,
            1.0,
            positions - 1.0,
            f"RMS over {positions} positions of the difference of each one's mean errors in the reading's and the "
            "installation's bands, every pairing of its sets, its rows compensated with surfaces fitted without "
            f"it (leave-one-position-out){note}; GUM H.5, F.1.1.2",
        ),
        _within(used, "reading"),
        _within(used_installation, "installation reading"),
    ], positions


def axis_cells(errors: AxisErrors, inputs: AxisInputs, temperature_c: tuple[float, float]) -> list[Cell]:
    """The axis's table, installation band by installation band, reading
    band by reading band (temperature) and band by band (tilt); a cell
    resting on fewer than two positions is left out."""
    t_bands = temperature_bands(*temperature_c)
    tilt = tilt_bands(errors.nominal_deg, np.isfinite(errors.reference_lsb))
    shares = _effective_shares(errors)
    row_t = band_index(errors.temperature_c, [list(b) for b in t_bands], closed_above=False)
    row_tilt = band_index(np.abs(errors.nominal_deg[errors.position]), [list(b) for b in tilt], closed_above=True)
    cells = []
    for tilt_index, tilt_band in enumerate(tilt):
        in_tilt = row_tilt == tilt_index
        positions_in_band = np.unique(errors.position[in_tilt])
        groups = [_groups(errors, in_tilt & (row_t == t_index), shares) for t_index in range(len(t_bands))]
        for early, installation_band in enumerate(t_bands):
            installed = in_tilt & (row_t == early)
            for late, t_band in enumerate(t_bands):
                type_a, positions = type_a_components(errors, groups[late], groups[early], positions_in_band)
                if not type_a:
                    continue
                cell = in_tilt & (row_t == late)
                type_a_combined = combine(type_a)
                components = type_a + type_b_components(
                    inputs,
                    errors.temperature_c[cell],
                    errors.temperature_c[installed],
                    errors.acceleration_lsb[cell],
                    errors.deg_per_lsb[cell],
                    type_a_combined.standard_deg,
                )
                cells.append(
                    Cell(
                        errors.axis,
                        installation_band,
                        t_band,
                        tilt_band,
                        positions,
                        tuple(components),
                        combine(components),
                        type_a_combined,
                    )
                )
    return cells


def table(cells: list[Cell], temperature_c: tuple[float, float], errors: AxisErrors) -> dict:
    """certificate.json's uncertainty_table entry of an axis (``domain.u95_at``
    reads it): U indexed [installation band][reading band][tilt band], the
    first two of temperature_bands_c, null where no cell could be evaluated."""
    t_bands, tilt = temperature_bands(*temperature_c), tilt_bands(errors.nominal_deg, np.isfinite(errors.reference_lsb))

    def grid(empty: object) -> list:
        return [[[empty] * len(tilt) for _ in t_bands] for _ in t_bands]

    u95, dof, factor, positions = grid(None), grid(None), grid(None), grid(0)
    for cell in cells:
        j, i = t_bands.index(cell.installation_band_c), t_bands.index(cell.temperature_band_c)
        k = tilt.index(cell.tilt_band_deg)
        u95[j][i][k] = cell.expanded_deg
        dof[j][i][k] = None if math.isinf(cell.combined.effective_dof) else round(cell.combined.effective_dof, 1)
        factor[j][i][k] = round(cell.combined.coverage_factor, 2)
        positions[j][i][k] = cell.positions
    return {
        "temperature_bands_c": [list(band) for band in t_bands],
        "tilt_bands_deg": [list(band) for band in tilt],
        "index": ["installation band", "reading band", "tilt band"],
        "u95_deg": u95,
        "effective_dof": dof,
        "coverage_factor": factor,
        "positions": positions,
    }
