"""The chamber's candidate terms for discovery: off by default and then
changing nothing, and each, switched on, acting as its summary says; and
the chamber's replay of a twin run, open loop from the logged drive."""

import math

import numpy as np
import pytest

from thermotilt.discovery.replay import chamber_replay, load_measured
from thermotilt.physics import Chamber, Model

AMBIENT_C = 22.0


def model_with(name, **values):
    return Model.from_document({name: {"enabled": True, **values}}, "test")


def trace(model, duty, direction=1, steps=600, dt_s=0.5):
    """(inner face, both readings) after each step at a constant drive."""
    chamber = Chamber(model, AMBIENT_C)
    out = []
    for _ in range(steps):
        chamber.step(dt_s, duty, direction, AMBIENT_C)
        out.append((chamber.inner_c, *chamber.readings_c()))
    return out


def test_the_chamber_candidates_are_off_by_default_and_then_change_nothing():
    model = Model.load()
    assert not model.enabled("drive_dead_zone") and not model.enabled("thermistor_offset")
    switched_off = Model.from_document(
        {
            "drive_dead_zone": {"enabled": False, "threshold_duty": 0.3},
            "thermistor_offset": {"enabled": False, "offset_c": {"inner": 2.0, "outer": -2.0}},
        },
        "test",
    )
    for duty in (0.1, 0.7):
        assert trace(switched_off, duty, steps=50) == trace(model, duty, steps=50)


@pytest.mark.parametrize("direction", [1, -1])
def test_a_dead_zone_moves_no_heat_below_its_threshold_and_all_at_full_duty(direction):
    dead = model_with("drive_dead_zone", threshold_duty=0.2)
    below = trace(dead, 0.19, direction)
    assert all(face == AMBIENT_C for face, _, _ in below)
    assert trace(dead, 1.0, direction) == trace(Model.load(), 1.0, direction)
    # Above the threshold the cell sees (d - t) / (1 - t): 0.6 -> 0.5.
    np.testing.assert_allclose(trace(dead, 0.6, direction), trace(Model.load(), 0.5, direction), rtol=1e-12)


def test_a_thermistor_offset_shifts_the_readings_and_nothing_else():
    shifted = model_with("thermistor_offset", offset_c={"inner": 0.4, "outer": -0.3})
    for (face, inner, outer), (face0, inner0, outer0) in zip(trace(shifted, 0.5), trace(Model.load(), 0.5)):
        assert face == face0
        assert inner == pytest.approx(inner0 + 0.4, abs=1e-12)
        assert outer == pytest.approx(outer0 - 0.3, abs=1e-12)
    chamber, plain = Chamber(shifted, AMBIENT_C), Chamber(Model.load(), AMBIENT_C)
    plain.inner_thermistor_c, plain.outer_thermistor_c = AMBIENT_C + 0.4, AMBIENT_C - 0.3
    assert chamber.thermistor_millivolts() == pytest.approx(plain.thermistor_millivolts(), abs=1e-9)


def test_start_at_readings_puts_the_faces_where_the_readings_say():
    chamber = Chamber(model_with("thermistor_offset", offset_c={"inner": 0.4, "outer": -0.3}), AMBIENT_C)
    chamber.start_at_readings(30.0, 10.0)
    assert (chamber.inner_c, chamber.outer_c) == pytest.approx((29.6, 10.3))
    assert chamber.readings_c() == pytest.approx((30.0, 10.0))


@pytest.mark.long
@pytest.mark.twin
def test_the_chamber_replay_follows_a_twin_run_open_loop(cycle_runs):
    # The twin's chamber is this model's, closed by the real firmware every
    # 250 ms; the replay sees the drive only at the logged 1 s status frames
    # and never the readings after the first, so what it leaves is the drive
    # between frames and the ADC's steps (~0.09 degC at 25 degC).
    # Bound: a tenth of the program's 2 degC step, so that each step's
    # residual stays its own (measured at this commit: 0.099 and 0.074 degC).
    measured = load_measured(cycle_runs[0])
    predicted = chamber_replay(measured, Model.load())
    assert np.ptp(measured.chamber_c) > 50.0
    for channel in ("inner", "outer"):
        used = measured.used[channel]
        residual = (measured.observed[channel] - predicted[channel])[used]
        assert math.sqrt(np.mean(residual**2)) < 0.2, channel
