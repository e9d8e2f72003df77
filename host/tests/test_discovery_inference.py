"""The search's inference on residual blocks drawn from a known covariance:
the undeclared flicker's REML fit and the test of an effect that differs
between table positions, which slow noise imitates."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solve_triangular
from threadpoolctl import threadpool_limits

from thermotilt.discovery.channel import BlockTimes, Fit, UndeclaredFlicker, filtered_exponentials
from thermotilt.discovery.search import ALPHA
from thermotilt.physics.terms.sensor import FLICKER_TIME_CONSTANTS_S

BLOCK_S = 20.0
# The benchmark's staircase: X +30, X -30 and Y +30 deg, 46 blocks each.
BLOCKS_PER_POSITION = 46
FRAME_S = 0.1
DRAWS = 100
POSITIONS_SEEN = 12


def _layout(positions: int) -> tuple[np.ndarray, BlockTimes, np.ndarray]:
    position = np.repeat(np.arange(positions), BLOCKS_PER_POSITION)
    frames = int(BLOCK_S / FRAME_S)
    block = np.repeat(np.arange(len(position)), frames)
    times = BlockTimes(np.arange(len(block)) * FRAME_S, block, np.bincount(block))
    excursion = np.tile(np.linspace(-25.0, 15.0, BLOCKS_PER_POSITION), positions)
    design = np.column_stack(
        [column for p in range(positions) for column in ((position == p) * 1.0, (position == p) * excursion)]
    )
    return position, times, design


def _declared_and_drawn(times: BlockTimes) -> tuple[np.ndarray, np.ndarray]:
    """The model's flicker at unit variance per decade through the filter,
    and the covariance drawn from: that flicker 25x (the benchmark's
    "flicker" family, its floor 5x) plus white noise."""
    declared = times.covariance(filtered_exponentials(0.0, tuple((tau, 1.0) for tau in FLICKER_TIME_CONSTANTS_S)))
    return declared, 25.0 * declared + 2.0 * np.eye(len(declared))


@pytest.mark.slow
def test_a_difference_between_positions_is_not_found_in_flicker_the_model_does_not_declare() -> None:
    # Flicker 24x the declared variance (the benchmark's "flicker" family:
    # the floor 5x) moves each position's mean; a test that took the
    # within-position correlation for all there is named sensitivity_loss
    # on 5 of 12 such staircases.
    position, times, design = _layout(3)
    declared, truth = _declared_and_drawn(times)
    draw = np.linalg.cholesky(truth)
    sensitivity = np.select([position == 0, position == 1], [1.0, -1.0], 0.0)
    rng = np.random.default_rng(11)
    rejections = 0
    with threadpool_limits(limits=1, user_api="blas"):
        for _ in range(DRAWS):
            values = draw @ rng.standard_normal(len(position))
            lower = UndeclaredFlicker(design, declared, times, BLOCK_S).fitted(values)
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
    position, times, design = _layout(POSITIONS_SEEN)
    declared, truth = _declared_and_drawn(times)
    values = np.linalg.cholesky(truth) @ np.random.default_rng(3).standard_normal(len(position))
    with threadpool_limits(limits=1, user_api="blas"):
        lower = UndeclaredFlicker(design, declared, times, BLOCK_S).fitted(values)
    means = np.stack([(position == p) / BLOCKS_PER_POSITION for p in range(POSITIONS_SEEN)])
    steps = means[1:] - means[:-1]
    drawn = np.trace(steps @ truth @ steps.T)
    fitted = np.trace(steps @ (lower @ lower.T) @ steps.T)
    assert 0.5 < fitted / drawn < 2.0, fitted / drawn


def test_the_declared_noise_through_the_firmware_filter_has_the_autocovariance_computed_for_it() -> None:
    # White noise and a 10 s Gauss-Markov process (its root equal to the
    # filter's pole, the case the formula treats apart) through the
    # firmware's own Kalman filter. 3e6 samples hold ~3000 filter time
    # constants: the lag-0 and lag-10 s estimates are within ~4 % (one
    # standard error), so 15 % is about four.
    from scipy.signal import lfilter

    from thermotilt import native

    rng = np.random.default_rng(5)
    count, tau, variance, white = 3_000_000, 10.0, 25.0, 17.4**2
    rho = np.exp(-0.01 / tau)
    wander = lfilter([1.0], [1.0, -rho], rng.standard_normal(count) * np.sqrt(variance * (1.0 - rho**2)))
    samples = 1000.0 + wander + np.sqrt(white) * rng.standard_normal(count)
    output = native.kalman_estimates(samples).astype(float)[20000:] - 1000.0
    terms = filtered_exponentials(white, ((tau, variance),))
    for lag_s in (0.0, 10.0):
        lag = int(round(lag_s / 0.01))
        measured = float(np.mean(output[: len(output) - lag] * output[lag:]))
        computed = sum(c * np.exp(-lag_s / time_constant) for time_constant, c in terms.items())
        assert measured == pytest.approx(computed, rel=0.15), (lag_s, measured, computed)


def test_block_means_of_exponentials_are_the_double_sums_over_their_frames() -> None:
    time_s = np.concatenate([np.arange(0, 20, 0.1), np.arange(20, 35, 0.1) + 0.05, np.arange(50, 70, 0.1)])
    block = np.repeat([0, 1, 2], [200, 150, 200])
    times = BlockTimes(time_s, block, np.bincount(block))
    for time_constant in (1.0, 10.0, 1000.0):
        pairs = np.exp(-np.abs(np.subtract.outer(time_s, time_s)) / time_constant)
        direct = np.array([[pairs[block == i][:, block == j].mean() for j in range(3)] for i in range(3)])
        np.testing.assert_allclose(times.mean_exponential(time_constant), direct, rtol=1e-9)


def test_the_goodness_of_fit_is_at_its_level_where_the_declared_noise_is_the_truth() -> None:
    # The benchmark's staircase layout with the model's X noise declared
    # (slope 0.55 LSB/degC per position, flicker floor 0.82 LSB). Of 2000
    # draws from the declared covariance, the share beyond `allowed` at
    # level 0.05 is 0.05 +- 0.0049 (binomial SD): 0.035..0.065 is three.
    from thermotilt.discovery.channel import GoodnessOfFit
    from thermotilt.physics.terms.sensor import FLICKER_VARIANCE_PER_FLOOR

    position, times, _ = _layout(3)
    excursion = np.tile(np.linspace(-25.0, 15.0, BLOCKS_PER_POSITION), 3)
    flicker = tuple((tau, 0.82**2 * FLICKER_VARIANCE_PER_FLOOR) for tau in FLICKER_TIME_CONSTANTS_S)
    declared = 0.55**2 * np.outer(excursion, excursion) * np.equal.outer(position, position)
    declared += times.covariance(filtered_exponentials(17.4**2, flicker))
    draws = np.linalg.cholesky(declared) @ np.random.default_rng(8).standard_normal((len(position), 2000))
    counts = times.counts
    offset = np.ones((len(position), 1))
    outside = [not GoodnessOfFit.of("X", draw, counts, declared, 0.05, offset).explained for draw in draws.T]
    assert 0.035 <= np.mean(outside) <= 0.065, np.mean(outside)


class _Blocks:
    """A chamber channel's blocks as fit_floor reads them."""

    def __init__(self, y: np.ndarray, nuisance: np.ndarray, times: BlockTimes) -> None:
        self.y, self.nuisance, self.times = y, nuisance, times

    def unit_covariance(self, time_constant_s: float) -> np.ndarray:
        return self.times.mean_exponential(time_constant_s)


