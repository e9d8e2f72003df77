"""Which candidate explains the gap between a run and its replay, decided
with inference that survives the residual's autocorrelation.

Each channel's residual (measured minus replay) is averaged over blocks
within each table position (channel.py), which leaves a few hundred points whose
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

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats
from statsmodels.stats.multitest import multipletests
from threadpoolctl import threadpool_limits

from ..physics import Model
from .candidates import BY_NAME, CANDIDATES, Candidate, experiment
from .channel import HALF_WIDTH_95, Channel, DeclaredNoise, GoodnessOfFit, gap_rms
from .nonlinear import NonlinearFits
from .replay import CHAMBER_CHANNELS, Measured, Replay

ALPHA = 0.05
# Benjamini-Yekutieli, not Benjamini-Hochberg: one round's tests share each
# channel's residual and test correlated regressors, a dependence under
# which only BY bounds the false-discovery rate. On the slow noise families
# each test's size is at its nominal level (docs/discovery.md), so the rate
# a run names anything at is set here.
MULTIPLE_TESTING = "fdr_by"
# A candidate must take at least this share off the channel's RMS residual:
# an effect as large as the noise (SNR 1) takes 29 %, SNR 0.5 takes 11 %.
MIN_GAP_REDUCTION = 0.10
MAX_ROUNDS = 4
# A found effect is refitted with the undeclared noise fitted to what it
# leaves, at most this many times, until its value moves by less than this
# share of its standard error.
REFINEMENT_STEPS = 8
REFINEMENT_TOLERANCE = 0.1
# With effects named, a channel beyond its declared noise makes them partial
# (the verdict `unexplained`) only at this level, shared among the channels
# as ALPHA is: at ALPHA, a right name would be called partial in one run of
# 20 by chance, which alone would hold the share of runs named right at 95 %.
# A model the run rejects far beyond its noise (a chamber the model does not
# describe: gaps 10-100x what the floor allows) is caught either way.
PARTIAL_ALPHA = 0.001


@dataclass(frozen=True)
class Test:
    """One candidate on one channel in one round. value: the parameter's
    value that explains the residual best (for an additive candidate the
    model's plus the fitted change), with its standard error; p_value: that
    the effect is zero."""

    candidate: str
    channel: str
    testable: bool
    why_not: str = ""  # why it is not testable here
    value: float = float("nan")
    standard_error: float = float("nan")
    p_value: float = float("nan")
    adjusted_p: float = float("nan")
    gap_reduction: float = float("nan")

    @property
    def key(self) -> tuple[str, str]:
        return self.candidate, self.channel

    @property
    def interval(self) -> tuple[float, float]:
        """The value's 95 % interval."""
        half_width = HALF_WIDTH_95 * self.standard_error
        return self.value - half_width, self.value + half_width


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
    not_testable: dict[str, str] = field(default_factory=dict)  # name: why, per channel
    rounds: list[list[Test]] = field(default_factory=list)
    residual_before: dict[str, np.ndarray] = field(default_factory=dict)
    residual_after: dict[str, np.ndarray] = field(default_factory=dict)
    gap: dict[str, dict[str, float]] = field(default_factory=dict)
    fit: dict[str, GoodnessOfFit] = field(default_factory=dict)

    def judged(self) -> str:
        """The verdict: `unexplained` while a channel is beyond its declared
        noise; after effects were named, only where the model with them is
        rejected at PARTIAL_ALPHA, the names then explaining a part of the
        gap only. A channel left ambiguous still holds its unresolved effect
        and does not count."""
        ambiguous_channels = {group.channel for group in self.ambiguous}
        share = PARTIAL_ALPHA / ALPHA if self.effects else 1.0
        if any(fit.channel not in ambiguous_channels and not fit.explained_at(share) for fit in self.fit.values()):
            return "unexplained"
        return "found" if self.effects else "ambiguous" if self.ambiguous else "none"


def _not_testable(tests: list[Test]) -> dict[str, str]:
    """The candidates no channel of the run can test, each with why: the
    channels that share a reason named together ("X, Y: ...")."""
    found: dict[str, str] = {}
    for name in dict.fromkeys(t.candidate for t in tests):
        mine = [t for t in tests if t.candidate == name]
        if any(t.testable for t in mine):
            continue
        reasons = {t.why_not: [u.channel for u in mine if u.why_not == t.why_not] for t in mine}
        found[name] = "; ".join(f"{', '.join(channels)}: {why}" for why, channels in reasons.items())
    return dict(sorted(found.items()))


def _probe_step(candidate: Candidate, value: float) -> float:
    """The candidate's probe from value, turned back where it would leave
    the parameter's bounds."""
    low, high = candidate.bounds
    return candidate.probe if low <= value + candidate.probe <= high else -candidate.probe


class Search:
    """Rounds of candidate tests on one measured run."""

    def __init__(self, measured: Measured, model: Model, progress: Callable[[str], None] | None = None) -> None:
        self.measured = measured
        self.replay = Replay(measured)
        self.model = model
        self._nonlinear = NonlinearFits(measured, self.predict)
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
        channels: dict[str, Channel] = {}
        for round_index in range(MAX_ROUNDS):
            self._progress(f"round {round_index + 1}: testing {len(CANDIDATES)} candidates")
            channels = self._channels(model, base)
            regressors = {candidate.name: self._regressors(candidate, model, base) for candidate in CANDIDATES}
            tests = self._tests(model, base, channels, regressors, done)
            outcome.rounds.append(tests)
            if round_index == 0:
                outcome.not_testable = _not_testable(tests)
            accepted = self._accepted(tests, model, base, channels, regressors)
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
            candidate = BY_NAME[best.candidate]
            if not candidate.per_axis:
                # One value acting on several channels (a heatsink's
                # conductance on both faces) is taken where the run measures
                # it best, which need not be where it explained most: the
                # chamber's replay error dominates the inner face.
                best = min(
                    (t for t in accepted if t.candidate == best.candidate),
                    key=lambda test: test.standard_error,
                )
            effect, model = self._add(candidate, best, model)
            outcome.effects.append(effect)
            channels = {}
            # One value acting on every channel is set once.
            done.update(
                [best.key] if candidate.per_axis else [(candidate.name, channel) for channel in candidate.channels]
            )
            base = self.predict(model)
        self._conclude(outcome, model, base, channels or self._channels(model, base))
        return outcome

    def channels(self) -> dict[str, Channel]:
        """Every channel's blocks and whitening on what the given model
        leaves (before any round)."""
        return self._channels(self.model, self.predict(self.model))

    def _channels(self, model: Model, base: Mapping[str, np.ndarray]) -> dict[str, Channel]:
        """Every channel's blocks and whitening for a round on the residual
        the model leaves."""
        residual = self.residuals(base)
        starts = (
            self.replay.chamber_start_response(model)
            if any(c in CHAMBER_CHANNELS for c in self.measured.channels)
            else {}
        )
        return {
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

    def _accepted(
        self,
        tests: list[Test],
        model: Model,
        base: Mapping[str, np.ndarray],
        channels: Mapping[str, Channel],
        regressors: Mapping[str, Mapping[str, np.ndarray]],
    ) -> list[Test]:
        """The round's tests that pass every rule of a found effect, each
        refined (_refined) before the other channels judge its value, in the
        order they are taken: the chamber's reading drives the sensor's
        replay, so an effect found there changes every channel and goes in
        first; then the largest reduction."""
        passing = [
            t for t in tests if t.adjusted_p < ALPHA and t.gap_reduction >= MIN_GAP_REDUCTION and self._within_bounds(t)
        ]
        refined = [
            self._refined(t, channels[t.channel], regressors[t.candidate][t.channel], model, base) for t in passing
        ]
        accepted = sorted(refined, key=lambda t: (t.channel not in CHAMBER_CHANNELS, -t.gap_reduction))
        return [t for t in accepted if not self._contradicted_elsewhere(t, model, base, channels)]

    def _conclude(
        self, outcome: Outcome, model: Model, base: Mapping[str, np.ndarray], channels: Mapping[str, Channel]
    ) -> None:
        """The outcome's model, gaps, goodness of fit and verdict once the
        rounds are over; each channel's fit at ALPHA shared among those
        tested, so that a run the model fits is called unexplained at most
        at ALPHA."""
        outcome.model = model
        outcome.residual_after = self.residuals(base)
        tested = [channel for channel in channels.values() if np.any(channel.declared)]
        outcome.fit = {channel.name: channel.goodness_of_fit(ALPHA / len(tested)) for channel in tested}
        outcome.verdict = outcome.judged()
        outcome.gap = {
            channel: {
                "before": gap_rms(channel, outcome.residual_before[channel][self.measured.used[channel]]),
                "after": gap_rms(channel, outcome.residual_after[channel][self.measured.used[channel]]),
            }
            for channel in self.measured.channels
        }

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
        start: float | None = None,
    ) -> tuple[Test, np.ndarray | None]:
        """One candidate on one channel: the test, and the effect at the
        fitted value (rows; None when not testable). start: where a
        Gauss-Newton fit starts, if not at the linear fit's value."""
        channel_name = channel.name
        g = channel.blocks(regressor_rows[channel.rows])
        why_not = channel.why_not_testable(g) if np.all(np.isfinite(g)) else "its replay is not finite"
        if why_not:
            return Test(candidate.name, channel_name, testable=False, why_not=why_not), None
        if candidate.additive and candidate.linear:
            result = channel.fit(g[:, None])
            change, standard_error = float(result.params[0]), float(result.bse[0])
            value = candidate.value(model, channel_name) + change
            p_value, effect_rows = float(result.pvalues[0]), change * regressor_rows
        else:
            if candidate.additive:
                if start is None:
                    start = candidate.value(model, channel_name) + float(channel.fit(g[:, None]).params[0])
                value, standard_error, effect_rows = self._nonlinear.fit_gauss_newton(
                    candidate, channel, model, base, start
                )
            else:
                value, standard_error, effect_rows = self._nonlinear.fit_tabulated(candidate, channel, model, base)
            effect_blocks = channel.blocks(effect_rows[channel.rows])
            p_value = float(channel.fit(effect_blocks[:, None]).pvalues[0]) if np.any(effect_blocks) else 1.0
        test = Test(
            candidate.name,
            channel_name,
            testable=True,
            value=value,
            standard_error=standard_error,
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
    ) -> Test:
        """The found effect fitted again with the undeclared noise fitted to
        the residual without it, until the value settles (iterated feasible
        GLS): fitted to a residual that still held the effect, the noise fit
        read the effect as correlated noise, which both widens and tilts the
        fit; one step left a heatsink's conductance a standard error low on
        average, where its outer face then stayed beyond the floor."""
        candidate = BY_NAME[best.candidate]
        # The regressor of a linear candidate is per unit; the others' is
        # already their effect at the fitted value (_tests).
        effect_rows = (
            (best.value - candidate.value(model, best.channel)) * regressor_rows
            if candidate.additive and candidate.linear
            else regressor_rows
        )
        for _ in range(REFINEMENT_STEPS):
            refined, refined_rows = self._test(
                candidate, channel.refitted(effect_rows), regressor_rows, model, base, start=best.value
            )
            if refined_rows is None or not self._within_bounds(refined):
                break
            settled = abs(refined.value - best.value) <= REFINEMENT_TOLERANCE * refined.standard_error
            best, effect_rows = replace(refined, adjusted_p=best.adjusted_p), refined_rows
            if settled:
                break
        return best

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
            if not np.any(per_unit) or channel.untestable(per_unit):
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
            if np.any(change) and not other.untestable(change):
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
        self._progress(f"named {candidate.name} on {test.channel}: {candidate.parameter} = {value:.4g}")
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
