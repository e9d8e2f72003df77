"""The sensor's set-crossing width read from a campaign's reversals
(calibration/certificate/crossing.py) and the turnaround row of the
certificate's budget it bounds: synthetic campaigns whose sensor crosses
with a known width on the filtered temperature, and ones that cannot say."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from test_calibration_fit import ANGLES_DEG, TRUE, cycle, smooth_noise, write_run_log
from test_certificate import campaign_of

from thermotilt.calibration.certificate import certify
from thermotilt.calibration.certificate.crossing import (
    FILTER_LAG_S,
    MAX_WIDTH_C,
    WIDTH_STEP_C,
    crossing_mismatch,
    estimate_crossing,
    largest_mismatch,
    stop_shares,
)
from thermotilt.calibration.certificate.errors import axis_errors, nominal_angles
from thermotilt.calibration.dataset import Campaign, SetData, load
from thermotilt.calibration.fit import fit_surface
from thermotilt.lsm9ds0 import LSB_PER_G
from thermotilt.physics.sensor import drift_sets
from thermotilt.set_blend import FIRMWARE_TRANSITION_C, blend, warming_shares

ROW_C = 0.01  # the synthetic path's temperature step a row (10 Hz at 6 degC/min)
ROW_S = 0.1
# The sets differ by 2 x SET_OFFSET_LSB, as the twin's X sets do at the ends
# of the staircase (16-31 LSB); the rows scatter as the twin's do about
# their line before a turn (0.5-1 LSB, runs/demo/batch), correlated over 4 s.
SET_OFFSET_LSB = 15.0
NOISE_LSB = 1.0
# The device's trend detector switches its label after this much excursion (lib/Compensation
# TrendDetector, whose Schmitt trigger physics.sensor.drift_sets follows).
LABEL_HYSTERESIS_C = 0.5
TURNS_C = (20.0, 44.0, -10.0, 30.0)  # two reversals a position, each with long runs both sides
TURNAROUND = "set selection at turnarounds"


def crossing_campaign(
    rng, width_c: float, set_offset: float = SET_OFFSET_LSB, turns=TURNS_C, axes=("X",), width_spread_c: float = 0.0
) -> Campaign:
    """Every angle of ANGLES_DEG along turns, its sensor crossing between
    the sets with a stop operator of width_c on the (filtered) temperature
    (each position's own, drawn N(width_c, width_spread_c)), each mounting
    and axis with its own offset, slope and noise about the drift."""
    temperature = np.concatenate(
        [np.arange(a, b, ROW_C if b > a else -ROW_C) for a, b in zip(turns[:-1], turns[1:])] + [[turns[-1]]]
    )
    labels = drift_sets(LABEL_HYSTERESIS_C, temperature[0], temperature)
    parts: dict[str, list] = {"W": [], "C": []}
    for index, angle in enumerate(ANGLES_DEG):
        width = max(0.0, width_c + rng.normal(0.0, width_spread_c)) if width_spread_c else width_c
        share = stop_shares(width, temperature[0], temperature, 1.0)
        reading = np.full(len(temperature), LSB_PER_G * np.sin(np.radians(angle)))
        drift = TRUE.evaluate(temperature, reading)
        residuals = {}
        for axis in axes:
            mounting = rng.normal(0.0, 3.0) + rng.normal(0.0, 0.3) * (temperature - 25.0)
            residual = blend(share, drift + set_offset, drift - set_offset) + mounting
            residuals[axis] = residual + smooth_noise(rng, len(temperature), NOISE_LSB, 40)
        for set_name, rows in parts.items():
            mine = labels == set_name
            rows.append(
                (
                    temperature[mine],
                    reading[mine],
                    {axis: values[mine] for axis, values in residuals.items()},
                    index,
                    np.flatnonzero(mine) * ROW_S,
                )
            )
    sets = {
        set_name: SetData(
            np.concatenate([part[0] for part in rows]),
            {axis: np.concatenate([part[1] for part in rows]) for axis in axes},
            {axis: np.concatenate([part[2][axis] for part in rows]) for axis in axes},
            np.concatenate([np.full(len(part[0]), part[3]) for part in rows]),
            time_s=np.concatenate([part[4] for part in rows]),
        )
        for set_name, rows in parts.items()
    }
    labels_text = tuple(f"p{index} (x {angle}.00 deg, y 0.00 deg)" for index, angle in enumerate(ANGLES_DEG))
    return Campaign(labels_text, sets, 0)


def crossing_of(campaign: Campaign, axes=("X",)):
    fits = [fit_surface(campaign.sets[s], s, axis) for axis in axes for s in ("W", "C")]
    angles = nominal_angles(campaign.positions)["X"]
    errors = {axis: axis_errors(campaign, fits, axis, angles) for axis in axes}
    return estimate_crossing(errors, fits), fits


# The synthetic paths' rate (ROW_C a ROW_S) and the certificate's field rate limit.
PATH_RATE_C_PER_S = ROW_C / ROW_S
FIELD_RATE_C_PER_S = 1.0 / 60.0
# The interval's widening for the filter's lag at the path's rate (crossing.py's docstring).
LAG_TRAVEL_C = FILTER_LAG_S * PATH_RATE_C_PER_S


@pytest.fixture(scope="module", params=[0.0, 1.5, 3.0])
def measured(request):
    width = request.param
    return width, crossing_of(crossing_campaign(np.random.default_rng(int(width * 10) + 1), width))[0]


def test_two_stop_operators_from_the_same_end_differ_by_at_most_one_less_their_widths_ratio():
    # On a monotone path the narrower operator has crossed at x = min(w, w_d)
    # while the wider is min / max of the way: exactly 1 - min / max. On
    # paths that wander (steps of either sign) from the same saturated end
    # the difference never exceeds it: 2000 random paths, float rounding only.
    rise = np.linspace(0.0, 8.0, 8001)
    for width, device in ((0.5, 1.5), (3.0, 1.5), (1.5, 1.5), (2.0, 6.0)):
        difference = warming_shares(width, 0.0, rise, 0.0) - warming_shares(device, 0.0, rise, 0.0)
        assert np.max(np.abs(difference)) == pytest.approx(crossing_mismatch(width, device), abs=1e-3)
    rng = np.random.default_rng(4)
    for _ in range(2000):
        width, device = rng.uniform(0.05, 6.0, 2)
        path = np.cumsum(rng.normal(rng.uniform(-0.1, 0.1), rng.uniform(0.01, 1.0), 300))
        start = float(rng.choice([0.0, 1.0]))
        difference = warming_shares(width, 0.0, path, start) - warming_shares(device, 0.0, path, start)
        assert np.max(np.abs(difference)) <= crossing_mismatch(width, device) + 1e-12
    assert crossing_mismatch(0.0) == 1.0 and crossing_mismatch(FIRMWARE_TRANSITION_C) == 0.0
    # Largest at an end of the interval: below w_d the narrow end, above it the wide one.
    assert largest_mismatch(1.0, 2.0) == pytest.approx(max(1 - 1.0 / 1.5, 1 - 1.5 / 2.0))


def test_an_instant_crossing_is_the_limit_of_a_narrow_one():
    path = np.array([1.0, 1.2, 1.2, 0.9, 0.9, 1.4, 1.3])
    narrow = warming_shares(1e-9, 1.0, path, 0.0)
    np.testing.assert_array_equal(stop_shares(0.0, 1.0, path, 0.0), narrow)
    np.testing.assert_array_equal(stop_shares(0.0, 1.0, path, 0.0), [0, 1, 1, 0, 0, 1, 0])


def test_a_known_crossing_width_lies_in_its_interval(measured):
    width, crossing = measured
    # Both reversals of every position: the top one after warming from
    # 20 degC, the bottom one after cooling 54 degC.
    assert len(crossing.reversals) == 2 * len(ANGLES_DEG) and crossing.unevaluated == 0
    assert {r.old_set for r in crossing.reversals} == {"W", "C"}
    assert all(r.rate_c_per_s == pytest.approx(PATH_RATE_C_PER_S, rel=0.01) for r in crossing.reversals)
    low, high = crossing.width_interval_c(FIELD_RATE_C_PER_S)
    assert low <= width <= high, (width, crossing.widths_c)
    # 1 LSB of noise against a 30 LSB step reads each width to ~0.2 degC or
    # better; an interval as wide as the device's whole width (beside the
    # lag's widening) would be the method reading noise, not the crossing.
    assert high - LAG_TRAVEL_C - low < FIRMWARE_TRANSITION_C, (low, high)
    # Unbiased: the widths' mean within its own 95 % confidence interval of
    # the truth (t s / sqrt(n)), plus half a grid step. Without the step's
    # scale free (crossing._profile), the fitted surfaces' share of the step
    # reads 3.0 degC as 2.84 and fails this.
    widths = crossing.widths_c
    mean_half = stats.t.ppf(0.975, len(widths) - 1) * np.std(widths, ddof=1) / np.sqrt(len(widths))
    assert abs(np.mean(widths) - width) <= mean_half + WIDTH_STEP_C / 2, (np.mean(widths), mean_half)


def test_the_mismatch_is_small_when_the_widths_match_and_whole_for_an_instant_crossing(measured):
    width, crossing = measured
    m = crossing.mismatch(FIELD_RATE_C_PER_S)
    assert m == pytest.approx(largest_mismatch(*crossing.width_interval_c(FIELD_RATE_C_PER_S)))
    if width == FIRMWARE_TRANSITION_C:
        # An interval within +-0.5 degC of 1.5 (a third of the width), widened
        # above by the lag at 6 degC/min (1 degC), gives m <= 1 - 1.5 / 3.
        assert m <= crossing_mismatch(width + 0.5 + LAG_TRAVEL_C), (m, crossing.width_interval_c(FIELD_RATE_C_PER_S))
    elif width == 0.0:
        # An interval reaching down to 0.15 degC (a tenth of w_d) gives m >= 0.9.
        assert m >= 0.9, (m, crossing.width_interval_c(FIELD_RATE_C_PER_S))
    else:
        assert m >= crossing_mismatch(width) - 0.1, m  # 1 - 1.5 / 3 = 0.5, less a grid step's worth at each end


@pytest.mark.slow
def test_the_variance_between_reversals_is_read_from_two_axes_and_only_it_widens_the_interval():
    # One width for every reversal: the axes' readings err apart, so their
    # covariance is about 0 and the interval is the mean's, narrower than
    # one axis's, which takes all the scatter as the reversals'.
    fixed = crossing_campaign(np.random.default_rng(11), 1.5, axes=("X", "Y"))
    both, _ = crossing_of(fixed, ("X", "Y"))
    alone, _ = crossing_of(fixed, ("X",))
    assert alone.between_variance() is None
    assert both.between_variance() < 0.02, both.between_variance()
    low, high = both.width_interval_c(FIELD_RATE_C_PER_S)
    single_low, single_high = alone.width_interval_c(FIELD_RATE_C_PER_S)
    assert high - low < single_high - single_low
    # Widths that truly differ between positions (sd 0.4 degC): the axes
    # share them, their covariance reads that variance, and the interval
    # holds the positions' own widths.
    spread = 0.4
    varied = crossing_campaign(np.random.default_rng(12), 1.5, axes=("X", "Y"), width_spread_c=spread)
    crossing, _ = crossing_of(varied, ("X", "Y"))
    between = crossing.between_variance()
    # 14 reversals of 7 positions: the covariance's sampling error is ~40 % of it.
    assert 0.3 * spread**2 < between < 2.5 * spread**2, between
    low, high = crossing.width_interval_c(FIELD_RATE_C_PER_S)
    assert (high - LAG_TRAVEL_C) - low > 2 * 1.5 * spread
    assert "covariance of the widths the two axes read apart" in crossing.source(FIELD_RATE_C_PER_S)


def test_the_lag_widens_the_interval_by_the_travel_the_filter_hides():
    # Above: the die's crossing the lag hid at the turns' rate; below: the
    # field's faster reversals hide more, beyond the campaign's rate.
    fixed = crossing_campaign(np.random.default_rng(13), 1.5)
    crossing, _ = crossing_of(fixed)
    slow_field = crossing.width_interval_c(0.0)
    fast_field = crossing.width_interval_c(PATH_RATE_C_PER_S + 0.05)
    assert fast_field[1] == pytest.approx(slow_field[1])
    assert slow_field[0] - fast_field[0] == pytest.approx(FILTER_LAG_S * 0.05, rel=1e-6)
    widths = crossing.widths_c
    assert slow_field[1] - LAG_TRAVEL_C > np.mean(widths) > slow_field[0]


def test_a_campaign_without_time_or_reversals_keeps_the_whole_difference(tmp_path):
    untimed = campaign_of(np.random.default_rng(5))  # test_certificate's: rows without time_s
    crossing, fits = crossing_of(untimed)
    assert not crossing.reversals and crossing.mismatch(FIELD_RATE_C_PER_S) == 1.0
    assert "not measured" in crossing.source(FIELD_RATE_C_PER_S) and "m = 1" in crossing.source(FIELD_RATE_C_PER_S)
    # A reversal that comes back less than MAX_WIDTH_C cannot tell the widest
    # candidate from a narrower one, and is said to be left out.
    short = crossing_campaign(np.random.default_rng(7), 1.5, turns=(-10.0, 44.0, 44.0 - MAX_WIDTH_C / 2))
    crossing = crossing_of(short)[0]
    assert crossing.mismatch(FIELD_RATE_C_PER_S) == 1.0 and crossing.unevaluated == len(ANGLES_DEG)
    assert "after it" in crossing.source(FIELD_RATE_C_PER_S)


def test_sets_that_do_not_differ_cannot_show_a_width():
    crossing = crossing_of(crossing_campaign(np.random.default_rng(8), 1.5, set_offset=0.0))[0]
    assert not crossing.reversals and crossing.unevaluated == 2 * len(ANGLES_DEG)
    assert crossing.mismatch(FIELD_RATE_C_PER_S) == 1.0 and "sigma" in crossing.source(FIELD_RATE_C_PER_S)


def test_the_turnaround_row_takes_m_of_the_sets_difference(tmp_path):
    campaign = crossing_campaign(np.random.default_rng(9), 1.5)
    crossing, fits = crossing_of(campaign)
    untimed = Campaign(
        campaign.positions,
        {name: SetData(d.temperature_c, d.acceleration, d.residual, d.position) for name, d in campaign.sets.items()},
        0,
    )
    rows, documents = {}, {}
    for name, each in (("timed", campaign), ("untimed", untimed)):
        documents[name] = certify(each, fits, tmp_path, "TT-A").document
        rows[name] = next(c for c in documents[name]["budget"]["X"]["components"] if c["name"] == TURNAROUND)

    def contributions(document: dict) -> list[float]:
        return [cell["contributions_deg"][TURNAROUND] for cell in document["cells"]]

    # The same cells, the same fits: only m differs, 1 without the rows' time (the cells round to 1e-6 deg).
    np.testing.assert_allclose(
        contributions(documents["timed"]),
        crossing.mismatch(FIELD_RATE_C_PER_S) * np.array(contributions(documents["untimed"])),
        rtol=1e-4,
        atol=1e-6,
    )
    assert rows["timed"]["value"] < 0.5 * rows["untimed"]["value"]
    assert f"measured at {2 * len(ANGLES_DEG)} reversals" in rows["timed"]["source"]
    assert f"m = {crossing.mismatch(FIELD_RATE_C_PER_S):.2f}" in rows["timed"]["source"]
    assert "m = 1" in rows["untimed"]["source"]


def test_load_gives_each_row_its_time(tmp_path):
    temperatures, sets = cycle()
    for angle in ANGLES_DEG[:3]:
        write_run_log(tmp_path / f"pos{angle}" / "run.csv", angle, temperatures, sets)
    campaign = load(tmp_path)
    for set_name in ("W", "C"):
        data = campaign.sets[set_name]
        written = np.flatnonzero(np.array(sets) == set_name) / 10.0  # write_run_log's time_s: a row each 0.1 s
        for position in np.unique(data.position):
            np.testing.assert_allclose(data.time_s[data.position == position], written, atol=1e-9)
