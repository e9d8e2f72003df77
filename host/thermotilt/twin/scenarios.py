"""What the twin runs: the paper's experiments as timelines of ambient
temperature, tilt-table positions and chamber commands.

A scenario is data (times, angles, command frames); ``thermotilt.twin.simulate``
plays it against the firmware and the physics model. The chamber program is
sent exactly as the host would send it to the real Mega (SETPRG, START).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..program import (
    CALIBRATION_MAX_C,
    CALIBRATION_MIN_C,
    CONTROLLERS,
    DEFAULT_CONTROLLER,
    DEFAULT_HOLD_START,
    DEFAULT_REST_S,
    HOLD_STARTS,
    PAPER_HOLD_S,
    PAPER_STEP_C,
    REACHED_BAND_C,
)
from ..run.log import RunColumns
from . import figures, weather

# The firmware prints its version and reads its thermistors first; commands
# are sent once it runs, as a host would after opening the port.
PROGRAM_SENT_S = 1.0
CONTROL_SENT_S = 1.25
PROGRAM_STARTED_S = 1.5


# Ambient temperatures. Figure 8's 16..22 degC run must cross the outside
# temperature between its 18 and 20 degC steps (the paper's overshoot), so
# 19 degC; the calibration runs happen in a lab at 22 degC.
FIG8_AMBIENT_C = 19.0
LAB_AMBIENT_C = 22.0

# How long the waits take in the twin's default chamber, measured in a
# -10..45 degC cycle with every step waiting (seed 7, 22 degC ambient, 60 s
# holds, the chamber of 54e87d3): the first step took 495 s to come from 22 to
# -9 degC (16 s per degC), the other 56 steps waited 617 s in all (3-29 s
# each, the longest at the cold end). A scenario is played for a fixed time,
# so the first gets a 25 % margin and the steps twice their mean (shorter
# holds leave the face farther behind); what is left over is idle.
REACH_S_PER_C_FROM_AMBIENT = 20.0
REACH_S_PER_STEP = 20.0

# The default model's [temperature_offset]: its die reads this much off the
# air. Section 3.3 gives the cooling night's air as 27 -> 17 degC, section 4.3
# the sensor's reading as 26 -> 16 degC: the same -1 degC.
FIELD_SENSOR_OFFSET_C = -1.0

# Section 3.2: 0 deg, then 5..45 deg in 5 deg steps on each axis, both ways.
CAMPAIGN_ANGLES_DEG = tuple(range(5, 50, 5))


class ScenarioError(ValueError):
    """Options a scenario cannot run with."""


@dataclass(frozen=True)
class Command:
    at_s: float
    frame_type: str
    values: tuple = ()
    # Which firmware it is for: "thermal_chamber" or "imu_reader".
    board: str = "thermal_chamber"


@dataclass(frozen=True)
class TablePosition:
    at_s: float
    label: str
    incl_x_deg: float
    incl_y_deg: float


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    duration_s: float
    uses_chamber: bool
    ambient_c: Callable[[float], float]
    positions: tuple[TablePosition, ...]
    commands: tuple[Command, ...] = ()
    # Named moments the analysis needs, e.g. when each program started.
    marks: dict[str, float] = field(default_factory=dict)
    # Stop once the chamber's program is over (phase back to idle or done):
    # the duration then only bounds a program whose waiting steps are timed
    # with a margin (reach_allowance_s).
    ends_with_program: bool = False
    # What it was built with (build), so that a run can be made again.
    options: ScenarioOptions | None = None
    # The paper's figures this experiment has, from its run.csv (twin/figures).
    paper_figures: Callable[[RunColumns], list[str]] | None = None
    # Where the sensor's history left its set state (set_blend): 1 warming,
    # as the paper's cycles start; 0 hours into a cooling.
    sensor_warming_share: float = 1.0


@dataclass(frozen=True)
class ScenarioOptions:
    hold_s: int = PAPER_HOLD_S
    rest_s: int = DEFAULT_REST_S
    incl_x_deg: float = 0.0
    incl_y_deg: float = 0.0
    positions: tuple[str, ...] | None = None
    ambient_c: float | None = None
    duration_s: float | None = None
    hold_start: str = DEFAULT_HOLD_START
    controller: str = DEFAULT_CONTROLLER
    # field-days only: how many days of weather (None: DEFAULT_FIELD_DAYS),
    # drawn from seed (the run's; 0 for a scenario not in DRAWS_WEATHER, so
    # that its options read as before). A summary.json from before these
    # two builds without them.
    days: float | None = None
    seed: int = 0


def program_steps(
    start_c: float | np.ndarray, max_c: float | np.ndarray, step_c: float | np.ndarray
) -> int | np.ndarray:
    """Steps in one cycle of the chamber's staircase (lib/Program): warming
    from start to max (max included even off the step grid), then cooling
    back through the same setpoints. For settings SETPRG accepts, computed as
    the firmware's warmingStepCount computes it, in float32 (the AVR's float,
    which SETPRG's fields are parsed into). Numbers give an int; numpy arrays,
    elementwise."""
    span = np.float32(max_c) - np.float32(start_c)
    # A span within 1e-4 of a step above a multiple gets no near-duplicate top step.
    intervals = np.ceil(span / np.float32(step_c) - np.float32(1e-4))
    warming = intervals.astype(np.int64) + 1
    steps = 2 * warming - 1
    return int(steps) if np.ndim(steps) == 0 else steps


def _constant(value: float) -> Callable[[float], float]:
    return lambda _t: value


def chamber_program(start_c: float, max_c: float, options: ScenarioOptions, cycles: int) -> list[Command]:
    """SETPRG, and SETCTL when the controller is not the firmware's default."""
    commands = [
        Command(
            PROGRAM_SENT_S,
            "SETPRG",
            (start_c, max_c, PAPER_STEP_C, options.hold_s, options.rest_s, cycles, options.hold_start),
        )
    ]
    control = CONTROLLERS[options.controller]
    if control is not None:
        commands.append(Command(CONTROL_SENT_S, "SETCTL", control))
    return commands


