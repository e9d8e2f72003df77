"""A sensor of the batch replayed on the host through a run the twin made
with another (or the same) sensor, or through a field profile, giving the
IMU frames the twin would have logged with that sensor: the field benchmark's
replay (docs/benchmarks/field-accuracy.md; ``field_bench``).

The twin steps the sensor every ``STEP_S`` on its environment (the inner
face of the chamber, or the air of a field scenario, which has no chamber)
and serves the registers to the IMU reader, whose firmware filters,
compensates and decimates them. The replay does the same on arrays: the
model's sensor (``physics.sensor_series``, step for step the samples
``Sensor.step`` gives; test_sensor_series) and the firmware's own
processing (``native.imu_process``, frame for frame what the firmware sends;
test_native_processing), read at the samples the firmware made frames of.

- **A field profile**: the environment is the scenario's ambient at each
  step's time, exactly as the twin asks it, and the sensor starts in the
  set state the scenario gives it (field-cooling: its cooling one), so the
  replay is the twin's run to the last bit (test_field_bench: every frame,
  at the precision the firmware prints it).
- **A chamber run** (a campaign position): run.csv holds the inner face
  (``true_inner_c``, to 1e-4 degC) only at its frames, one step in ten,
  sampled in the step after the frame's sample (the step in which the frame
  reached the host). Between them the face is interpolated linearly. On a
  twin Figure 8 run that put the face 5e-5 degC RMS off (3.6e-3 at most, at
  the drive's switches), and 1 register value in 500 one LSB off, which the
  Kalman filter passes on at a hundredth: the frames within 0.01 LSB (and
  0.0005 degC) of the twin's, beyond the printed rounding (TWIN_TOLERANCE).

The frames' samples: the firmware's first frame is of the sample served in
step 13 (the IMU reader's start: t_ms 132 in every twin run), or in step 14
when it loads a coefficient block from its EEPROM at start (t_ms 144), as
a board in the field does; then every ``DECIMATION``-th sample, each
filtered from ``DECIMATION - 1`` samples before the first (docs/firmware.md).
A frame's ``time_s`` is its sample's step plus the 2 ms (4 ms with the
block) the firmware takes to send it (``FrameClock``). A twin run.csv gives
each frame's step by its ``time_s``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import native
from ..physics import Model
from ..physics.sensor import sensor_series
from ..run.log import RunColumns
from ..twin.scenarios import DRAWS_WEATHER, Scenario, ScenarioOptions, build

STEP_S = 0.01  # the twin's step (twin.simulate.STEP_S) and the IMU's sample period
DECIMATION = native.DEFAULT_DECIMATION


@dataclass(frozen=True)
class FrameClock:
    """When the IMU reader sends frames: the step whose sample its first
    frame carries, and how long after that sample's step a frame's t_ms is."""

    first_step: int
    latency_s: float


# Measured on twin runs (test_field_bench): the firmware's defaults, and a
# coefficient block loaded from the EEPROM at start (one step later).
DEFAULTS_CLOCK = FrameClock(13, 0.002)
EEPROM_CLOCK = FrameClock(14, 0.004)
FIELD_PROFILES = ("field-warming", "field-cooling", "field-alternating", "field-days")
# The frame columns the replay gives (native's names; the temperature is run.csv's imu_temp_c).
FRAME_COLUMNS = ("ax_filt", "ay_filt", "az_filt", "ax_comp", "ay_comp", "az_comp", "temp_c")
# How far a chamber run's replay may lie from the twin's frames beyond the
# printed rounding (the module's docstring): LSB, and degC for temp_c.
TWIN_TOLERANCE = {"lsb": 0.01, "degc": 0.0005}
# What the firmware prints: 0.1 LSB, 0.001 degC.
PRINTED_DECIMALS = {"lsb": 1, "degc": 3}


@dataclass(frozen=True)
class SensorInputs:
    """What the twin's sensor was stepped through, one value per step from
    the run's start: the environment (degC), the table's angles (one
    position), where the sensor started, and the steps whose samples
    became frames."""

    start_c: float
    environment_c: np.ndarray
    incl_x_deg: float
    incl_y_deg: float
    frame_steps: np.ndarray
    latency_s: float = DEFAULTS_CLOCK.latency_s
    # The sensor's set state at the start (Scenario.sensor_warming_share).
    warming_share: float = 1.0

    @property
    def steps(self) -> int:
        return int(self.frame_steps[-1]) + 1

    @property
    def first_step(self) -> int:
        """The first sample the firmware filtered."""
        return int(self.frame_steps[0]) - (DECIMATION - 1)

    @property
    def time_s(self) -> np.ndarray:
        """Each frame's time on the IMU's clock, as run.csv's time_s."""
        return np.round(self.frame_steps * STEP_S + self.latency_s, 3)


def frame_steps_of(time_s: np.ndarray) -> np.ndarray:
    """The step whose sample each twin frame carries, from its time_s (a
    latency of a few ms, FrameClock's, rounds off)."""
    return np.rint(np.asarray(time_s, dtype=float) / STEP_S - 0.25).astype(np.int64)


