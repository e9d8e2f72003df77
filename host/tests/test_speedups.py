"""The faster forms of the physics' step-by-step series give the same floats
as the steps, and what is kept for the same inputs stays as it was made:
warming_shares in stretches against SetBlend.update, the series memo,
sensor_series on a die it has seen before, and the sizing of a hidden
effect by a root finder against the bisection it replaced."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermotilt.discovery import hide
from thermotilt.discovery.candidates import BY_NAME
from thermotilt.discovery.channel import gap_rms
from thermotilt.discovery.replay import Replay
from thermotilt.physics import Model, Sensor
from thermotilt.physics.sensor import SensorSeries, sensor_series
from thermotilt.physics.terms.lag import SeriesMemo
from thermotilt.set_blend import SetBlend, warming_shares

PROPERTY = settings(max_examples=200, deadline=None)


def stepped_shares(transition_c: float, start_c: float, temperature_c: np.ndarray, warming_share: float) -> np.ndarray:
    state = SetBlend(transition_c, warming_share)
    changes = np.diff(temperature_c, prepend=start_c)
    return np.array([state.update(change) for change in changes.tolist()], dtype=float)


@st.composite
def temperature_paths(draw) -> np.ndarray:
    """Ramps, holds and noise, as the die sees them, and now and then a NaN
    or a step larger than the transition."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    pieces = []
    for _ in range(draw(st.integers(1, 8))):
        count = draw(st.integers(0, 3000))
        rate = draw(st.sampled_from([0.0, 1e-3, -1e-3, 0.05, -0.05]))
        noise = draw(st.sampled_from([0.0, 1e-6, 1e-3, 0.3]))
        pieces.append(rate * np.arange(count) + rng.normal(0.0, noise, count) if noise else rate * np.arange(count))
    path = draw(st.floats(-20, 50)) + np.cumsum(np.concatenate([np.zeros(1), *pieces]))
    if draw(st.booleans()) and len(path) > 2:
        path[draw(st.integers(0, len(path) - 1))] = np.nan
    return path


@PROPERTY
@given(
    path=temperature_paths(),
    transition_c=st.sampled_from([1.5, 0.25, 1e-9, 40.0]),
    warming_share=st.sampled_from([1.0, 0.0, -0.0, 0.5, 0.999999]),
    start_offset_c=st.floats(-2.0, 2.0),
)
def test_warming_shares_are_the_updates_floats(path, transition_c, warming_share, start_offset_c):
    start_c = float(path[0]) + start_offset_c if math.isfinite(path[0]) else 0.0
    expected = stepped_shares(transition_c, start_c, path, warming_share)
    # Bytes: NaN where update gives NaN, and the sign of a zero, too.
    assert warming_shares(transition_c, start_c, path, warming_share).tobytes() == expected.tobytes()


def test_warming_shares_of_no_steps_are_empty():
    assert warming_shares(1.5, 20.0, np.array([])).shape == (0,)


def test_the_memo_keeps_read_only_series_by_their_inputs_within_its_budget():
    memo = SeriesMemo(budget_bytes=3 * 8 * 100)
    made = []

    def make(values: np.ndarray):
        made.append(values)
        return values * 2.0, values + 1.0

    first = np.arange(100.0)
    kept = memo.get((1.0, first), lambda: make(first))
    assert memo.get((1.0, first.copy()), lambda: make(first)) is kept
    assert not kept[0].flags.writeable and not kept[1].flags.writeable
    # Another number, another array of the same bytes: computed again.
    memo.get((2.0, first), lambda: make(first))
    memo.get((1.0, first[:50]), lambda: make(first[:50]))
    assert len(made) == 3
    # Over the budget, the oldest went.
    memo.get((1.0, first), lambda: make(first))
    assert len(made) == 4


def test_sensor_series_on_a_die_it_has_seen_gives_the_steps_samples_again():
    rng = np.random.default_rng(5)
    count = 3000
    dt_s = np.where(rng.random(count) < 0.05, 0.2, 0.01)
    environment_c = 20.0 + np.cumsum(rng.normal(0.0, 0.05, count))
    incl_x = np.repeat([30.0, -30.0, 0.0], count // 3)
    incl_y = np.repeat([0.0, 0.0, 30.0], count // 3)
    for switches in ({"scale_tempco": False}, {"scale_tempco": True}, {"hysteresis": True}):
        model = Model.load().with_terms(switches)
        series = sensor_series(model, 3, 20.2, dt_s, environment_c, incl_x, incl_y)
        sensor = Sensor(model, 3, 20.2)
        samples = [sensor.step(*step) for step in zip(dt_s.tolist(), environment_c.tolist(), incl_x, incl_y)]
        for index, name in enumerate(SensorSeries._fields):
            assert np.array_equal(series[index], np.array([sample[index] for sample in samples])), name


def bisected(candidate, model, frames, channel, target_rms, end):
    """The value hide._scaled found before the root finder: 30 halvings of
    the log-scale bracket from the model's value (its least, for a term the
    model has off) to the bound; and the precision that gives."""
    predict = Replay(frames)
    used = frames.used[channel]
    base = predict(model)[channel][used]

    def effect_rms(value: float) -> float:
        return gap_rms(channel, predict(candidate.changed(model, {channel: value}))[channel][used] - base)

    start = candidate.value(model, channel) if model.enabled(candidate.name) else candidate.bounds[0]
    near, far = math.log(start), math.log(end)
    for _ in range(30):
        middle = 0.5 * (near + far)
        if effect_rms(math.exp(middle)) < target_rms:
            near = middle
        else:
            far = middle
    return math.exp(0.5 * (near + far)), abs(math.log(end / start)) / 2**31


@pytest.mark.parametrize("snr", [1.0, 4.0])
def test_a_non_additive_effect_is_sized_as_finely_as_by_bisection(tmp_path: Path, snr: float):
    inputs = hide.staircase_inputs(tmp_path / "run.csv", positions=((30.0, 0.0),), high_c=20.0, step_c=10.0)
    model = Model.load()
    measured = hide._read_inputs(inputs).measured
    run = hide._NullRun.of(measured, model, "model", seed=7)
    candidate, channel = BY_NAME["sensor_lag"], "X"
    target_rms = snr * hide._noise_rms(run.measured, model, channel)
    value, effect_rms = hide._scaled(candidate, model, run.measured, channel, target_rms, sign=1.0)
    expected, bisection_precision = bisected(candidate, model, run.measured, channel, target_rms, candidate.bounds[1])
    assert abs(math.log(value / expected)) <= 2 * bisection_precision
    assert effect_rms == pytest.approx(target_rms, rel=1e-6)