def reach_allowance_s(start_c: float, steps: int, ambient_c: float, options: ScenarioOptions) -> float:
    """Time a program's waiting steps add to its holds in the twin's default
    chamber: the first step's run from ambient to within the reached band,
    and each later 2 degC step's approach."""
    if options.hold_start == "T":
        return 0.0
    first = max(0.0, abs(ambient_c - start_c) - REACHED_BAND_C) * REACH_S_PER_C_FROM_AMBIENT
    if options.hold_start == "F":
        return first
    return first + (steps - 1) * REACH_S_PER_STEP


def fig8(options: ScenarioOptions) -> Scenario:
    """Figure 8: four warming steps, 16 to 22 degC, one minute each."""
    steps = 4
    ambient = FIG8_AMBIENT_C if options.ambient_c is None else options.ambient_c
    duration = PROGRAM_STARTED_S + steps * options.hold_s + reach_allowance_s(16.0, steps, ambient, options)
    return Scenario(
        name="fig8",
        description="Figure 8: warming steps 16-18-20-22 degC",
        duration_s=duration,
        uses_chamber=True,
        ambient_c=_constant(ambient),
        positions=(TablePosition(0.0, "table", options.incl_x_deg, options.incl_y_deg),),
        commands=(
            *chamber_program(16.0, 16.0 + PAPER_STEP_C * (steps - 1), options, 1),
            Command(PROGRAM_STARTED_S, "START"),
        ),
        marks={"program_start_s": PROGRAM_STARTED_S},
        paper_figures=figures.figure8_lines,
    )


def _cycle_length_s(options: ScenarioOptions, ambient_c: float) -> float:
    steps = program_steps(CALIBRATION_MIN_C, CALIBRATION_MAX_C, PAPER_STEP_C)
    return (
        PROGRAM_STARTED_S
        + steps * options.hold_s
        + options.rest_s
        + reach_allowance_s(CALIBRATION_MIN_C, steps, ambient_c, options)
    )


def cycle(options: ScenarioOptions) -> Scenario:
    """One -10 -> 45 -> -10 degC staircase, then the rest with the Peltier
    off, at one inclination."""
    ambient = LAB_AMBIENT_C if options.ambient_c is None else options.ambient_c
    return Scenario(
        name="cycle",
        description="one calibration cycle -10..45..-10 degC and rest",
        duration_s=_cycle_length_s(options, ambient),
        uses_chamber=True,
        ambient_c=_constant(ambient),
        positions=(
            TablePosition(0.0, _label(options.incl_x_deg, options.incl_y_deg), options.incl_x_deg, options.incl_y_deg),
        ),
        commands=(
            *chamber_program(CALIBRATION_MIN_C, CALIBRATION_MAX_C, options, 1),
            Command(PROGRAM_STARTED_S, "START"),
        ),
        marks={"program_start_s": PROGRAM_STARTED_S},
        ends_with_program=True,
        paper_figures=figures.drift_lines,
    )


