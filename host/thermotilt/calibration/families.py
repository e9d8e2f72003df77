"""``thermotilt fit --compare-families``: which model family the campaign
supports. The paper chose "the lowest order ... considering also the final
RMS error" (section 3.3); here each family is scored per set and axis by

- leave-one-position-out cross-validated RMSE: fitted on every other
  position, predicted on the one left out — what a new mounting would see;
- BIC (statsmodels OLS), which counts every row as independent and so
  favours larger families on autocorrelated logs: shown, not decisive.

The recommendation is the family with the fewest terms whose CV RMSE is
within RECOMMEND_WITHIN of the best family's, for every set and axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import statsmodels.api as sm

from ..coefficients import SETS
from .dataset import Campaign, CalibrationDataError
from .fit import design

# Powers of (T, a, dT/dt), as fit.design takes them.
FAMILIES: dict[str, tuple[tuple[int, int, int], ...]] = {
    "poly11": ((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)),
    "poly22": ((0, 0, 0), (1, 0, 0), (0, 1, 0), (2, 0, 0), (1, 1, 0), (0, 2, 0)),
    "poly22+rate": ((0, 0, 0), (1, 0, 0), (0, 1, 0), (2, 0, 0), (1, 1, 0), (0, 2, 0), (0, 0, 1)),
    "poly33": tuple((i, total - i, 0) for total in range(4) for i in range(total, -1, -1)),
}
PAPER_FAMILY = "poly22"
RECOMMEND_WITHIN = 0.05


@dataclass(frozen=True)
class FamilyScore:
    family: str
    set_name: str
    axis: str
    terms: int
    cv_rmse_lsb: float
    rmse_lsb: float
    bic: float


def score(campaign: Campaign, family: str, set_name: str, axis: str) -> FamilyScore:
    data = campaign.sets[set_name]
    if data.rate_c_per_s is None:
        raise CalibrationDataError("the campaign has no temperature rates (a log without time_s?)")
    columns = design(data.temperature_c, data.acceleration[axis], FAMILIES[family], data.rate_c_per_s)
    residual = data.residual[axis]
    positions = np.unique(data.position)
    if positions.size < 3:
        raise CalibrationDataError(f"{set_name} set, {axis} axis: cross-validation needs at least 3 positions")
    # Each fold's normal equations are the campaign's minus the left-out
    # position's: one pass over the rows instead of one fit per position.
    groups = [data.position == position for position in positions]
    grams = [columns[rows].T @ columns[rows] for rows in groups]
    moments = [columns[rows].T @ residual[rows] for rows in groups]
    total_gram, total_moment = sum(grams), sum(moments)
    if np.linalg.matrix_rank(total_gram) < columns.shape[1]:
        raise CalibrationDataError(f"{set_name} set, {axis} axis: the campaign cannot determine the terms "
                                   f"of {family} (a column such as dT/dt does not vary independently)")
    squared_error = 0.0
    for rows, gram, moment in zip(groups, grams, moments):
        params, *_ = np.linalg.lstsq(total_gram - gram, total_moment - moment, rcond=None)
        squared_error += float(np.sum((residual[rows] - columns[rows] @ params) ** 2))
    full = sm.OLS(residual, columns).fit(method="qr")
    return FamilyScore(family, set_name, axis, columns.shape[1],
                       float(np.sqrt(squared_error / len(residual))),
                       float(np.sqrt(full.ssr / full.df_resid)), float(full.bic))


def compare_families(campaign: Campaign, axes: tuple[str, ...]) -> list[FamilyScore]:
    return [score(campaign, family, set_name, axis)
            for axis in axes for set_name in SETS for family in FAMILIES]


def recommend(scores: list[FamilyScore]) -> str:
    """The fewest terms whose CV RMSE is within RECOMMEND_WITHIN of the best
    in every set and axis; if none is, the smallest worst-case excess."""
    keys = {(s.set_name, s.axis) for s in scores}
    best = {key: min(s.cv_rmse_lsb for s in scores if (s.set_name, s.axis) == key) for key in keys}

    def excess(family: str) -> float:
        return max(s.cv_rmse_lsb / best[(s.set_name, s.axis)] - 1.0 for s in scores if s.family == family)

    families = [family for family in FAMILIES if any(s.family == family for s in scores)]
    acceptable = [family for family in families if excess(family) <= RECOMMEND_WITHIN]
    if acceptable:
        return min(acceptable, key=lambda family: (len(FAMILIES[family]), family))
    return min(families, key=excess)


def format_families(scores: list[FamilyScore]) -> str:
    lines = ["model families (leave-one-position-out CV RMSE decides; BIC counts rows as independent):",
             f"{'family':<13}{'terms':>6}  {'set':<8}{'axis':<5}{'CV RMSE':>10}{'RMSE':>9}{'BIC':>14}"]
    for s in scores:
        lines.append(f"{s.family:<13}{s.terms:>6}  {'warming' if s.set_name == 'W' else 'cooling':<8}"
                     f"{s.axis:<5}{s.cv_rmse_lsb:>10.2f}{s.rmse_lsb:>9.2f}{s.bic:>14.1f}")
    choice = recommend(scores)
    lines.append(f"recommended: {choice} (the fewest terms within {RECOMMEND_WITHIN:.0%} of the best CV RMSE"
                 + ("; the paper's family" if choice == PAPER_FAMILY else f"; the paper used {PAPER_FAMILY}")
                 + ")")
    return "\n".join(lines)
