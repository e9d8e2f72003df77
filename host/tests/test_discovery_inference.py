"""The search's inference on residual blocks drawn from a known covariance:
the undeclared flicker's REML fit and the test of an effect that differs
between table positions, which slow noise imitates."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solve_triangular
from threadpoolctl import threadpool_limits

from thermotilt.discovery.channel import Fit, UndeclaredFlicker, _flicker_blocks
from thermotilt.discovery.search import ALPHA
from thermotilt.physics.terms.sensor import FLICKER_TIME_CONSTANTS_S

BLOCK_S = 20.0
# The benchmark's staircase: X +30, X -30 and Y +30 deg, 46 blocks each.
BLOCKS_PER_POSITION = 46
DRAWS = 100
POSITIONS_SEEN = 12


def _layout(positions: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    position = np.repeat(np.arange(positions), BLOCKS_PER_POSITION)
    time_s = np.arange(len(position)) * BLOCK_S
    excursion = np.tile(np.linspace(-25.0, 15.0, BLOCKS_PER_POSITION), positions)
    design = np.column_stack(
        [column for p in range(positions) for column in ((position == p) * 1.0, (position == p) * excursion)]
    )
    return position, np.abs(np.subtract.outer(time_s, time_s)), design


def _declared_and_drawn(lag_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The model's flicker at unit variance per decade, and the covariance
    drawn from: that flicker 25x (the benchmark's "flicker" family, its
    floor 5x) plus white noise."""
    declared = _flicker_blocks(lag_s, BLOCK_S, tuple((tau, 1.0) for tau in FLICKER_TIME_CONSTANTS_S))
    return declared, 25.0 * declared + 2.0 * np.eye(len(lag_s))


@pytest.mark.slow
def test_a_difference_between_positions_is_not_found_in_flicker_the_model_does_not_declare() -> None:
    # Flicker 24x the declared variance (the benchmark's "flicker" family:
    # the floor 5x) moves each position's mean; a test that took the
    # within-position correlation for all there is named sensitivity_loss
    # on 5 of 12 such staircases.
    position, lag_s, design = _layout(3)
    declared, truth = _declared_and_drawn(lag_s)
    draw = np.linalg.cholesky(truth)
    sensitivity = np.select([position == 0, position == 1], [1.0, -1.0], 0.0)
    rng = np.random.default_rng(11)
    rejections = 0
    with threadpool_limits(limits=1, user_api="blas"):
        for _ in range(DRAWS):
            values = draw @ rng.standard_normal(len(position))
            lower = UndeclaredFlicker(design, declared, lag_s, BLOCK_S).fitted(values)
            columns = np.column_stack([np.ones(len(position)), sensitivity, values])
            whitened = solve_triangular(lower, columns, lower=True)
            rejections += Fit.of(whitened[:, 2], whitened[:, :2], 1).pvalues[0] < ALPHA
    # At a true size of 5 %, 12 or more of 100 happen with probability
    # 0.5 % (binomial).
    assert rejections < 12, rejections


def test_the_fitted_covariance_moves_position_means_as_the_drawn_flicker_does() -> None:
    # What the test of a difference between positions needs from the fit:
    # the variance of one position's mean against the next, here within a
    # factor of 2 of the drawn covariance's, on 12 positions.
    position, lag_s, design = _layout(POSITIONS_SEEN)
    declared, truth = _declared_and_drawn(lag_s)
    values = np.linalg.cholesky(truth) @ np.random.default_rng(3).standard_normal(len(position))
    with threadpool_limits(limits=1, user_api="blas"):
        lower = UndeclaredFlicker(design, declared, lag_s, BLOCK_S).fitted(values)
    means = np.stack([(position == p) / BLOCKS_PER_POSITION for p in range(POSITIONS_SEEN)])
    steps = means[1:] - means[:-1]
    drawn = np.trace(steps @ truth @ steps.T)
    fitted = np.trace(steps @ (lower @ lower.T) @ steps.T)
    assert 0.5 < fitted / drawn < 2.0, fitted / drawn
