"""How wide the sensor's own crossing from one set to the other is, read
from the campaign's reversals, and what the device's fixed crossing can
then leave uncompensated (budget's "set selection at turnarounds").

A reversal is where the device's set label changes in a position's rows
put back in time order: the old label's rows end at the turn (their
extreme temperature), and must span MAX_WIDTH_C up to it, so that the
sensor is wholly in the old set at the turn whatever it was before; the
window runs on until the temperature is MAX_WIDTH_C past the turn. For
each candidate width w (0, an instant step, to MAX_WIDTH_C) the sensor's
warming share is ``set_blend.warming_shares(w, ...)`` on the filtered
temperature from the window's start in the old set, and the window's error
is the residual less ``blend(share, f_W(T, a), f_C(T, a))`` with the fit's
surfaces, about the mounting's own line in the temperature and with the
step's scale a line in it (``_profile`` says why); the width is the
candidate of least squares. The crossing is one
state of the die, the same share for both axes, so the axes' sums of
squares are added, each over its scatter before the turn (an axis whose
sets hardly differ there carries no say, see MIN_SET_CONTRAST).

Across the reversals the widths are readings of the crossing at the
campaign's rates. A field reversal's width may differ from their mean by
the mean's own uncertainty and by how much the crossing truly varies from
one reversal to the next: that variance is the covariance of the two axes'
widths read apart on the same reversals (each axis's reading errs on its
own; what they share is the reversal's width), or, with one axis, all the
widths' scatter. The interval for a new reversal is mean +- t(n - 1)
sqrt(between + s^2 / n), Student's t on n - 1. The width is read on the
filtered temperature, which lags the die's by the Kalman filter's time
constant (FILTER_LAG_S): the slower a reversal, the less of the die's
crossing the lag hides. So the interval is widened below by the lag over
the field's rates beyond the campaign's slowest turn (up to the validity's
rate limit), and above by the whole lag at its fastest turn, where a
field reversal at rest would show all of the die's crossing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from ...set_blend import FIRMWARE_TRANSITION_C, blend, warming_shares
from ..fit import SurfaceFit
from .errors import AxisErrors

# The widest crossing looked for: four times the firmware's, beyond the
# paper's 2 degC steps, on whose plateaus each set showed whole.
MAX_WIDTH_C = 6.0
WIDTH_STEP_C = 0.05
CANDIDATE_WIDTHS_C = np.linspace(0.0, MAX_WIDTH_C, round(MAX_WIDTH_C / WIDTH_STEP_C) + 1)
# An axis reads the width when its sets' difference at the turn is at least
# this many standard deviations of its in-sample errors before the turn
# (about their line): a smaller step is within what the rows' own wander shows.
MIN_SET_CONTRAST = 3.0
# Fewer widths give no spread, so no prediction interval.
MIN_REVERSALS = 2
# Fewer reversals read on two axes leave the variance between reversals unread.
MIN_PAIRED_REVERSALS = 3
PREDICTION_PROBABILITY = 0.95
# lib/Kalman: the gain settles at sqrt(Q/R) = 1e-3 a sample, a first-order
# lag of ~1000 samples, 10 s at 100 Hz; the temperature goes through the
# same filter as the axes (lib/ImuProcessing).
FILTER_LAG_S = 10.0


@dataclass(frozen=True)
class Reversal:
    """One reversal of one position and the width its rows show."""

    position: int
    old_set: str  # the set before the turn: "W" at the top of a warming run, "C" at the bottom
    turn_c: float  # the filtered temperature at the turn
    turn_time_s: float
    axes: tuple[str, ...]  # the axes whose sets differ enough to read the width
    width_c: float  # read on those axes together
    axis_widths_c: tuple[float, ...]  # read on each of them alone, in axes' order
    rate_c_per_s: float  # |dT/dt| of the filtered temperature over the window after the turn


@dataclass(frozen=True)
class Crossing:
    """The campaign's reversals, the widths they show and what they leave."""

    reversals: tuple[Reversal, ...]  # the evaluated ones
    unevaluated: int  # reversals found but not evaluated
    reasons: tuple[str, ...]  # why, one per kind

    @property
    def widths_c(self) -> np.ndarray:
        return np.array([reversal.width_c for reversal in self.reversals])

    @property
    def measured(self) -> bool:
        return len(self.reversals) >= MIN_REVERSALS

    def between_variance(self) -> float | None:
        """How much the crossing's width varies from one reversal to the
        next (degC^2): the covariance of the widths two axes read apart on
        the same reversals, at least 0; None with fewer than
        MIN_PAIRED_REVERSALS reversals read on two axes."""
        paired = np.array([r.axis_widths_c[:2] for r in self.reversals if len(r.axis_widths_c) >= 2])
        if len(paired) < MIN_PAIRED_REVERSALS:
            return None
        return max(0.0, float(np.cov(paired[:, 0], paired[:, 1], ddof=1)[0, 1]))

    def width_interval_c(self, field_rate_limit_c_per_s: float) -> tuple[float, float]:
        """The 95 % interval of a field reversal's width on the filtered
        temperature (the module's docstring), held at or above 0."""
        widths = self.widths_c
        count = len(widths)
        spread = float(np.var(widths, ddof=1))
        between = self.between_variance()
        variance = spread * (1.0 + 1.0 / count) if between is None else min(spread, between) + spread / count
        half = float(stats.t.ppf(0.5 + PREDICTION_PROBABILITY / 2.0, count - 1)) * math.sqrt(variance)
        rates = [reversal.rate_c_per_s for reversal in self.reversals]
        mean = float(np.mean(widths))
        low = mean - half - FILTER_LAG_S * max(0.0, field_rate_limit_c_per_s - min(rates))
        return max(0.0, low), mean + half + FILTER_LAG_S * max(rates)

    def mismatch(self, field_rate_limit_c_per_s: float) -> float:
        """m: the largest share of |f_W - f_C| the device's crossing can be
        off by, over the widths of width_interval_c; 1 unmeasured."""
        if not self.measured:
            return 1.0
        return largest_mismatch(*self.width_interval_c(field_rate_limit_c_per_s))

    def source(self, field_rate_limit_c_per_s: float) -> str:
        found = len(self.reversals) + self.unevaluated
        skipped = f"; {self.unevaluated} not evaluated ({'; '.join(self.reasons)})" if self.unevaluated else ""
        if not self.measured:
            return (
                f"the sensor's crossing width is not measured: {len(self.reversals)} of {found} reversals evaluated"
                f"{skipped}, fewer than {MIN_REVERSALS}; a sensor that crosses at once leaves up to the whole "
                "difference, m = 1"
            )
        widths = self.widths_c
        between = self.between_variance()
        low, high = self.width_interval_c(field_rate_limit_c_per_s)
        varies = (
            "no second axis to tell it from the readings' scatter, so all of the scatter is taken as the reversals'"
            if between is None
            else "the reversals' own variance, the covariance of the widths the two axes read apart (held at 0 "
            f"or above): {between:.2g} degC^2"
        )
        rates = [reversal.rate_c_per_s * 60.0 for reversal in self.reversals]
        return (
            f"the sensor's crossing width w measured at {len(widths)} reversals of the campaign (the stop "
            "operator's width on the filtered temperature whose blend of the fitted sets best fits the residuals "
            f"around each turn, least squares, one share for the axes){skipped}: mean {np.mean(widths):.2f} degC, "
            f"s {np.std(widths, ddof=1):.2f} degC; {varies}; a new reversal mean +- t s_new "
            f"(Student t, {len(widths) - 1} degrees of freedom, {PREDICTION_PROBABILITY * 100:g} %), widened for "
            f"the filter's {FILTER_LAG_S:g} s lag between the turns' rates ({min(rates):.2g}..{max(rates):.2g} "
            f"degC/min) and the field's (0..{field_rate_limit_c_per_s * 60.0:g} degC/min): {low:.2f} .. {high:.2f} "
            f"degC; m = {self.mismatch(field_rate_limit_c_per_s):.2f}"
        )


