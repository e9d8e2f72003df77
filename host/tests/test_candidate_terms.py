"""The discovery workflow's candidate terms and the SensorSample fields
the replay needs: the unrounded acceleration the registers were rounded
from and the temperature the drift was evaluated at."""

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from thermotilt.physics import Model, Sensor

PROPERTY = settings(max_examples=60, deadline=None)

temperatures = st.floats(-10.0, 45.0)
angles = st.floats(-90.0, 90.0)
# (chamber temperature degC, incl x deg, incl y deg) per step; a few steps
# hold the table still, so the mounting and the ideal acceleration persist.
paths = st.lists(st.tuples(temperatures, angles, angles), min_size=2, max_size=25).map(
    lambda steps: [step for step in steps for _ in range(3)]
)
seeds = st.integers(0, 2**32 - 1)


def run(model, seed, path, dt_s=0.5):
    sensor = Sensor(model, seed, path[0][0])
    return [sensor.step(dt_s, *step) for step in path]


def unrounded(sample):
    return sample.unrounded_ax, sample.unrounded_ay, sample.unrounded_az


# --- the new SensorSample fields ----------------------------------------------


@PROPERTY
@given(seed=seeds, path=paths)
def test_the_registers_are_the_unrounded_acceleration_rounded(seed, path):
    for sample in run(Model.load(), seed, path):
        for register, value in zip((sample.ax, sample.ay, sample.az), unrounded(sample)):
            assert register == max(-32768, min(32767, math.floor(value + 0.5)))
        # The drift is evaluated at the reported temperature.
        assert sample.drift_temperature_c == sample.reported_c
