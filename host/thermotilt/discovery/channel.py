"""One channel of a run as the search (search.py) tests it: its residual
(measured minus replay) averaged over blocks of BLOCK_S within each table
position, whitened by the blocks' covariance (GLS), and fitted on the
whitened blocks with Newey-West (HAC) standard errors.

The covariance is what the model declares (on the acceleration channels
the random drift slope per mounting and the flicker of bias instability)
plus flicker and white noise it does not, fitted to the run; on the
chamber's channels the unknown start of the chamber is a nuisance.
docs/discovery.md ("Decision") states the rules.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import statsmodels.api as sm
from scipy import stats
from scipy.linalg import solve_triangular
from scipy.optimize import minimize

from .. import native
from ..physics import Model
from ..physics.terms.sensor import FLICKER_TIME_CONSTANTS_S, FLICKER_VARIANCE_PER_FLOOR
from ..surfaces import REFERENCE_C
from .chamber_floor import floors
from .reml import restricted_parts
from .replay import ACCELERATION_CHANNELS, CHAMBER_CHANNELS, SAMPLE_PERIOD_S, Measured

# Long against the Kalman filters' ~10 s and short against a 60 s
# staircase hold, so a block still follows the temperature.
BLOCK_S = 20.0
# A regressor this well explained by the nuisance columns (the channel's
# constant offset) cannot be told from them on this run.
NOT_TESTABLE_R2 = 0.999
# A regressor this well explained by one mounting's drift slope: what the
# slope leaves is a tenth of the effect or less (in standard errors).
ONE_SLOPE_R2 = 0.99
# A 95 % interval's half width in standard errors: every value discovery
# reports is this many either side.
HALF_WIDTH_95 = 1.96
# Two effects this correlated on a run (whitened, beyond the nuisance)
# cannot be told apart by it, whatever their fits say.
COLLINEAR = 0.99
# Longer runs get longer blocks, so the block covariance stays this small.
MAX_BLOCKS = 2000
# The undeclared AR(1)'s correlation from one block to the next stays
# below this, so that it is not a second offset per position.
MAX_AR_RHO = 0.99
# The undeclared noise's levels, as shares of the residual blocks'
# variance (natural logs): from none to far more than there is.
LOG_LEVEL_MIN = -14.0
LOG_LEVEL_MAX = 4.0
# White noise of at least this share of the residual blocks' variance
# keeps the fitted covariance well conditioned.
MIN_WHITE_SHARE = 1e-3
# A register holds a whole LSB: rounding adds a uniform error of +-0.5.
REGISTER_ROUNDING_VARIANCE = 1.0 / 12.0

# Why a candidate cannot be tested on a channel it does not act on in the
# run, which then cannot hold any of its gap.
NOTHING_MOVES_IT = "nothing in this run moves it"


def _nuisance(channel: str) -> bool:
    """The acceleration channels carry an unknown constant offset (the
    sensor's mounting on the table); the temperature channel does not."""
    return channel in ACCELERATION_CHANNELS


def gap_rms(channel: str, residual: np.ndarray) -> float:
    """RMS of a residual as the search judges it: about its mean where the
    channel has an unknown offset."""
    centred = residual - residual.mean() if _nuisance(channel) else residual
    return float(np.sqrt(np.mean(centred**2)))


@dataclass(frozen=True)
class Fit:
    """The regressors' coefficients, standard errors and two-sided p-values
    of a fit on whitened blocks.

    The whitening is by a covariance stated in LSB (not up to a scale), so
    the standard error is the GLS one with that covariance as it is; it
    carries the random slope per mounting, which one run shows only once
    per position and no residual-based error can see. The Newey-West (HAC)
    error of the whitened fit guards against correlation the covariance
    misses: the larger of the two is used."""

    params: np.ndarray
    bse: np.ndarray
    pvalues: np.ndarray

    @classmethod
    def of(cls, y_w: np.ndarray, design: np.ndarray, count: int) -> Fit:
        model = sm.OLS(y_w, design)
        lags = int(np.floor(4 * (len(y_w) / 100.0) ** (2.0 / 9.0)))
        robust = model.fit(cov_type="HAC", cov_kwds={"maxlags": lags})
        known = np.sqrt(np.diag(np.linalg.pinv(design.T @ design)))
        bse = np.maximum(known, robust.bse)[-count:]
        params = robust.params[-count:]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.abs(params / bse)
        return cls(params, bse, 2.0 * stats.norm.sf(z))


@dataclass(frozen=True)
class DeclaredNoise:
    """The noise discovery declares on a channel. On the acceleration
    channels the model's: a random drift slope per mounting (LSB/degC),
    flicker (one Gauss-Markov process per time constant with its variance,
    LSB^2) and white noise (LSB^2 per sample, the registers' rounding
    included), the last two at the IMU filter's input. On the chamber's
    channels the replay's measured floor (chamber_floor.py): one
    Gauss-Markov process in the readings themselves, which no filter of
    the IMU's smooths."""

    slope_sigma: float = 0.0
    flicker: tuple[tuple[float, float], ...] = ()  # (time constant s, variance)
    white_variance: float = 0.0
    through_imu_filter: bool = True

    @classmethod
    def of(cls, model: Model, channel: str) -> DeclaredNoise:
        if channel in CHAMBER_CHANNELS and channel in floors():
            floor = floors()[channel]
            return cls(flicker=((floor.time_constant_s, floor.sigma_c**2),), through_imu_filter=False)
        if channel not in ACCELERATION_CHANNELS:
            return cls()
        axis = channel.lower()
        slope = (
            float(model.terms["drift_repeatability"]["sigma_lsb_per_c"][axis])
            if model.enabled("drift_repeatability")
            else 0.0
        )
        flicker: tuple[tuple[float, float], ...] = ()
        if model.enabled("bias_instability"):
            floor = float(model.terms["bias_instability"]["allan_floor_lsb"][axis])
            variance = floor**2 * FLICKER_VARIANCE_PER_FLOOR
            flicker = tuple((tau, variance) for tau in FLICKER_TIME_CONSTANTS_S)
        white = (
            float(model.terms["noise"]["sigma_lsb"][axis]) ** 2 + REGISTER_ROUNDING_VARIANCE
            if model.enabled("noise")
            else 0.0
        )
        return cls(slope, flicker, white)

    def exponentials(self) -> dict[float, float]:
        """The autocovariance of the channel's noise as {time constant s:
        coefficient} of exponentials in the lag."""
        if self.through_imu_filter:
            return filtered_exponentials(self.white_variance, self.flicker)
        return dict(self.flicker)


@functools.cache
def filter_pole() -> float:
    """The firmware's Kalman filter in steady state is the exponential
    smoother estimate += gain * (sample - estimate): its pole 1 - gain per
    sample, read from the filter itself (thermotilt.native) as the decay of
    its step response long after a reset (lib/Kalman: the gain settles
    within 0.5 % after ~3000 samples)."""
    settle, after, size = 20000, 1000, 1.0e4
    samples = np.zeros(settle + after + 1)
    samples[settle:] = size
    estimate = float(native.kalman_estimates(samples)[settle + after])
    return float((1.0 - estimate / size) ** (1.0 / (after + 1)))


def filtered_exponentials(white_variance: float, gauss_markov: tuple[tuple[float, float], ...]) -> dict[float, float]:
    """The autocovariance of the filter's output, as {time constant s:
    coefficient} of exponentials in the lag, for white noise (variance per
    sample) and Gauss-Markov processes (time constant s, variance) at its
    input. Each Gauss-Markov process through the smoother is an AR(2) with
    the roots rho and the pole, whose autocovariance is the standard sum of
    two geometric terms (Brockwell and Davis, Introduction to Time Series
    and Forecasting, 3.3); white noise is the filter's own geometric term."""
    pole = filter_pole()
    gain = 1.0 - pole
    filter_s = -SAMPLE_PERIOD_S / math.log(pole)
    terms = {filter_s: white_variance * gain / (1.0 + pole)}
    for tau, variance in gauss_markov:
        rho = math.exp(-SAMPLE_PERIOD_S / tau)
        if abs(rho - pole) < 1e-9:
            # Equal roots make the two terms one of another form; a root
            # moved by 1e-9 changes the covariance by about 1e-6 of itself.
            rho = pole - 1e-9
        innovation = gain**2 * variance * (1.0 - rho**2)
        common = innovation / ((rho - pole) * (1.0 - rho * pole))
        terms[-SAMPLE_PERIOD_S / math.log(rho)] = terms.get(-SAMPLE_PERIOD_S / math.log(rho), 0.0) + (
            common * rho / (1.0 - rho**2)
        )
        terms[filter_s] -= common * pole / (1.0 - pole**2)
    return terms


class BlockTimes:
    """Where each block of a channel lies in time: its frames' times, the
    block each belongs to, and each block's first and last frame."""

    def __init__(self, time_s: np.ndarray, block: np.ndarray, counts: np.ndarray) -> None:
        self.time_s, self.block, self.counts = time_s, block, counts
        self.start = np.full(len(counts), np.inf)
        np.minimum.at(self.start, block, time_s)
        self.end = np.full(len(counts), -np.inf)
        np.maximum.at(self.end, block, time_s)

    def mean_exponential(self, time_constant_s: float) -> np.ndarray:
        """Block by block, the mean over pairs of their frames of
        exp(-|lag| / time constant): blocks do not overlap, so for one
        before another the double sum factors into the first's tail and
        the second's head; within a block the frames are evenly spaced."""
        decay = 1.0 / time_constant_s
        tail = np.bincount(self.block, np.exp(-(self.end[self.block] - self.time_s) * decay)) / self.counts
        head = np.bincount(self.block, np.exp(-(self.time_s - self.start[self.block]) * decay)) / self.counts
        before = self.start[:, None] < self.start[None, :]
        between = np.where(before, self.start[None, :] - self.end[:, None], 0.0)
        upper = np.where(before, np.exp(-np.maximum(between, 0.0) * decay) * np.outer(tail, head), 0.0)
        covariance = upper + upper.T
        m = self.counts.astype(float)
        spacing = np.where(m > 1, (self.end - self.start) / np.maximum(m - 1, 1), 0.0)
        r = np.exp(-spacing * decay)
        with np.errstate(divide="ignore", invalid="ignore"):
            pairs = np.where(r < 1.0, r * (m * (1.0 - r) - (1.0 - r**m)) / (1.0 - r) ** 2, m * (m - 1) / 2.0)
        covariance[np.diag_indices_from(covariance)] = (m + 2.0 * pairs) / m**2
        return covariance

    def covariance(self, exponentials: dict[float, float]) -> np.ndarray:
        covariance = np.zeros((len(self.counts), len(self.counts)))
        for time_constant_s, coefficient in exponentials.items():
            if coefficient:
                covariance += coefficient * self.mean_exponential(time_constant_s)
        return covariance


@dataclass(frozen=True)
class GoodnessOfFit:
    """Whether the noise declared on a channel explains its residual. gap:
    the RMS of what its nuisance leaves of its block means (their mean on
    an acceleration channel, the chamber's start on the chamber's; each
    block weighted by its rows, in the channel's unit); allowed: the RMS
    the declared noise alone exceeds with probability `level`; p_value:
    that it exceeds the gap."""

    channel: str
    gap: float
    allowed: float
    p_value: float
    level: float

    @property
    def explained(self) -> bool:
        return self.explained_at(1.0)

    def explained_at(self, share: float) -> bool:
        """Explained at this share of the level (a stricter test below 1)."""
        return self.p_value >= self.level * share

    @classmethod
    def of(  # noqa: PLR0913 - the blocks, their weights and covariance, the level and the nuisance
        cls,
        channel: str,
        blocks: np.ndarray,
        counts: np.ndarray,
        declared: np.ndarray,
        level: float,
        nuisance: np.ndarray,
    ) -> GoodnessOfFit:
        """The gap is what a fit of the nuisance columns (an offset, the
        chamber's start), weighted by the blocks' rows, leaves of them. Its
        square is a quadratic form y'Ay of the blocks (A = M'WM, M that
        fit's residual maker), so under the declared covariance S it is a sum
        of chi-squares weighted by the eigenvalues of AS. Its tail is taken
        from the first three cumulants, the traces of the powers of AS, by
        Hall-Buckley-Eagleson's scaled chi-square (Bodenham and Adams,
        Statistics and Computing 26, 2016, compare it with exact methods;
        test_discovery_inference checks it against draws). Written here: no
        maintained library offers it."""
        weights = counts / counts.sum()
        weighted = nuisance * weights[:, None]
        maker = np.eye(len(blocks))
        if nuisance.shape[1]:
            maker -= nuisance @ np.linalg.solve(nuisance.T @ weighted, weighted.T)
        left = maker @ blocks
        gap_square = float(weights @ left**2)
        product = (maker.T * weights) @ maker @ declared
        squared = product @ product
        first, second, third = np.trace(product), np.trace(squared), float(np.sum(squared * product.T))
        dof = second**3 / third**2 if third > 0 else np.inf
        spread = math.sqrt(2.0 * second) / math.sqrt(2.0 * dof)
        p_value = float(stats.chi2.sf(dof + (gap_square - first) / spread, dof))
        allowed_square = first + (float(stats.chi2.isf(level, dof)) - dof) * spread
        return cls(channel, math.sqrt(gap_square), math.sqrt(max(allowed_square, 0.0)), p_value, level)


class UndeclaredFlicker:
    """Flicker and white noise the model does not declare on an acceleration
    channel, at levels fitted by restricted maximum likelihood (REML) to the
    residual blocks on top of the declared covariance.

    The flicker has the model's shape (one Gauss-Markov process per decade
    of time constant, equal variances, across the whole run), the MEMS bias
    instability's. It is what moves a position's mean against the others',
    which a test of an effect that differs between positions must allow for,
    yet a run of a few positions cannot measure: its decades as slow as a
    block or slower are seen within a position (faster ones, averaged in a
    block and smoothed by the filters, pass for white), and the 1/f shape
    says how far the slower ones move the means. Noise of another shape (a
    bias wander of one time constant) is read as flicker: a safe error,
    since it widens intervals.

    REML integrates out a free offset and slope per position, so that no
    effect constant or linear within a position is taken for noise."""

    def __init__(self, design: np.ndarray, declared: np.ndarray, times: BlockTimes, block_s: float) -> None:
        self.design = design
        self.declared = declared
        slow = tuple((tau, 1.0) for tau in FLICKER_TIME_CONSTANTS_S if tau >= block_s)
        self.unit_flicker = times.covariance(filtered_exponentials(0.0, slow))

    def covariance(self, theta: np.ndarray, scale: float) -> np.ndarray:
        flicker, white = np.exp(theta)
        undeclared = flicker * self.unit_flicker
        undeclared[np.diag_indices_from(undeclared)] += white + MIN_WHITE_SHARE
        return self.declared + scale * undeclared

    def fitted(self, values: np.ndarray) -> np.ndarray:
        """The lower Cholesky factor of the fitted covariance."""
        left = _left_by(self.design, values)
        scale = max(float(np.mean(left**2)), 1e-12)

        def restricted_deviance(theta: np.ndarray) -> float:
            try:
                return sum(restricted_parts(self.covariance(theta, scale), self.design, values))
            except np.linalg.LinAlgError:
                return 1e300

        bounds = [(LOG_LEVEL_MIN, LOG_LEVEL_MAX)] * 2
        theta = minimize(restricted_deviance, np.log([0.1, 0.5]), method="L-BFGS-B", bounds=bounds).x
        return np.linalg.cholesky(self.covariance(theta, scale))


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    return abs(float(a @ b)) / float(np.linalg.norm(a) * np.linalg.norm(b))


def _left_by(design: np.ndarray, values: np.ndarray) -> np.ndarray:
    """What a least-squares fit of the design's columns leaves of values."""
    return values - design @ np.linalg.lstsq(design, values, rcond=None)[0]


def _position_ar1(left: np.ndarray, same: np.ndarray, mounting: np.ndarray, declared: np.ndarray) -> np.ndarray:
    """An AR(1) within each position for what a free offset and slope per
    position leave beyond the declared noise: its variance and lag-1
    covariance less the declared covariance's (method of moments). The
    temperature and chamber channels' undeclared noise: the readings'
    rounding, a real rig's."""
    total = max(float(np.mean(left**2)), 1e-12)
    neighbours = mounting[1:] == mounting[:-1]
    lag1 = float(np.mean((left[1:] * left[:-1])[neighbours])) if neighbours.any() else 0.0
    declared_lag1 = float(np.mean(np.diagonal(declared, 1)[neighbours])) if neighbours.any() else 0.0
    variance = max(total - float(np.mean(np.diagonal(declared))), 0.0)
    rho = float(np.clip((lag1 - declared_lag1) / variance, 0.0, MAX_AR_RHO)) if variance > 0.0 else 0.0
    index = np.arange(len(left))
    return variance * rho ** np.abs(np.subtract.outer(index, index)) * same + MIN_WHITE_SHARE * total * np.eye(
        len(left)
    )


class Channel:
    """One channel's blocks and its whitening, fixed for a round.

    The whitening is by the covariance the model declares (DeclaredNoise)
    plus what it does not, fitted to the residual: UndeclaredFlicker on the
    acceleration channels, an AR(1) within each position on the others."""

    def __init__(
        self,
        measured: Measured,
        channel: str,
        residual: np.ndarray,
        temperature_c: np.ndarray,
        noise: DeclaredNoise,
        start_response: np.ndarray | None = None,
        noise_residual: np.ndarray | None = None,
    ) -> None:
        """noise_residual: what the undeclared noise is fitted to, if not the residual
        itself (the residual less an effect found in it: the noise is then
        not taken to hold that effect)."""
        self.name = channel
        self._measured, self._residual, self._temperature_c = measured, residual, temperature_c
        self._noise, self._start_response = noise, start_response
        used = measured.used[channel]
        self.rows = used
        self.residual_rows = residual[used]
        mounting = measured.mounting[used]
        time_s = measured.time_s[used]
        start = time_s[np.searchsorted(mounting, mounting)]
        span = time_s[-1] - time_s[0]
        block_s = max(BLOCK_S, span / MAX_BLOCKS)
        keys = mounting * 10**9 + np.floor((time_s - start) / block_s).astype(np.int64)
        _, self._block, counts = np.unique(keys, return_inverse=True, return_counts=True)
        self._counts = counts
        self._mounting = np.rint(self.blocks(mounting.astype(float))).astype(np.int64)
        self.times = times = BlockTimes(time_s, self._block, counts)
        self._excursion = excursion = self.blocks(temperature_c[used]) - REFERENCE_C
        self.y = self.blocks(self.residual_rows)
        if _nuisance(channel):
            self.nuisance = np.ones((len(self.y), 1))
        elif start_response is not None:
            self.nuisance = np.column_stack([self.blocks(column[used]) for column in start_response.T])
        else:
            self.nuisance = np.empty((len(self.y), 0))
        noise_blocks = self.y if noise_residual is None else self.blocks(noise_residual[used])
        self.whiten = self._whitening(times, excursion, block_s, noise, noise_blocks)
        self.y_w = self.whiten(self.y)
        self.nuisance_w = self.whiten(self.nuisance)

    def blocks(self, values: np.ndarray) -> np.ndarray:
        return np.bincount(self._block, weights=values) / self._counts

    def goodness_of_fit(self, level: float) -> GoodnessOfFit:
        """The residual beyond the nuisance against the noise declared here."""
        return GoodnessOfFit.of(self.name, self.y, self._counts, self.declared, level, self.nuisance)

    def unit_covariance(self, time_constant_s: float) -> np.ndarray:
        """The blocks' covariance for a Gauss-Markov process of unit
        variance in the channel's values."""
        return self.times.mean_exponential(time_constant_s)

    def refitted(self, effect_rows: np.ndarray) -> Channel:
        """The same channel with its undeclared noise fitted to the residual
        less an effect found in it (rows)."""
        return Channel(
            self._measured,
            self.name,
            self._residual,
            self._temperature_c,
            self._noise,
            self._start_response,
            noise_residual=self._residual - effect_rows,
        )

    def _whitening(
        self,
        times: BlockTimes,
        excursion: np.ndarray,
        block_s: float,
        noise: DeclaredNoise,
        noise_blocks: np.ndarray,
    ) -> Callable[[np.ndarray], np.ndarray]:
        same = np.equal.outer(self._mounting, self._mounting)
        declared = noise.slope_sigma**2 * np.outer(excursion, excursion) * same
        declared += times.covariance(noise.exponentials())
        self.declared = declared
        columns = []
        for m in np.unique(self._mounting):
            inside = (self._mounting == m).astype(float)
            columns += [inside[:, None], (inside * excursion)[:, None]]
        design = np.hstack(columns)
        if self.name in ACCELERATION_CHANNELS:
            lower = UndeclaredFlicker(design, declared, times, block_s).fitted(noise_blocks)
        else:
            left = _left_by(design, noise_blocks)
            lower = np.linalg.cholesky(declared + _position_ar1(left, same, self._mounting, declared))

        def whiten(values: np.ndarray) -> np.ndarray:
            return solve_triangular(lower, values, lower=True)

        return whiten

    def fit(self, regressors: np.ndarray, left: np.ndarray | None = None) -> Fit:
        """GLS of the residual blocks (or of `left`, blocks of what an
        effect leaves of them) on the nuisance and these regressors (block
        means, one column each)."""
        design = np.hstack([self.nuisance_w, self.whiten(regressors)])
        return Fit.of(self.y_w if left is None else self.whiten(left), design, regressors.shape[1])

    def beyond_nuisance(self, whitened: np.ndarray) -> np.ndarray:
        """What of whitened blocks the nuisance columns do not explain."""
        if not self.nuisance_w.shape[1]:
            return whitened
        return _left_by(self.nuisance_w, whitened)

    def joint_p_values(self, first: np.ndarray, second: np.ndarray) -> tuple[float, float]:
        """The p-values of two effects (block means) fitted together; both 1
        where their whitened effects beyond the nuisance correlate at
        COLLINEAR or more, which this run cannot tell apart whatever a fit
        says."""
        beyond = [self.beyond_nuisance(self.whiten(g)) for g in (first, second)]
        if _correlation(*beyond) >= COLLINEAR:
            return 1.0, 1.0
        first_p, second_p = self.fit(np.column_stack([first, second])).pvalues
        return float(first_p), float(second_p)

    def untestable(self, regressor: np.ndarray) -> str:
        """Why this run cannot test an effect of these block means here, in
        a few words; "" where it can."""
        return self._untestable(self.whiten(regressor))

    def why_not_testable(self, regressor: np.ndarray) -> str:
        """untestable's reason, or else that the effect is a drift slope of
        one mounting: one that moves a single mounting, and there as a slope
        in temperature, is one draw of that mounting's random slope, which
        no run can tell from a spread of slopes wider than the model
        declares; "" where this run can test it."""
        g = self.whiten(regressor)
        return self._untestable(g) or self._one_mounting_slope(g)

    def _untestable(self, g: np.ndarray) -> str:
        total = float(g @ g)
        if total == 0.0:
            return NOTHING_MOVES_IT
        left = self.beyond_nuisance(g)
        if 1.0 - float(left @ left) / total < NOT_TESTABLE_R2:
            return ""
        if self.name in ACCELERATION_CHANNELS:
            return "a constant offset on this run, which the sensor's measuring offset takes"
        return "what the chamber's unknown start already fits"

    def _one_mounting_slope(self, g: np.ndarray) -> str:
        """For a whitened g that moves something (_untestable said "")."""
        total = float(g @ g)
        for beside in self._one_mounting_designs:
            left = _left_by(beside, g)
            if 1.0 - float(left @ left) / total >= ONE_SLOPE_R2:
                return "a drift slope of one mounting, which the model's random slope per mounting makes as well"
        return ""

    @functools.cached_property
    def _one_mounting_designs(self) -> list[np.ndarray]:
        """The whitened nuisance beside each mounting's drift slope in
        temperature, where the model declares a random one."""
        if self._noise.slope_sigma == 0.0:
            return []
        return [
            np.hstack([self.nuisance_w, self.whiten(((self._mounting == mounting) * self._excursion)[:, None])])
            for mounting in np.unique(self._mounting)
        ]

    def reduction(self, explained_rows: np.ndarray) -> float:
        """The share of the RMS residual an effect takes off."""
        before = gap_rms(self.name, self.residual_rows)
        after = gap_rms(self.name, self.residual_rows - explained_rows)
        return 1.0 - after / before if before > 0 else 0.0