def position_inputs(columns: RunColumns) -> SensorInputs:
    """A twin chamber run's sensor inputs from its run.csv: the inner face
    each frame's row holds (``true_inner_c``, sampled one step after the
    frame's sample) interpolated onto every step; the sensor started at the
    room's temperature (a campaign position's chamber starts at rest in it)."""
    numbers = columns.numbers
    steps = frame_steps_of(numbers["time_s"])
    face = numbers["true_inner_c"]
    if not np.isfinite(face).all():
        raise ValueError(f"{columns.path}: the replay needs true_inner_c on every row (a twin run with a chamber)")
    environment = np.interp(np.arange(int(steps[-1]) + 1), steps + 1, face)
    return SensorInputs(
        start_c=float(numbers["ambient_c"][0]),
        environment_c=environment,
        incl_x_deg=float(numbers["incl_x_deg"][0]),
        incl_y_deg=float(numbers["incl_y_deg"][0]),
        frame_steps=steps,
    )


def field_scenario(profile: str, tilt_deg: float, seed: int, duration_s: float | None = None) -> Scenario:
    """The field scenario at a tilt about X; field-days draws its weather from seed."""
    weather_seed = seed if profile in DRAWS_WEATHER else 0
    return build(profile, ScenarioOptions(incl_x_deg=tilt_deg, duration_s=duration_s, seed=weather_seed))


def field_inputs(scenario: Scenario, clock: FrameClock = EEPROM_CLOCK) -> SensorInputs:
    """A field scenario's sensor inputs: the air at each step's time, as the
    twin asks it (no chamber: the air is the sensor's environment); the
    frames as the IMU reader sends them with its coefficients in the EEPROM
    (clock)."""
    steps = round(scenario.duration_s / STEP_S)
    ambient = scenario.ambient_c
    environment = np.fromiter((ambient(step * STEP_S) for step in range(steps)), dtype=float, count=steps)
    position = scenario.positions[0]
    return SensorInputs(
        start_c=float(ambient(0.0)),
        environment_c=environment,
        incl_x_deg=float(position.incl_x_deg),
        incl_y_deg=float(position.incl_y_deg),
        frame_steps=np.arange(clock.first_step, steps, DECIMATION, dtype=np.int64),
        latency_s=clock.latency_s,
        warming_share=scenario.sensor_warming_share,
    )


def replay_frames(model: Model, seed: int, inputs: SensorInputs, coefficients: Any = None) -> dict[str, np.ndarray]:
    """The frames the IMU reader sends with this sensor (its model and noise
    seed) through these inputs and these coefficients (a CoefficientTable or
    36 numbers; None: the firmware's defaults): native.imu_process's outputs
    at the frames, and the raw registers of each frame's sample."""
    count = inputs.steps
    series = sensor_series(
        model,
        seed,
        inputs.start_c,
        np.full(count, STEP_S),
        inputs.environment_c[:count],
        np.full(count, inputs.incl_x_deg),
        np.full(count, inputs.incl_y_deg),
        inputs.warming_share,
    )
    first = inputs.first_step
    registers = [series.ax, series.ay, series.az, series.temperature_raw]
    del series
    frames = native.imu_process(
        *(values[first:] for values in registers), coefficients=coefficients, at=inputs.frame_steps - first
    )
    for name, values in zip(("ax_raw", "ay_raw", "az_raw"), registers):
        frames[name] = values[inputs.frame_steps]
    return frames


def printed(frames: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The frame columns as the firmware prints them (0.1 LSB, 0.001 degC),
    as float: what run.csv holds and a monitoring user reads."""
    return {
        name: np.round(frames[name].astype(float), PRINTED_DECIMALS["degc" if name == "temp_c" else "lsb"])
        for name in FRAME_COLUMNS
    }


def twin_gap(columns: RunColumns, frames: Mapping[str, np.ndarray]) -> dict[str, float]:
    """Per frame column, the largest distance of the replay from the twin's
    run.csv beyond the printed rounding (0 where every frame prints the
    same), and "comp_set": the share of frames whose set differs."""
    numbers = columns.numbers
    gaps = {}
    for name in FRAME_COLUMNS:
        column = "imu_temp_c" if name == "temp_c" else name
        half_unit = 0.5 * 10.0 ** -PRINTED_DECIMALS["degc" if name == "temp_c" else "lsb"]
        distance = np.abs(frames[name].astype(float) - numbers[column]) - half_unit
        gaps[name] = float(max(0.0, np.max(distance)))
    letters = np.array(list(native.SET_LETTERS))[frames["set"]]
    gaps["comp_set"] = float(np.mean(letters != columns.texts["comp_set"]))
    return gaps


def within_tolerance(gaps: Mapping[str, float], tolerance: Mapping[str, float] = TWIN_TOLERANCE) -> bool:
    """Whether a replay's gaps to the twin (twin_gap) are within the tolerance."""
    for name, gap in gaps.items():
        if name == "comp_set":
            if gap > 0.0:
                return False
        elif gap > tolerance["degc" if name == "temp_c" else "lsb"] + 1e-9:
            return False
    return True
