"""``thermotilt fit --compare-families``: which model family the campaign
supports. The paper chose "the lowest order ... considering also the final
RMS error" (section 3.3); here each family is scored per set and axis by

- leave-one-position-out cross-validated RMSE: fitted on every other
  position, predicted on the one left out — what a new mounting would see;
- BIC (statsmodels OLS), which counts every row as independent and so
  favours larger families on autocorrelated logs: shown, not decisive.

The recommendation, per axis, is the family with the fewest terms whose CV
RMSE is within RECOMMEND_WITHIN of the best family's in both sets.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..surfaces import SETS
from .dataset import CalibrationDataError, Campaign
from .fit import design
from .newey_west import group_bounds

# Powers of (T, a, dT/dt), as fit.design takes them.
FAMILIES: dict[str, tuple[tuple[int, int, int], ...]] = {
    "poly11": ((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)),
    "poly22": ((0, 0, 0), (1, 0, 0), (0, 1, 0), (2, 0, 0), (1, 1, 0), (0, 2, 0)),
    "poly22+rate": ((0, 0, 0), (1, 0, 0), (0, 1, 0), (2, 0, 0), (1, 1, 0), (0, 2, 0), (0, 0, 1)),
    "poly33": tuple((i, total - i, 0) for total in range(4) for i in range(total, -1, -1)),
}
PAPER_FAMILY = "poly22"
RECOMMEND_WITHIN = 0.05
# A CV RMSE this many times the in-sample RMSE means a left-out position lies outside the others' span.
EXTRAPOLATION_RATIO = 3.0


@dataclass(frozen=True)
class FamilyScore:
    family: str
    set_name: str
    axis: str
    terms: int
    cv_rmse_lsb: float  # NaN, as the two below, for a family the campaign cannot determine
    rmse_lsb: float
    bic: float

    @property
    def determined(self) -> bool:
        return not math.isnan(self.cv_rmse_lsb)


def score(campaign: Campaign, family: str, set_name: str, axis: str) -> FamilyScore:
    data = campaign.sets[set_name]
    if data.rate_c_per_s is None:
        raise CalibrationDataError("the campaign has no temperature rates (a log without time_s?)")
    columns = design(data.temperature_c, data.acceleration[axis], FAMILIES[family], data.rate_c_per_s)
    residual = data.residual[axis]
    positions = group_bounds(data.position)
    if len(positions) < 3:
        raise CalibrationDataError(f"{set_name} set, {axis} axis: cross-validation needs at least 3 positions")
    # Each fold's normal equations are the campaign's minus the left-out
    # position's: one pass over the rows instead of one fit per position.
    grams = [columns[start:end].T @ columns[start:end] for start, end in positions]
    moments = [columns[start:end].T @ residual[start:end] for start, end in positions]
    total_gram, total_moment = sum(grams), sum(moments)
    terms = columns.shape[1]
    if np.linalg.matrix_rank(total_gram) < terms:
        return FamilyScore(family, set_name, axis, terms, math.nan, math.nan, math.nan)
    squared_error = 0.0
    for (start, end), gram, moment in zip(positions, grams, moments):
        params, *_ = np.linalg.lstsq(total_gram - gram, total_moment - moment, rcond=None)
        squared_error += float(np.sum((residual[start:end] - columns[start:end] @ params) ** 2))
    rows = len(residual)
    params, *_ = np.linalg.lstsq(total_gram, total_moment, rcond=None)
    sse = float(np.sum((residual - columns @ params) ** 2))
    return FamilyScore(
        family,
        set_name,
        axis,
        terms,
        float(np.sqrt(squared_error / rows)),
        float(np.sqrt(sse / (rows - terms))),
        gaussian_bic(sse, rows, terms),
    )


def gaussian_bic(sse: float, rows: int, parameters: int) -> float:
    """The BIC statsmodels' OLS gives a fit with a constant (its bic, with
    Gaussian errors), from the fit's sum of squared errors; computed here
    from the normal equations the cross-validation has already formed
    instead of a QR pass over every row (host/tests/test_families.py holds
    it to statsmodels')."""
    log_likelihood = -rows / 2.0 * (math.log(2.0 * math.pi) + math.log(sse / rows) + 1.0)
    return -2.0 * log_likelihood + math.log(rows) * parameters


def compare_families(campaign: Campaign, axes: tuple[str, ...]) -> list[FamilyScore]:
    return [score(campaign, family, set_name, axis) for axis in axes for set_name in SETS for family in FAMILIES]


def recommend(scores: list[FamilyScore]) -> dict[str, str]:
    """Per axis, the fewest terms whose CV RMSE is within RECOMMEND_WITHIN of
    the best in both sets; if none is, the smallest worst-case excess."""
    choices = {}
    for axis in dict.fromkeys(s.axis for s in scores):
        mine = [s for s in scores if s.axis == axis and s.determined]
        best = {
            set_name: min(s.cv_rmse_lsb for s in mine if s.set_name == set_name)
            for set_name in {s.set_name for s in mine}
        }

        def excess(family: str) -> float:
            return max(s.cv_rmse_lsb / best[s.set_name] - 1.0 for s in mine if s.family == family)

        families = list(dict.fromkeys(s.family for s in mine))
        if not families:
            continue
        acceptable = [family for family in families if excess(family) <= RECOMMEND_WITHIN]
        choices[axis] = (
            min(acceptable, key=lambda family: (len(FAMILIES[family]), family))
            if acceptable
            else min(families, key=excess)
        )
    return choices


def extrapolating(scores: list[FamilyScore]) -> list[str]:
    """Axes where the paper's family predicts a left-out position far worse
    than it fits the rest: too few levels of that axis's acceleration, so a
    quadratic in it extrapolates."""
    return sorted(
        {s.axis for s in scores if s.family == PAPER_FAMILY and s.cv_rmse_lsb > EXTRAPOLATION_RATIO * s.rmse_lsb}
    )


def format_families(scores: list[FamilyScore]) -> str:
    lines = [
        "model families (leave-one-position-out CV RMSE decides; BIC counts rows as independent):",
        f"{'family':<13}{'terms':>6}  {'set':<8}{'axis':<5}{'CV RMSE':>10}{'RMSE':>9}{'BIC':>14}",
    ]
    for s in scores:
        line = f"{s.family:<13}{s.terms:>6}  {'warming' if s.set_name == 'W' else 'cooling':<8}{s.axis:<5}"
        lines.append(
            line
            + (
                f"{s.cv_rmse_lsb:>10.2f}{s.rmse_lsb:>9.2f}{s.bic:>14.1f}"
                if s.determined
                else "  not determined: its terms do not vary independently in this campaign"
            )
        )
    for axis, choice in recommend(scores).items():
        lines.append(
            f"recommended for {axis}: {choice} (the fewest terms within {RECOMMEND_WITHIN:.0%} of the "
            f"best CV RMSE"
            + ("; the paper's family)" if choice == PAPER_FAMILY else f"; the paper used {PAPER_FAMILY})")
        )
    for axis in extrapolating(scores):
        lines.append(
            f"note: on {axis} the {PAPER_FAMILY} surface predicts a left-out position more than "
            f"{EXTRAPOLATION_RATIO:g}x worse than it fits: the campaign has too few inclinations on "
            f"{axis} for a quadratic in its acceleration; add positions on {axis}"
        )
    return "\n".join(lines)


def write_families(scores: list[FamilyScore], out_dir: Path) -> Path:
    """families.json: the recommendation and every score."""
    path = out_dir / "families.json"
    document = {"recommended": recommend(scores), "scores": [vars(score) for score in scores]}
    path.write_text(json.dumps(document, indent=2) + "\n")
    return path