def _label(incl_x_deg: float, incl_y_deg: float) -> str:
    if incl_x_deg == 0 and incl_y_deg == 0:
        return "0"
    if incl_y_deg == 0:
        return f"X{incl_x_deg:+g}"
    if incl_x_deg == 0:
        return f"Y{incl_y_deg:+g}"
    return f"X{incl_x_deg:+g}Y{incl_y_deg:+g}"


def campaign_positions() -> tuple[tuple[str, float, float], ...]:
    """The paper's 37 positions as (label, incl_x_deg, incl_y_deg)."""
    positions = [("0", 0.0, 0.0)]
    for axis in ("X", "Y"):
        for sign in (1, -1):
            for angle in CAMPAIGN_ANGLES_DEG:
                degrees = float(sign * angle)
                x, y = (degrees, 0.0) if axis == "X" else (0.0, degrees)
                positions.append((_label(x, y), x, y))
    return tuple(positions)


def campaign(options: ScenarioOptions) -> Scenario:
    """Section 3.2: every position through a full cycle, one after another."""
    known = {label: (x, y) for label, x, y in campaign_positions()}
    labels = options.positions or tuple(known)
    unknown = [label for label in labels if label not in known]
    if unknown:
        raise ScenarioError(f"unknown position(s) {', '.join(unknown)}; use labels like 0, X+5, X-45, Y+30")
    ambient = LAB_AMBIENT_C if options.ambient_c is None else options.ambient_c
    length = _cycle_length_s(options, ambient)
    positions, commands = [], []
    for index, label in enumerate(labels):
        begin = index * length
        x, y = known[label]
        positions.append(TablePosition(begin, label, x, y))
        # The table has just moved: the IMU's filters start again from the new angle.
        commands.append(Command(begin, "RESEED", board="imu_reader"))
        if index == 0:
            commands += chamber_program(CALIBRATION_MIN_C, CALIBRATION_MAX_C, options, 1)
        commands.append(Command(begin + PROGRAM_STARTED_S, "START"))
    return Scenario(
        name="campaign",
        description=f"calibration campaign, {len(labels)} tilt positions",
        duration_s=len(labels) * length,
        uses_chamber=True,
        ambient_c=_constant(ambient),
        positions=tuple(positions),
        commands=tuple(commands),
        marks={f"position_{p.label}_s": p.at_s for p in positions},
    )


def _ramp(begin_c: float, end_c: float, duration_s: float) -> Callable[[float], float]:
    """A straight line from begin to end over the run: the paper's "before"
    RMS figures (section 4.3) fit it, a raised cosine or a Newtonian fall do
    not (docs/physics-model.md, "Field tests")."""

    def ambient(t: float) -> float:
        fraction = min(max(t / duration_s, 0.0), 1.0)
        return begin_c + (end_c - begin_c) * fraction

    return ambient


def _field(
    name: str,
    description: str,
    paper_duration_s: float,
    options: ScenarioOptions,
    profile: Callable[[float], Callable[[float], float]],
) -> Scenario:
    duration = options.duration_s or paper_duration_s
    if duration != paper_duration_s:
        description += f", compressed into {duration:g} s"
    return Scenario(
        name=name,
        description=description,
        duration_s=duration,
        uses_chamber=False,
        ambient_c=profile(duration),
        positions=(
            TablePosition(0.0, _label(options.incl_x_deg, options.incl_y_deg), options.incl_x_deg, options.incl_y_deg),
        ),
    )


def _field_air_c(imu_reading_c: float) -> float:
    """The air temperature at which the twin's sensor reads imu_reading_c:
    section 4.3 states the field tests' temperatures as the LSM9DS0 read them,
    and the default model's die reads FIELD_SENSOR_OFFSET_C off."""
    return imu_reading_c - FIELD_SENSOR_OFFSET_C


def field_warming(options: ScenarioOptions) -> Scenario:
    """Section 4.3, first test: 3 h in a black box outdoors, the IMU reading
    9 to 48 degC, rising at a steady 13 degC/h (Figure 16a, b)."""
    return _field(
        "field-warming",
        "field test: 3 h, the IMU reading 9 -> 48 degC on a straight ramp",
        3 * 3600.0,
        options,
        lambda duration: _ramp(_field_air_c(9.0), _field_air_c(48.0), duration),
    )