def crossing_mismatch(width_c: float, device_c: float = FIRMWARE_TRANSITION_C) -> float:
    """The largest difference between the shares of two stop operators of
    widths width_c and device_c starting from the same end on the same
    path: 1 - min / max, where the narrower one has crossed and the wider
    is min / max of the way (0 for equal widths, 1 for an instant one)."""
    wider = max(width_c, device_c)
    return 0.0 if wider == 0.0 else 1.0 - min(width_c, device_c) / wider


def largest_mismatch(low_c: float, high_c: float, device_c: float = FIRMWARE_TRANSITION_C) -> float:
    """crossing_mismatch's largest over widths low_c..high_c: it falls to 0
    at device_c from either side, so at one of the ends."""
    return max(crossing_mismatch(low_c, device_c), crossing_mismatch(high_c, device_c))


def stop_shares(width_c: float, start_c: float, temperature_c: np.ndarray, warming_share: float) -> np.ndarray:
    """set_blend.warming_shares, with its limit at width 0: the warming set
    from any rise, the cooling set from any fall."""
    if width_c > 0.0:
        return warming_shares(width_c, start_c, temperature_c, warming_share)
    direction = np.sign(np.diff(np.asarray(temperature_c, dtype=float), prepend=start_c))
    last_move = np.maximum.accumulate(np.where(direction != 0.0, np.arange(len(direction)), -1))
    return np.where(last_move >= 0, (direction[np.maximum(last_move, 0)] > 0.0).astype(float), warming_share)


