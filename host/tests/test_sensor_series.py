"""sensor_series against Sensor.step, step for step: the replay and the
effect hider run the sensor as a series (physics/sensor.py), the twin steps
it, and both must give the same sample to the last bit — the series runs
each term's own function on arrays, in the step's order of sums."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermotilt.physics import Model, Sensor
from thermotilt.physics.sensor import SensorSeries, sensor_series

PROPERTY = settings(max_examples=40, deadline=None)
CANDIDATES = ("sensor_lag", "hysteresis", "scale_tempco", "cross_axis")
SCATTER = ("noise", "bias_instability", "drift_repeatability")


def stepped(model: Model, seed: int, start_c: float, share: float, *inputs: np.ndarray) -> list[tuple]:
    sensor = Sensor(model, seed, start_c, share)
    return [sensor.step(*step) for step in zip(*(values.tolist() for values in inputs))]


def assert_same(series: SensorSeries, samples: list[tuple]) -> None:
    for index, name in enumerate(SensorSeries._fields):
        expected = np.array([sample[index] for sample in samples])
        assert np.array_equal(series[index], expected), name


@st.composite
def runs(draw) -> tuple[np.ndarray, ...]:
    """Table positions held for a while, the environment wandering and
    ramping through the drift's Schmitt band, and steps of 10 ms with some
    longer ones (the replay's uneven row steps, the flicker's refills)."""
    positions = draw(st.integers(1, 6))
    held = draw(st.lists(st.integers(1, 400), min_size=positions, max_size=positions))
    count = sum(held)
    angles = draw(st.lists(st.tuples(st.floats(-90, 90), st.floats(-90, 90)), min_size=positions, max_size=positions))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    incl_x = np.repeat([x for x, _ in angles], held)
    incl_y = np.repeat([y for _, y in angles], held)
    environment_c = draw(st.floats(-10, 45)) + np.cumsum(rng.normal(0.0, draw(st.floats(0.0, 0.5)), count))
    dt_s = np.where(rng.random(count) < draw(st.sampled_from([0.0, 0.01, 0.3])), 0.2, 0.01)
    return dt_s, environment_c, incl_x, incl_y


@PROPERTY
@given(
    run=runs(),
    seed=st.integers(0, 2**32 - 1),
    candidates=st.sets(st.sampled_from(CANDIDATES)),
    scatter=st.sets(st.sampled_from(SCATTER)),
    quantised=st.booleans(),
    share=st.sampled_from([1.0, 0.0, 0.25]),
)
def test_a_series_gives_the_steps_samples(run, seed, candidates, scatter, quantised, share):
    switches = {name: name in candidates for name in CANDIDATES}
    switches.update({name: name in scatter for name in SCATTER}, temperature_quantisation=quantised)
    model = Model.load().with_terms(switches)
    start_c = float(run[1][0]) + 0.3
    assert_same(sensor_series(model, seed, start_c, *run, share), stepped(model, seed, start_c, share, *run))


def test_a_series_refuses_a_step_that_does_not_advance():
    zero = np.zeros(3)
    with pytest.raises(ValueError, match="dt_s must be > 0"):
        sensor_series(Model.load(), 1, 20.0, np.array([0.01, 0.0, 0.01]), zero + 20.0, zero, zero)


def test_a_series_on_a_die_it_has_seen_gives_the_steps_samples_again():
    # The set series are kept per die (physics/sensor.py): a second model
    # on the same die must still give its own steps' samples.
    rng = np.random.default_rng(5)
    count = 3000
    dt_s = np.where(rng.random(count) < 0.05, 0.2, 0.01)
    environment_c = 20.0 + np.cumsum(rng.normal(0.0, 0.05, count))
    incl_x = np.repeat([30.0, -30.0, 0.0], count // 3)
    incl_y = np.repeat([0.0, 0.0, 30.0], count // 3)
    run = (dt_s, environment_c, incl_x, incl_y)
    for switches in ({"scale_tempco": False}, {"scale_tempco": True}, {"hysteresis": True}):
        model = Model.load().with_terms(switches)
        assert_same(sensor_series(model, 3, 20.2, *run), stepped(model, 3, 20.2, 1.0, *run))