def field_cooling(options: ScenarioOptions) -> Scenario:
    """Section 4.3, second test: 9 h overnight, the IMU reading 26 to 16 degC,
    falling at a steady 1.1 degC/h (Figure 16c, d). The record began at 8 pm
    of a July day, hours into the evening's fall, and the paper compensated
    all of it with the cooling set: the sensor starts in its cooling state."""
    scenario = _field(
        "field-cooling",
        "field test: 9 h, the IMU reading 26 -> 16 degC on a straight ramp",
        9 * 3600.0,
        options,
        lambda duration: _ramp(_field_air_c(26.0), _field_air_c(16.0), duration),
    )
    return replace(scenario, sensor_warming_share=0.0)


def field_alternating(options: ScenarioOptions) -> Scenario:
    """Figure 17: 12 h in which warming and cooling alternate, three
    swings of +-6 degC around 24 degC."""

    def profile(duration: float) -> Callable[[float], float]:
        period = duration / 3.0
        return lambda t: 24.0 + 6.0 * math.sin(2.0 * math.pi * t / period)

    return _field(
        "field-alternating", "field test: 12 h alternating warming and cooling", 12 * 3600.0, options, profile
    )


DEFAULT_FIELD_DAYS = 2.0
# The scenarios whose profile is drawn from ScenarioOptions.seed.
DRAWS_WEATHER = frozenset({"field-days"})


def field_days(options: ScenarioOptions) -> Scenario:
    """Days of weather at a site, from local midnight: the IMU in a closed
    box outdoors, its air following the days' diurnal swings, gusts, sun
    and clouds (twin/weather.py), drawn from options.seed."""
    days = DEFAULT_FIELD_DAYS if options.days is None else options.days
    if not 0.0 < days <= weather.MAX_DAYS:
        raise ScenarioError(f"--days must be more than 0 and at most {weather.MAX_DAYS:g}, got {days:g}")
    drawn = weather.draw_weather(days, options.seed)
    scenario = _field(
        "field-days",
        f"field days: {days:g} days of weather from midnight (seed {options.seed}), the IMU in a closed box outdoors",
        days * weather.SECONDS_PER_DAY,
        options,
        drawn.ambient_c,
    )
    seconds_per_day = scenario.duration_s / days
    return replace(scenario, paper_figures=lambda columns: weather.day_lines(columns, seconds_per_day))


# Long enough for a session at the pseudo-terminals; Ctrl-C ends it sooner.
IDLE_DURATION_S = 3600.0


def idle(options: ScenarioOptions) -> Scenario:
    """Both boards powered at a constant ambient, the table still, and no
    command sent: for --pty, where a user or a test drives the boards."""
    ambient = LAB_AMBIENT_C if options.ambient_c is None else options.ambient_c
    return Scenario(
        name="idle",
        description="both boards idle at a constant ambient, no host commands",
        duration_s=options.duration_s or IDLE_DURATION_S,
        uses_chamber=True,
        ambient_c=_constant(ambient),
        positions=(
            TablePosition(0.0, _label(options.incl_x_deg, options.incl_y_deg), options.incl_x_deg, options.incl_y_deg),
        ),
    )


SCENARIOS: dict[str, Callable[[ScenarioOptions], Scenario]] = {
    "fig8": fig8,
    "cycle": cycle,
    "campaign": campaign,
    "field-warming": field_warming,
    "field-cooling": field_cooling,
    "field-alternating": field_alternating,
    "field-days": field_days,
    "idle": idle,
}


def build(name: str, options: ScenarioOptions) -> Scenario:
    if name not in SCENARIOS:
        raise ScenarioError(f"unknown scenario {name!r}; choose from {', '.join(SCENARIOS)}")
    if options.hold_s < 1 or options.rest_s < 0:
        raise ScenarioError("--hold-seconds must be at least 1 and --rest-seconds not negative")
    if options.hold_start not in HOLD_STARTS:
        raise ScenarioError(f"hold start {options.hold_start!r} is not one of {', '.join(HOLD_STARTS)}")
    if options.controller not in CONTROLLERS:
        raise ScenarioError(f"unknown controller {options.controller!r}; choose from {', '.join(CONTROLLERS)}")
    if options.duration_s is not None and options.duration_s <= 0:
        raise ScenarioError("--duration must be positive")
    if options.days is not None and name != "field-days":
        raise ScenarioError(f"--days is for field-days, not {name}")
    for angle in (options.incl_x_deg, options.incl_y_deg):
        if not -90.0 <= angle <= 90.0:
            raise ScenarioError(f"inclination {angle:g} deg is outside -90..90")
    return replace(SCENARIOS[name](options), options=options)