@dataclass(frozen=True)
class _Window:
    position: int
    old_set: str
    turn: int  # index into rows of the turn
    rows: np.ndarray  # into the axis's rows, in time order


def _windows(errors: AxisErrors) -> tuple[list[_Window], dict[str, int]]:
    """The reversals of the axis's rows, as windows, and the count of those
    left out by reason."""
    windows: list[_Window] = []
    skipped: dict[str, int] = {}
    timed = np.isfinite(errors.time_s)
    for position in np.unique(errors.position[timed]):
        rows = np.flatnonzero(timed & (errors.position == position))
        rows = rows[np.argsort(errors.time_s[rows], kind="stable")]
        labels, temperature = errors.set_name[rows], errors.temperature_c[rows]
        starts = [0, *(np.flatnonzero(labels[1:] != labels[:-1]) + 1).tolist(), len(rows)]
        for begin, change, end in zip(starts[:-2], starts[1:-1], starts[2:]):
            old_set = str(labels[begin])
            run = temperature[begin:change]
            turn = begin + int(np.argmax(run) if old_set == "W" else np.argmin(run))
            distance = np.abs(temperature - temperature[turn])
            lead = np.flatnonzero(distance[begin:turn] >= MAX_WIDTH_C)
            tail = np.flatnonzero(distance[turn:end] >= MAX_WIDTH_C)
            if not lead.size:
                reason = f"where the old set's rows span less than {MAX_WIDTH_C:g} degC before the turn"
            elif not tail.size:
                reason = f"where the new set's rows span less than {MAX_WIDTH_C:g} degC after it"
            else:
                first, last = begin + int(lead[-1]), turn + int(tail[0])
                windows.append(_Window(int(position), old_set, turn - first, rows[first : last + 1]))
                continue
            skipped[reason] = skipped.get(reason, 0) + 1
    return windows, skipped


def _rate_after(errors: AxisErrors, window: _Window) -> float:
    """|dT/dt| of the filtered temperature from the turn to the window's end (least squares), degC/s."""
    after = window.rows[window.turn :]
    return abs(float(np.polyfit(errors.time_s[after], errors.temperature_c[after], 1)[0]))


