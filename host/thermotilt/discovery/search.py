"""Which candidate explains the gap between a run and its replay, decided
with inference that survives the residual's autocorrelation.

Each channel's residual (measured minus replay) is averaged over blocks of
BLOCK_S within each table position, which leaves a few hundred points whose
correlation is modelled, not ignored: what the model itself declares (on
the acceleration channels the random drift slope per mounting and the
flicker of bias instability) plus flicker and white noise it does not,
fitted to the run. Every block is whitened with that covariance (GLS), and
each candidate's effect (its replayed regressor) is tested on the whitened
blocks with Newey-West (HAC) standard errors, a guard against correlation
the fit misses. The p-values of all candidates and channels of a round are
adjusted for the false-discovery rate (Benjamini-Yekutieli); a candidate is
found only when it is significant after that, shrinks the channel's RMS
residual by at least MIN_GAP_REDUCTION, has a value its parameter can take
and no other channel's data reject the change it makes there. The chamber's
channels carry the unknown start of the chamber as nuisance columns.
docs/discovery.md states the rules.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
import statsmodels.api as sm
from scipy import stats
from scipy.interpolate import CubicSpline
from scipy.linalg import solve_triangular
from scipy.optimize import minimize, minimize_scalar
from statsmodels.stats.multitest import multipletests
from threadpoolctl import threadpool_limits

from ..physics import Model
from ..physics.document import plain
from ..physics.terms.sensor import (
    FLICKER_TIME_CONSTANTS_S,
    FLICKER_VARIANCE_PER_FLOOR,
    REFERENCE_C,
)
from .candidates import BY_NAME, CANDIDATES, Candidate, experiment
from .replay import ACCELERATION_CHANNELS, CHAMBER_CHANNELS, Measured, Replay

ALPHA = 0.05
# Benjamini-Yekutieli, not Benjamini-Hochberg: one round's tests share each
# channel's residual and test correlated regressors, a dependence under
# which only BY bounds the false-discovery rate. On the slow noise families
# each test's size is at its nominal level (docs/discovery.md), so the rate
# a run names anything at is set here.
MULTIPLE_TESTING = "fdr_by"
# Long against the Kalman filters' ~10 s and short against a 60 s
# staircase hold, so a block still follows the temperature.
BLOCK_S = 20.0
# A candidate must take at least this share off the channel's RMS residual:
# an effect as large as the noise (SNR 1) takes 29 %, SNR 0.5 takes 11 %.
MIN_GAP_REDUCTION = 0.10
# A regressor this well explained by the nuisance columns (the channel's
# constant offset) cannot be told from them on this run.
NOT_TESTABLE_R2 = 0.999
# Two effects this correlated on a run (whitened, beyond the nuisance)
# cannot be told apart by it, whatever their fits say.
COLLINEAR = 0.99
MAX_ROUNDS = 4
# Gauss-Newton on a candidate not linear in its parameter: at most this
# many steps, stopping when a step is below this share of its probe.
GAUSS_NEWTON_STEPS = 6
GAUSS_NEWTON_TOLERANCE = 0.01
# A candidate that is not additive is tabulated at most this far apart in
# the log of its value, then, about each channel's best value, at half that
# spacing, and interpolated between: for sensor_lag on the staircase the
# interpolant at half this spacing is off by 0.16 LSB at most where the
# effect is 245 LSB and the noise 6 LSB RMS, so the minimum it gives is
# where the exact one is, well within its interval; the value found is
# replayed. The coarse points only say where to look: the minimum is
# bracketed by the fine ones.
NONLINEAR_GRID_STEP = 1.0
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


@dataclass(frozen=True)
class Test:
    """One candidate on one channel in one round. value: the parameter's
    value that explains the residual best (for an additive candidate the
    model's plus the fitted change), with its 95 % interval; p_value: that
    the effect is zero."""

    candidate: str
    channel: str
    testable: bool
    value: float = float("nan")
    interval: tuple[float, float] = (float("nan"), float("nan"))
    p_value: float = float("nan")
    adjusted_p: float = float("nan")
    gap_reduction: float = float("nan")

    @property
    def key(self) -> tuple[str, str]:
        return self.candidate, self.channel


@dataclass
class Tabulated:
    """A candidate's effect per channel (rows) at log values, in order."""

    log_values: list[float]
    effects: dict[str, list[np.ndarray]]

    def add(self, log_value: float, predicted: Mapping[str, np.ndarray], base: Mapping[str, np.ndarray]) -> None:
        at = int(np.searchsorted(self.log_values, log_value))
        self.log_values.insert(at, log_value)
        for channel, rows in self.effects.items():
            rows.insert(at, predicted[channel] - base[channel])


@dataclass(frozen=True)
class Effect:
    candidate: str
    channel: str
    parameter: str
    unit: str
    value: float  # the parameter's new value in the written model
    interval: tuple[float, float]
    adjusted_p: float
    gap_reduction: float


@dataclass(frozen=True)
class Ambiguity:
    names: tuple[str, ...]
    channel: str
    experiment: str


@dataclass
class Outcome:
    verdict: str
    model: Model
    effects: list[Effect] = field(default_factory=list)
    ambiguous: list[Ambiguity] = field(default_factory=list)
    not_testable: list[str] = field(default_factory=list)
    rounds: list[list[Test]] = field(default_factory=list)
    residual_before: dict[str, np.ndarray] = field(default_factory=dict)
    residual_after: dict[str, np.ndarray] = field(default_factory=dict)
    gap: dict[str, dict[str, float]] = field(default_factory=dict)


def _nuisance(channel: str) -> bool:
    """The acceleration channels carry an unknown constant offset (the
    sensor's mounting on the table); the temperature channel does not."""
    return channel in ACCELERATION_CHANNELS


def gap_rms(channel: str, residual: np.ndarray) -> float:
    """RMS of a residual as this module judges it: about its mean where the
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
    """The noise the model declares on a channel, as block covariances: a
    random drift slope per mounting (LSB/degC) and flicker, one Gauss-Markov
    process per time constant with its variance (LSB^2)."""

    slope_sigma: float = 0.0
    flicker: tuple[tuple[float, float], ...] = ()  # (time constant s, variance)

    @classmethod
    def of(cls, model: Model, channel: str) -> DeclaredNoise:
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
        return cls(slope, flicker)


def _flicker_blocks(lag_s: np.ndarray, block_s: float, flicker: tuple[tuple[float, float], ...]) -> np.ndarray:
    """The block-mean covariance of Gauss-Markov processes (time constant
    s, variance) over the whole run: flicker does not stop at a table move.
    A block's mean keeps the share of a process slower than the block,
    about 2 tau / block of a faster one."""
    covariance = np.zeros_like(lag_s)
    for tau, variance in flicker:
        covariance += variance * min(1.0, 2.0 * tau / block_s) * np.exp(-lag_s / tau)
    return covariance


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
    effect constant or linear within a position is taken for noise.
    Written here because statsmodels' REML (MixedLM) takes only random
    effects, not a covariance of this form."""

    def __init__(self, design: np.ndarray, declared: np.ndarray, lag_s: np.ndarray, block_s: float) -> None:
        self.design = design
        self.declared = declared
        slow = tuple((tau, 1.0) for tau in FLICKER_TIME_CONSTANTS_S if tau >= block_s)
        self.unit_flicker = _flicker_blocks(lag_s, block_s, slow)

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
                lower = np.linalg.cholesky(self.covariance(theta, scale))
            except np.linalg.LinAlgError:
                return 1e300
            x_w = solve_triangular(lower, self.design, lower=True)
            y_w = solve_triangular(lower, values, lower=True)
            q, r = np.linalg.qr(x_w)
            residual = y_w - q @ (q.T @ y_w)
            return float(
                2.0 * np.sum(np.log(np.diag(lower))) + 2.0 * np.sum(np.log(np.abs(np.diag(r)))) + residual @ residual
            )

        bounds = [(LOG_LEVEL_MIN, LOG_LEVEL_MAX)] * 2
        theta = minimize(restricted_deviance, np.log([0.1, 0.5]), method="L-BFGS-B", bounds=bounds).x
        return np.linalg.cholesky(self.covariance(theta, scale))


def _probe_step(candidate: Candidate, value: float) -> float:
    """The candidate's probe from value, turned back where it would leave
    the parameter's bounds."""
    low, high = candidate.bounds
    return candidate.probe if low <= value + candidate.probe <= high else -candidate.probe


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    return abs(float(a @ b)) / float(np.linalg.norm(a) * np.linalg.norm(b))


def _left_by(design: np.ndarray, values: np.ndarray) -> np.ndarray:
    """What a least-squares fit of the design's columns leaves of values."""
    return values - design @ np.linalg.lstsq(design, values, rcond=None)[0]


def _position_ar1(left: np.ndarray, same: np.ndarray, mounting: np.ndarray) -> np.ndarray:
    """An AR(1) within each position, from the lag-1 correlation of what a
    free offset and slope per position leave: the temperature and chamber
    channels' undeclared noise (the readings' rounding, a real rig's)."""
    total = max(float(np.mean(left**2)), 1e-12)
    neighbours = mounting[1:] == mounting[:-1]
    lag1 = float(np.mean((left[1:] * left[:-1])[neighbours])) if neighbours.any() else 0.0
    rho = float(np.clip(lag1 / total, 0.0, MAX_AR_RHO))
    index = np.arange(len(left))
    return total * rho ** np.abs(np.subtract.outer(index, index)) * same + MIN_WHITE_SHARE * total * np.eye(len(left))


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
        block_time = self.blocks(time_s)
        excursion = self.blocks(temperature_c[used]) - REFERENCE_C
        self.y = self.blocks(self.residual_rows)
        if _nuisance(channel):
            self.nuisance = np.ones((len(self.y), 1))
        elif start_response is not None:
            self.nuisance = np.column_stack([self.blocks(column[used]) for column in start_response.T])
        else:
            self.nuisance = np.empty((len(self.y), 0))
        noise_blocks = self.y if noise_residual is None else self.blocks(noise_residual[used])
        self.whiten = self._whitening(block_time, excursion, block_s, noise, noise_blocks)
        self.y_w = self.whiten(self.y)
        self.nuisance_w = self.whiten(self.nuisance)

    def blocks(self, values: np.ndarray) -> np.ndarray:
        return np.bincount(self._block, weights=values) / self._counts

    def _whitening(
        self,
        block_time: np.ndarray,
        excursion: np.ndarray,
        block_s: float,
        noise: DeclaredNoise,
        noise_blocks: np.ndarray,
    ) -> Callable[[np.ndarray], np.ndarray]:
        lag_s = np.abs(np.subtract.outer(block_time, block_time))
        same = np.equal.outer(self._mounting, self._mounting)
        declared = noise.slope_sigma**2 * np.outer(excursion, excursion) * same
        declared += _flicker_blocks(lag_s, block_s, noise.flicker)
        columns = []
        for m in np.unique(self._mounting):
            inside = (self._mounting == m).astype(float)
            columns += [inside[:, None], (inside * excursion)[:, None]]
        design = np.hstack(columns)
        if self.name in ACCELERATION_CHANNELS:
            lower = UndeclaredFlicker(design, declared, lag_s, block_s).fitted(noise_blocks)
        else:
            lower = np.linalg.cholesky(declared + _position_ar1(_left_by(design, noise_blocks), same, self._mounting))

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

    def testable(self, regressor: np.ndarray) -> bool:
        g = self.whiten(regressor)
        total = float(g @ g)
        if total == 0.0:
            return False
        left = self.beyond_nuisance(g)
        return 1.0 - float(left @ left) / total < NOT_TESTABLE_R2

    def reduction(self, explained_rows: np.ndarray) -> float:
        """The share of the RMS residual an effect takes off."""
        before = gap_rms(self.name, self.residual_rows)
        after = gap_rms(self.name, self.residual_rows - explained_rows)
        return 1.0 - after / before if before > 0 else 0.0


class Search:
    """Rounds of candidate tests on one measured run."""

    def __init__(self, measured: Measured, model: Model, progress: Callable[[str], None] | None = None) -> None:
        self.measured = measured
        self.replay = Replay(measured)
        self.model = model
        self._tables: dict[tuple[str, str], Tabulated] = {}
        self._progress = progress or (lambda message: None)

    def predict(self, model: Model) -> dict[str, np.ndarray]:
        return self.replay(model)

    def residuals(self, predicted: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {channel: self.measured.observed[channel] - predicted[channel] for channel in self.measured.channels}

    def run(self) -> Outcome:
        # The search's algebra is on matrices of a few hundred blocks, where
        # a BLAS thread per core costs more than it brings, most of all on
        # a busy machine (a Cholesky of 138 blocks: 0.08 ms on one thread,
        # 60 ms on two beside another job).
        with threadpool_limits(limits=1, user_api="blas"):
            return self._rounds()

    def _rounds(self) -> Outcome:
        model = self.model
        base = self.predict(model)
        outcome = Outcome(verdict="none", model=model)
        outcome.residual_before = self.residuals(base)
        done: set[tuple[str, str]] = set()
        for round_index in range(MAX_ROUNDS):
            self._progress(f"round {round_index + 1}: testing {len(CANDIDATES)} candidates")
            residual = self.residuals(base)
            starts = (
                self.replay.chamber_start_response(model)
                if any(c in CHAMBER_CHANNELS for c in self.measured.channels)
                else {}
            )
            channels = {
                channel: Channel(
                    self.measured,
                    channel,
                    residual[channel],
                    base["temperature"],
                    DeclaredNoise.of(model, channel),
                    starts.get(channel),
                )
                for channel in self.measured.channels
            }
            regressors = {candidate.name: self._regressors(candidate, model, base) for candidate in CANDIDATES}
            tests = self._tests(model, base, channels, regressors, done)
            outcome.rounds.append(tests)
            if round_index == 0:
                outcome.not_testable = sorted({t.candidate for t in tests} - {t.candidate for t in tests if t.testable})
            # The chamber's reading drives the sensor's replay: an effect
            # found there changes every channel, so it goes in first.
            accepted = sorted(
                (
                    t
                    for t in tests
                    if t.adjusted_p < ALPHA and t.gap_reduction >= MIN_GAP_REDUCTION and self._within_bounds(t)
                ),
                key=lambda t: (t.channel not in CHAMBER_CHANNELS, -t.gap_reduction),
            )
            accepted = [t for t in accepted if not self._contradicted_elsewhere(t, model, base, channels)]
            if not accepted:
                break
            best, rivals = self._settled(accepted, channels, regressors)
            rivals += self._rivals_elsewhere(best, tests, model, base, channels, regressors)
            if rivals:
                names = tuple(sorted({best.candidate, *rivals}))
                outcome.ambiguous.append(Ambiguity(names, best.channel, experiment(frozenset(names))))
                # The channel's residual still holds the unresolved effect,
                # which would confound every later test on it.
                done.update((candidate.name, best.channel) for candidate in CANDIDATES)
                continue
            candidate = next(c for c in CANDIDATES if c.name == best.candidate)
            best = self._refined(
                best,
                channels[best.channel],
                regressors[best.candidate][best.channel],
                model,
                base,
                residual[best.channel],
                base["temperature"],
                starts.get(best.channel),
            )
            effect, model = self._add(candidate, best, model)
            outcome.effects.append(effect)
            # One value acting on every channel is set once, where it
            # explained most.
            done.update(
                [best.key] if candidate.per_axis else [(candidate.name, channel) for channel in candidate.channels]
            )
            base = self.predict(model)
        outcome.model = model
        outcome.residual_after = self.residuals(base)
        outcome.verdict = "found" if outcome.effects else "ambiguous" if outcome.ambiguous else "none"
        outcome.gap = {
            channel: {
                "before": gap_rms(channel, outcome.residual_before[channel][self.measured.used[channel]]),
                "after": gap_rms(channel, outcome.residual_after[channel][self.measured.used[channel]]),
            }
            for channel in self.measured.channels
        }
        return outcome

    def _regressors(self, candidate: Candidate, model: Model, base: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Per channel, the replayed effect of one unit of the parameter
        (rows), from a replay with the parameter moved by `probe`; on the
        channels it is not tested on, what the same replay changes there
        (all of its values moved at once)."""
        channels = [c for c in candidate.channels if c in self.measured.channels]
        if not channels:
            return {}
        steps = {c: _probe_step(candidate, candidate.value(model, c)) for c in channels}
        moved = self.predict(candidate.changed(model, {c: candidate.value(model, c) + steps[c] for c in channels}))
        step = steps[channels[0]]
        return {c: (moved[c] - base[c]) / steps.get(c, step) for c in self.measured.channels}

    def _tests(
        self,
        model: Model,
        base: Mapping[str, np.ndarray],
        channels: Mapping[str, Channel],
        regressors: dict[str, dict[str, np.ndarray]],
        done: set[tuple[str, str]],
    ) -> list[Test]:
        """Every candidate on every channel it acts on. A candidate that is
        not additive (a time constant) is fitted first and tested through
        the effect at its fitted value; its regressor is then that effect."""
        tests: list[Test] = []
        for candidate in CANDIDATES:
            for channel_name, regressor_rows in regressors[candidate.name].items():
                if channel_name not in candidate.channels or (candidate.name, channel_name) in done:
                    continue
                test, effect_rows = self._test(candidate, channels[channel_name], regressor_rows, model, base)
                if effect_rows is not None and not (candidate.additive and candidate.linear):
                    regressors[candidate.name][channel_name] = effect_rows
                tests.append(test)
        testable = [t for t in tests if t.testable]
        if testable:
            adjusted = multipletests([t.p_value for t in testable], alpha=ALPHA, method=MULTIPLE_TESTING)[1]
            by_key = {t.key: float(p) for t, p in zip(testable, adjusted)}
            tests = [replace(t, adjusted_p=by_key.get(t.key, float("nan"))) for t in tests]
        return tests

    def _test(
        self,
        candidate: Candidate,
        channel: Channel,
        regressor_rows: np.ndarray,
        model: Model,
        base: Mapping[str, np.ndarray],
    ) -> tuple[Test, np.ndarray | None]:
        """One candidate on one channel: the test, and the effect at the
        fitted value (rows; None when not testable)."""
        channel_name = channel.name
        g = channel.blocks(regressor_rows[channel.rows])
        if not np.all(np.isfinite(g)) or not channel.testable(g):
            return Test(candidate.name, channel_name, testable=False), None
        if candidate.additive and candidate.linear:
            result = channel.fit(g[:, None])
            change, half_width = float(result.params[0]), 1.96 * float(result.bse[0])
            value = candidate.value(model, channel_name) + change
            interval = (value - half_width, value + half_width)
            p_value, effect_rows = float(result.pvalues[0]), change * regressor_rows
        else:
            if candidate.additive:
                start = candidate.value(model, channel_name) + float(channel.fit(g[:, None]).params[0])
                value, interval, effect_rows = self._gauss_newton(candidate, channel_name, model, base, channel, start)
            else:
                value, interval, effect_rows = self._fit_nonlinear(candidate, channel_name, model, base, channel)
            effect_blocks = channel.blocks(effect_rows[channel.rows])
            p_value = float(channel.fit(effect_blocks[:, None]).pvalues[0]) if np.any(effect_blocks) else 1.0
        test = Test(
            candidate.name,
            channel_name,
            testable=True,
            value=value,
            interval=interval,
            p_value=p_value,
            gap_reduction=channel.reduction(effect_rows[channel.rows]),
        )
        return test, effect_rows

    def _refined(
        self,
        best: Test,
        channel: Channel,
        regressor_rows: np.ndarray,
        model: Model,
        base: Mapping[str, np.ndarray],
        residual: np.ndarray,
        temperature_c: np.ndarray,
        start_response: np.ndarray | None,
    ) -> Test:
        """The found effect fitted again with the undeclared noise fitted to
        the residual without it (one step of iterated feasible GLS): fitted
        to a residual that still held the effect, the noise fit read the
        effect as correlated noise, which both widens and tilts the first
        fit."""
        candidate = BY_NAME[best.candidate]
        # The regressor of a linear candidate is per unit; the others' is
        # already their effect at the fitted value (_tests).
        effect_rows = (
            (best.value - candidate.value(model, best.channel)) * regressor_rows
            if candidate.additive and candidate.linear
            else regressor_rows
        )
        cleaner = Channel(
            self.measured,
            best.channel,
            residual,
            temperature_c,
            DeclaredNoise.of(model, best.channel),
            start_response,
            noise_residual=residual - effect_rows,
        )
        refined, _ = self._test(candidate, cleaner, regressor_rows, model, base)
        if not refined.testable or not self._within_bounds(refined):
            return best
        return replace(refined, adjusted_p=best.adjusted_p)

    def _settled(
        self, accepted: list[Test], channels: Mapping[str, Channel], regressors: Mapping[str, Mapping[str, np.ndarray]]
    ) -> tuple[Test, list[str]]:
        """The first accepted test, or the one on its channel that explains
        what it does and more, with its rivals there. Each other accepted on
        that channel is fitted together with the best: one that keeps a
        significant share of its own where the best keeps none takes its
        place (a ramp's turning points show a lag where a rate sensitivity,
        which takes more off the residual alone, leaves them); one whose
        effect is collinear with the best's, or which leaves neither
        significant, is a rival."""
        best = accepted[0]
        channel = channels[best.channel]
        same = [t for t in accepted if t.channel == best.channel]

        def effect(test: Test) -> np.ndarray:
            return channel.blocks(regressors[test.candidate][test.channel][channel.rows])

        tried = set()
        while True:
            tried.add(best.candidate)
            g_best = effect(best)
            rivals, stronger = [], None
            for other in same:
                if other.candidate == best.candidate:
                    continue
                best_p, other_p = channel.joint_p_values(g_best, effect(other))
                if best_p >= ALPHA and other_p >= ALPHA:
                    rivals.append(other.candidate)
                elif best_p >= ALPHA and stronger is None and other.candidate not in tried:
                    stronger = other
            if stronger is None:
                return best, rivals
            best = stronger

    def _rivals_elsewhere(
        self,
        best: Test,
        tests: list[Test],
        model: Model,
        base: Mapping[str, np.ndarray],
        channels: Mapping[str, Channel],
        regressors: Mapping[str, Mapping[str, np.ndarray]],
    ) -> list[str]:
        """Candidates tested on other channels that change the best's
        channel as well. One is a rival when, at the value that explains the
        best's channel, its change there is collinear with the best's effect
        (or, fitted together with it, leaves neither significant), the value
        is within its bounds and no other channel's data (its own included)
        reject it: an inner thermistor reading warm moves the face the
        sensor's replay is driven by, so it shifts the sensor's temperature
        as a temperature offset does, and on a run too short for the inner
        reading to show its own offset against the chamber's unknown start
        nothing tells the two apart. The effects are compared as replayed at
        those values, not per unit: the sensor's temperature is rounded to
        its register's step, so a shift up and one down differ per unit.
        Only candidates linear in their parameter, whose value the fit on
        the best's channel gives."""
        channel = channels[best.channel]

        def change_at(candidate: Candidate, on: str, value: float) -> np.ndarray:
            moved = self.predict(candidate.changed(model, {on: value}))[best.channel]
            return channel.blocks((moved - base[best.channel])[channel.rows])

        g_best = change_at(BY_NAME[best.candidate], best.channel, best.value)
        rivals = []
        for test in tests:
            candidate = BY_NAME[test.candidate]
            if (
                not test.testable
                or test.candidate == best.candidate
                or best.channel in candidate.channels
                or not (candidate.additive and candidate.linear)
                or not np.any(regressors[test.candidate][best.channel])
            ):
                continue
            value = candidate.value(model, test.channel)
            step = _probe_step(candidate, value)
            per_unit = change_at(candidate, test.channel, value + step) / step
            if not np.any(per_unit) or not channel.testable(per_unit):
                continue
            rival = replace(test, value=value + float(channel.fit(per_unit[:, None]).params[0]))
            if not self._within_bounds(rival):
                continue
            if min(channel.joint_p_values(g_best, change_at(candidate, test.channel, rival.value))) < ALPHA:
                continue
            if not self._contradicted_elsewhere(rival, model, base, channels, agreed=best.channel):
                rivals.append(test.candidate)
        return rivals

    def _contradicted_elsewhere(
        self,
        test: Test,
        model: Model,
        base: Mapping[str, np.ndarray],
        channels: Mapping[str, Channel],
        agreed: str | None = None,
    ) -> bool:
        """A channel's data other than the one the effect was fitted on
        (`agreed`, by default the test's own) reject the change the effect
        makes there (a thermistor offset that the sensor's own temperature
        contradicts is not the missing effect). Each other channel's
        residual is fitted on that change with its own whitening, so a change
        its declared noise could make (a drift slope per mounting)
        contradicts nothing, nor does a channel too noisy to see the whole
        change: contradicted when the data take less than half of the change
        and reject all of it, one-sided at ALPHA over the channels checked."""
        candidate = BY_NAME[test.candidate]
        predicted = self.predict(candidate.changed(model, {test.channel: test.value}))
        changes = {}
        for name, other in channels.items():
            if name == (agreed or test.channel):
                continue
            change = other.blocks((predicted[name] - base[name])[other.rows])
            if np.any(change) and other.testable(change):
                changes[name] = change
        critical = stats.norm.isf(ALPHA / max(len(changes), 1))
        for name, change in changes.items():
            fit = channels[name].fit(change[:, None])
            share, error = float(fit.params[0]), float(fit.bse[0])
            # A channel that could not see the whole change contradicts
            # nothing: a temperature offset moves X on Figure 8 by a trace,
            # which the X data of one run took -144 +- 65 times ("rejected").
            if critical * error >= 1.0:
                continue
            if share < 0.5 and (1.0 - share) > critical * error:
                return True
        return False

    @staticmethod
    def _within_bounds(test: Test) -> bool:
        """A value the parameter cannot take (a negative dead zone) is not
        that effect, however well it fits."""
        low, high = BY_NAME[test.candidate].bounds
        return low <= test.value <= high

    def _add(self, candidate: Candidate, test: Test, model: Model) -> tuple[Effect, Model]:
        """The found value into the model."""
        value = test.value
        self._progress(f"found {candidate.name} on {test.channel}: {candidate.parameter} = {value:.4g}")
        effect = Effect(
            candidate.name,
            test.channel,
            candidate.parameter,
            candidate.unit,
            value,
            test.interval,
            test.adjusted_p,
            test.gap_reduction,
        )
        return effect, candidate.changed(model, {test.channel: value})

    def _gauss_newton(
        self,
        candidate: Candidate,
        channel_name: str,
        model: Model,
        base: Mapping[str, np.ndarray],
        channel: Channel,
        value: float,
    ) -> tuple[float, tuple[float, float], np.ndarray]:
        """Least squares of the whitened blocks over an additive parameter
        whose effect is not linear in it (a dead zone), by Gauss-Newton
        steps from the linear fit's value, each slope from replays: the
        value (within its bounds), its interval from the slope there, and
        the effect at that value (rows)."""
        low, high = candidate.bounds

        def effect(at: float) -> np.ndarray:
            return self.predict(candidate.changed(model, {channel_name: at}))[channel_name] - base[channel_name]

        for _ in range(GAUSS_NEWTON_STEPS):
            value = float(np.clip(value, low, high))
            current = effect(value)
            step = candidate.probe if value + candidate.probe <= high else -candidate.probe
            slope = (effect(value + step) - current) / step
            result = channel.fit(
                channel.blocks(slope[channel.rows])[:, None], left=channel.y - channel.blocks(current[channel.rows])
            )
            change = float(result.params[0])
            value += change
            if abs(change) < GAUSS_NEWTON_TOLERANCE * abs(candidate.probe):
                break
        value = float(np.clip(value, low, high))
        half_width = 1.96 * float(result.bse[0])
        return value, (value - half_width, value + half_width), effect(value)

    def _tabulated(self, candidate: Candidate, model: Model, base: Mapping[str, np.ndarray]) -> Tabulated:
        """The candidate's effect on each of its channels (rows) at
        NONLINEAR_GRID_STEP-spaced log values over its search range, and at
        the values _refined_about added: one replay a value, shared by
        every channel it acts on."""
        key = (candidate.name, json.dumps(plain(model.terms), sort_keys=True))
        if key not in self._tables:
            low, high = np.log(candidate.bounds[0]), np.log(candidate.bounds[1])
            channels = [c for c in candidate.channels if c in self.measured.channels]
            table = Tabulated([], {c: [] for c in channels})
            for log_value in np.linspace(low, high, max(4, int(np.ceil((high - low) / NONLINEAR_GRID_STEP)) + 1)):
                table.add(float(log_value), self._predicted_at(candidate, model, float(log_value)), base)
            self._tables[key] = table
        return self._tables[key]

    def _predicted_at(self, candidate: Candidate, model: Model, log_value: float) -> dict[str, np.ndarray]:
        channels = [c for c in candidate.channels if c in self.measured.channels]
        return self.predict(candidate.changed(model, {channels[0]: float(np.exp(log_value))}))

    def _refined_about(
        self, table: Tabulated, candidate: Candidate, model: Model, base: Mapping[str, np.ndarray], index: int
    ) -> None:
        """The table with the points halfway to the neighbours of its
        index-th value, where it has none closer."""
        values = list(table.log_values)
        spacing = NONLINEAR_GRID_STEP / 2.0
        for neighbour in (index - 1, index + 1):
            if 0 <= neighbour < len(values) and abs(values[neighbour] - values[index]) > spacing * 1.01:
                middle = 0.5 * (values[neighbour] + values[index])
                table.add(middle, self._predicted_at(candidate, model, middle), base)

    def _fit_nonlinear(
        self, candidate: Candidate, channel_name: str, model: Model, base: Mapping[str, np.ndarray], channel: Channel
    ) -> tuple[float, tuple[float, float], np.ndarray]:
        """Least squares of the whitened blocks over the parameter's value
        (log scale, within its bounds): the cost on the tabulated effect,
        interpolated cubically in the log value, from the best grid value
        to the minimum between its neighbours; then the value's effect
        replayed, and its interval from the interpolant's slope there (the
        linearised GLS)."""

        def effect(value: float) -> np.ndarray:
            return self.predict(candidate.changed(model, {channel_name: value}))[channel_name] - base[channel_name]

        table = self._tabulated(candidate, model, base)

        def cost_at(effect_blocks: np.ndarray) -> float:
            left = channel.beyond_nuisance(channel.whiten(channel.y - effect_blocks))
            return float(left @ left)

        coarse = [cost_at(channel.blocks(rows[channel.rows])) for rows in table.effects[channel_name]]
        self._refined_about(table, candidate, model, base, int(np.argmin(coarse)))
        blocks = np.array([channel.blocks(rows[channel.rows]) for rows in table.effects[channel_name]])
        interpolated = CubicSpline(table.log_values, blocks, axis=0)

        def cost(log_value: float) -> float:
            return cost_at(interpolated(log_value))

        grid = np.array(table.log_values)
        nearest = int(np.argmin([cost_at(effect_blocks) for effect_blocks in blocks]))
        bracket = (grid[max(nearest - 1, 0)], grid[min(nearest + 1, len(grid) - 1)])
        best = minimize_scalar(cost, bounds=bracket, method="bounded", options={"xatol": 1e-3})
        value = float(np.exp(best.x))
        # d effect / d value, from the interpolant's slope in the log value.
        slope = interpolated(best.x, 1) / value
        result = channel.fit(slope[:, None])
        half_width = 1.96 * float(result.bse[0])
        return value, (value - half_width, value + half_width), effect(value)