def _chamber_layout(blocks: int = 200) -> tuple[BlockTimes, np.ndarray]:
    """20 s blocks of 1 s readings, and two nuisance columns that decay
    from the start as a chamber's faces do (chamber_start_response)."""
    time_s = np.arange(blocks * 20, dtype=float)
    block = time_s.astype(int) // 20
    times = BlockTimes(time_s, block, np.bincount(block))
    start = times.start + 10.0
    return times, np.column_stack([np.exp(-start / 300.0), np.exp(-start / 40.0)])


def test_the_goodness_of_fit_beyond_the_chambers_start_is_at_its_level() -> None:
    # One Gauss-Markov process declared (0.06 degC, 200 s, as chamber_floor
    # measures), the start's response fitted out: of 2000 draws the share
    # beyond `allowed` at level 0.05 is 0.05 +- 0.0049, 0.035..0.065 three SD.
    from thermotilt.discovery.channel import GoodnessOfFit

    times, start = _chamber_layout()
    declared = 0.06**2 * times.mean_exponential(200.0)
    draws = np.linalg.cholesky(declared) @ np.random.default_rng(9).standard_normal((len(start), 2000))
    draws += start @ np.array([[3.0], [-1.0]])
    outside = [not GoodnessOfFit.of("inner", d, times.counts, declared, 0.05, start).explained for d in draws.T]
    assert 0.035 <= np.mean(outside) <= 0.065, np.mean(outside)


def test_the_chamber_floor_fit_recovers_a_known_process() -> None:
    # 20 runs of 200 blocks from 0.06 degC at 200 s: REML's estimates over
    # 4000 blocks. Across 50 such fits (seeds 0..49, run once) sigma's
    # spread was 3.4 % and tau's 6.9 %, both unbiased; 3.5 SD each side.
    from thermotilt.discovery.chamber_floor import fit_floor

    times, start = _chamber_layout()
    declared = 0.06**2 * times.mean_exponential(200.0)
    lower = np.linalg.cholesky(declared)
    rng = np.random.default_rng(10)
    runs = [
        _Blocks(lower @ rng.standard_normal(len(start)) + start @ rng.normal(size=2), start, times) for _ in range(20)
    ]
    floor = fit_floor(runs)
    assert floor.sigma_c == pytest.approx(0.06, rel=0.12)
    assert floor.time_constant_s == pytest.approx(200.0, rel=0.24)