def _profile(errors: AxisErrors, fits: dict[str, SurfaceFit], window: _Window, shares: np.ndarray) -> np.ndarray | None:
    """The window's sum of squared errors per candidate width, over the
    variance of the in-sample errors before the turn (about their line in
    the temperature); None when the sets differ too little at the turn to
    read a width. Each candidate's error is taken about the mounting's own
    line in the temperature, and with the blend's step scaled by a line in
    the temperature: the mounting's offset, slope and W - C difference
    depart from the campaign's surfaces (the between-positions and set
    offset components carry those), and the surfaces, fitted to the rows
    the device labelled before the sensor had crossed, take up part of the
    step near the turns, more the nearer (on synthetic campaigns a
    crossing of 4.5 degC reads 4.2 with the step's scale one constant).
    The width is read from the step's shape: where the blend bends, at the
    turn and w past it."""
    temperature, acceleration = errors.temperature_c[window.rows], errors.acceleration_lsb[window.rows]
    warming = fits["W"].surface.evaluate(temperature, acceleration)
    cooling = fits["C"].surface.evaluate(temperature, acceleration)
    residual = errors.residual_lsb[window.rows]
    mounting = np.column_stack([np.ones(len(temperature)), temperature - temperature[window.turn]])
    before = residual[: window.turn] - (warming if window.old_set == "W" else cooling)[: window.turn]
    _, before_sse, *_ = np.linalg.lstsq(mounting[: window.turn], before, rcond=None)
    scatter = math.sqrt(float(before_sse[0]) / (window.turn - mounting.shape[1])) if len(before_sse) else 0.0
    contrast = abs(float(warming[window.turn] - cooling[window.turn]))
    if scatter == 0.0 or contrast < MIN_SET_CONTRAST * scatter:
        return None
    sse = np.empty(len(shares))
    for index, share in enumerate(shares):
        step = blend(share, warming, cooling) - cooling
        columns = np.column_stack([step, step * mounting[:, 1], mounting])
        _, sse[index : index + 1], *_ = np.linalg.lstsq(columns, residual - cooling, rcond=None)
    return sse / scatter**2


def estimate_crossing(errors_by_axis: dict[str, AxisErrors], fits: list[SurfaceFit]) -> Crossing:
    """Every reversal of the campaign with its width, over the axes fitted
    in both sets (one share per reversal for all of them)."""
    profiles: dict[tuple[int, float], dict[str, np.ndarray | None]] = {}
    turns: dict[tuple[int, float], tuple[str, float, float]] = {}
    skipped: dict[str, int] = {}
    # The axes fitted in both sets hold the same rows, so the same windows: their shares once.
    shares_of: dict[tuple[int, float], np.ndarray] = {}
    for axis, errors in errors_by_axis.items():
        axis_fits = {fit.set_name: fit for fit in fits if fit.axis == axis}
        if not {"W", "C"} <= set(axis_fits):
            continue
        windows, axis_skipped = _windows(errors)
        for reason, count in axis_skipped.items():
            skipped[reason] = max(skipped.get(reason, 0), count)
        for window in windows:
            times = errors.time_s[window.rows]
            key = (window.position, float(times[window.turn]))
            if key not in shares_of:
                temperature = errors.temperature_c[window.rows]
                old_share = 1.0 if window.old_set == "W" else 0.0
                shares_of[key] = np.array(
                    [stop_shares(width, temperature[0], temperature, old_share) for width in CANDIDATE_WIDTHS_C]
                )
            profiles.setdefault(key, {})[axis] = _profile(errors, axis_fits, window, shares_of[key])
            turns[key] = (
                window.old_set,
                float(errors.temperature_c[window.rows[window.turn]]),
                _rate_after(errors, window),
            )
    reversals = []
    flat = 0
    for key, by_axis in sorted(profiles.items()):
        readable = {axis: profile for axis, profile in by_axis.items() if profile is not None}
        if not readable:
            flat += 1
            continue
        total = np.sum(list(readable.values()), axis=0)
        old_set, turn_c, rate = turns[key]
        reversals.append(
            Reversal(
                key[0],
                old_set,
                turn_c,
                key[1],
                tuple(readable),
                float(CANDIDATE_WIDTHS_C[np.argmin(total)]),
                tuple(float(CANDIDATE_WIDTHS_C[np.argmin(profile)]) for profile in readable.values()),
                rate,
            )
        )
    if flat:
        skipped[f"where the sets differ by less than {MIN_SET_CONTRAST:g} sigma of the rows at the turn"] = flat
    return Crossing(tuple(reversals), sum(skipped.values()), tuple(f"{n} {reason}" for reason, n in skipped.items()))
