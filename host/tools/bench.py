"""`make bench`: how fast the twin runs and where its time goes, how much
of each board's CPU the firmware uses, how much RAM each board has left,
and how many corrupted frames the line check lets through.

Speed, in simulated seconds per wall second: the IMU alone (field-warming,
10 simulated minutes), the chamber alone (its firmware coupled to the
chamber model, a cycle's program for 10 simulated minutes), both boards
coupled (Figure 8: the IMU reading its LSM9DS0 over I2C at 100 Hz, the
chamber controlling every 250 ms, both sending frames), and one campaign
position with 1 s holds, alone and carrying a batch of four sensors, from
which it estimates the paper's full campaign for one sensor and for four,
and the floor of the four sensors' campaign: simavr executing the IMUs'
awake cycles alone; with the share of a coupled step's wall time that goes to the physics
model, the ctypes binding, simavr, frame parsing and run.csv. Each board's
awake fraction (cycles the CPU executed against those it slept), and where
the IMU's awake cycles go (the twin's sampling profiler, grouped into
stages). Prints figures; asserts nothing: the targets (the IMU awake at
most 5 % of its cycles at 100 Hz and the default decimation, the coupled
twin at least 50x real time on one core, the 37-position campaign within
30 minutes on two cores, four sensors' within 45, at least 300 B of SRAM the stack never reaches,
at most one corrupted frame accepted per million at a 0.1 % byte error
rate) are for a person to compare. Other jobs on the machine slow the
speed figures down.

Each figure is printed as it is measured and, at the end, written with the
date, the machine and the command to docs/performance.md (overwritten;
`--page` names another file). Then each Nano test program's RAM goes into
docs/testing.md (host/tools/nano_ram.py).

`bench.py --memory` prints only each board's RAM: its static data and the
stack's high-water mark (a few seconds). `bench.py --live` prints only the
live view's figures (docs/live.md): a twin campaign's wall and processor
time with and without `--serve` and the page's first load (about 8 minutes).
`bench.py --discover` prints only `thermotilt discover`'s time end to end
on a 100 000-row run (docs/discovery.md; about a minute).

`bench.py --scatter [--seed N] [--disable TERM ...]` instead runs the long
check of the scatter the twin's sensor leaves to the paper's fit (about
40 minutes on one core; docs/physics-model.md, "Scatter the surfaces
leave"): a campaign subset through the twin and `thermotilt fit`'s RMS
errors beside Tables 2-3, and both field tests' RMS about the 25 degC
reading before and after the firmware's compensation beside section 4.3.
It prints only; host/tests/test_scatter.py holds the same figures, with the
filter emulated, to the paper's.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import os
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import generated_page
import nano_ram
import numpy as np

from thermotilt.build_tree import build_dir
from thermotilt.calibration.dataset import Campaign, SetData, load
from thermotilt.calibration.families import compare_families
from thermotilt.calibration.fit import fit_surface
from thermotilt.calibration.paper import FIELD_RMS_LSB, TABLES
from thermotilt.calibration.validate import validate
from thermotilt.physics import Chamber, Model, Sensor
from thermotilt.program import CALIBRATION_MAX_C, CALIBRATION_MIN_C, PAPER_HOLD_S, PAPER_STEP_C
from thermotilt.run.folder import LOG_FILE
from thermotilt.run.log import RunLogWriter
from thermotilt.run.summary import BoardReport
from thermotilt.surfaces import PAPER_DEFAULTS
from thermotilt.twin import simulate
from thermotilt.twin.boards import (
    DEFAULT_FREQUENCY_HZ,
    Board,
    FirmwareSymbols,
    firmware_elf,
    is_runtime_routine,
)
from thermotilt.twin.scenarios import ScenarioOptions, build, campaign_positions
from thermotilt.wire.protocol import build_frame

COUPLED_TARGET_X_REAL_TIME = 50.0
CAMPAIGN_TARGET_MINUTES = 30.0
# A batch on one tilt table: four sensors' 37 positions in at most 45 min.
BATCH_SENSORS = 4
BATCH_TARGET_MINUTES = 45.0
# As `campaign --jobs` defaults: one position per core of this machine.
CORES = os.cpu_count() or 1
IMU_AWAKE_TARGET = 0.05
# A still sensor at 25 degC: ax, ay, az in LSB, OUT_TEMP_XM raw.
STEADY_SENSOR = (-1700, -400, 16000, 32)


class Figures:
    """Every figure the bench measures, printed as it comes and kept as a
    (figure, value, note) row of docs/performance.md: a new figure is one
    more `add`."""

    def __init__(self) -> None:
        self.rows: list[tuple[str, str, str]] = []

    def add(self, figure: str, value: str, note: str = "") -> None:
        print(f"{figure}: {value}" + (f" ({note})" if note else ""), flush=True)
        self.rows.append((figure, value, note))


PAGE = generated_page.DOCS / "performance.md"


def write_page(path: Path, rows: list[tuple[str, str, str]], started: datetime.datetime, load_at_start: str) -> None:
    generated_page.write(
        path,
        [
            "# Performance",
            "",
            "How fast the digital twin runs, how much of each board's CPU and RAM the firmware uses, how "
            "long the fits take and how many corrupted frames the line check lets through. What each figure "
            "measures and its target are in `host/tools/bench.py`; the targets are for a person to compare, "
            "the bench asserts nothing.",
            "",
            *generated_page.stamp("make bench", started, load_at_start),
            "",
            *generated_page.table(("figure", "value", "note"), rows),
        ],
    )


def physics_step_us(model: Model, steps: int = 20000) -> tuple[float, float]:
    chamber = Chamber(model, 22.0)
    sensor = Sensor(model, 1, 22.0)
    begin = time.perf_counter()
    for step in range(steps):
        chamber.step(0.01, 0.5, 1 if step % 2000 < 1000 else -1, 22.0)
    middle = time.perf_counter()
    for _ in range(steps):
        sensor.step(0.01, chamber.inner_c, 30.0, 0.0)
    end = time.perf_counter()
    return (middle - begin) / steps * 1e6, (end - middle) / steps * 1e6


def speed_line(figures: Figures, label: str, simulated_s: float, wall_s: float, target: str = "") -> float:
    speed = simulated_s / wall_s
    figures.add(
        f"twin speed, {label}",
        f"{speed:.1f}x real time",
        f"{simulated_s:.0f} s simulated in {wall_s:.1f} s wall{target}",
    )
    return speed


def awake_line(figures: Figures, name: str, report: BoardReport, doing: str, target: str = "") -> None:
    awake, asleep = report.awake_cycles, report.sleep_cycles
    seconds = (awake + asleep) / DEFAULT_FREQUENCY_HZ
    figures.add(
        f"{name} CPU awake, {doing}",
        f"{100 * awake / (awake + asleep):.1f} % of cycles",
        f"{awake / seconds / 1e6:.2f} M cycles executed and {asleep / seconds / 1e6:.2f} M slept "
        f"a simulated second{target}",
    )


CHAMBER_ALONE_S = 600.0


def chamber_alone_seconds(model: Model) -> float:
    """The chamber's firmware coupled to the chamber model every 10 ms as
    `simulate` couples it, without the IMU (no scenario runs the chamber
    alone): a cycle's program for 10 simulated minutes. Returns the wall
    seconds it took."""
    scenario = build("cycle", ScenarioOptions())
    commands = [command for command in scenario.commands if command.board == simulate.CHAMBER]
    sequence = itertools.count(1)
    ambient = scenario.ambient_c(0.0)
    chamber = Chamber(model, ambient)
    with Board.thermal_chamber() as board:
        board.attach_l298n()
        begin = time.perf_counter()
        for step in range(round(CHAMBER_ALONE_S / simulate.STEP_S)):
            while commands and commands[0].at_s <= step * simulate.STEP_S:
                command = commands.pop(0)
                board.write_uart(build_frame(command.frame_type, next(sequence), command.values).encode())
            drive = board.read_l298n()
            chamber.step(simulate.STEP_S, drive.duty, drive.direction, ambient)
            for channel, millivolts in zip(
                (simulate.INNER_THERMISTOR_CHANNEL, simulate.OUTER_THERMISTOR_CHANNEL), chamber.thermistor_millivolts()
            ):
                board.set_adc_millivolts(channel, millivolts)
            board.run_until((step + 1) * simulate.STEP_S)
            board.read_uart()
        return time.perf_counter() - begin


def run_until_call_seconds() -> float:
    """What a run_until that has nothing to simulate costs: the Python
    wrapper and the ctypes call, without simavr."""
    calls = 20000
    with Board.imu_reader() as board:
        board.run_until(0.01)
        now = board.seconds
        begin = time.perf_counter()
        for _ in range(calls):
            board.run_until(now)
        return (time.perf_counter() - begin) / calls


def step_breakdown(figures: Figures, timing: simulate.StepTiming, steps: int, boards: int) -> None:
    """Where a coupled step's wall time goes. The run_until calls' own
    binding cost (measured on calls with nothing to simulate) moves from
    simavr to the binding; frames still holds its two ctypes reads a board."""
    seconds = timing.seconds
    binding_in_run = steps * boards * run_until_call_seconds()
    simavr = seconds["boards"] - binding_in_run
    shares = {
        "physics model": seconds["physics"],
        "simavr (both boards, with the twin's C device models)": simavr,
        "binding (ctypes calls and their Python wrappers)": seconds["board_io"] + binding_in_run,
        "frames (read, saved, parsed)": seconds["frames"],
        "run.csv rows": seconds["csv"],
        "other (schedule, loop)": seconds["other"],
    }
    total = sum(seconds.values())
    figures.add(
        "coupled step (fig8, 10 ms simulated), wall time",
        f"{total / steps * 1e6:.0f} us",
        ", ".join(f"{label} {100 * part / total:.0f} %" for label, part in shares.items()),
    )
    figures.add(
        "coupled step, Python against simavr",
        f"Python {100 * (total - simavr) / total:.0f} %, simavr {100 * simavr / total:.0f} %",
    )


def speed_and_awake(figures: Figures, model: Model) -> None:
    with tempfile.TemporaryDirectory() as scratch:
        imu_timing = simulate.StepTiming()
        imu = simulate.run(
            build("field-warming", ScenarioOptions(duration_s=600)), model, Path(scratch) / "field", timing=imu_timing
        ).summary
        speed_line(figures, "IMU alone, field-warming (10 min)", imu.sim_seconds, imu.wall_seconds)
        speed_line(figures, "chamber alone, a cycle's program (10 min)", CHAMBER_ALONE_S, chamber_alone_seconds(model))
        # Timed, its laps add about 1.5 us to a step of 150-250.
        timing = simulate.StepTiming()
        fig8 = simulate.run(build("fig8", ScenarioOptions()), model, Path(scratch) / "fig8", timing=timing).summary
        speed_line(
            figures,
            "both boards coupled, fig8",
            fig8.sim_seconds,
            fig8.wall_seconds,
            f"; target >= {COUPLED_TARGET_X_REAL_TIME:.0f}x on one core",
        )
        step_breakdown(figures, timing, round(fig8.sim_seconds / simulate.STEP_S), len(fig8.boards))
        position_scenario = build("campaign", ScenarioOptions(hold_s=1, positions=("0",)))
        position = simulate.run(position_scenario, model, Path(scratch) / "campaign").summary
        batch = model.with_population(BATCH_SENSORS, seed=1)
        imus = [
            simulate.ImuRun(batch.for_sensor(sensor_id), Path(scratch) / "batch" / sensor_id, seed=1)
            for sensor_id in batch.sensor_ids
        ]
        batch_position = simulate.run_sensors(position_scenario, batch, imus)[0].summary
    speed = speed_line(
        figures,
        "one campaign position, 1 s holds (simulate campaign --positions 0 --hold-seconds 1)",
        position.sim_seconds,
        position.wall_seconds,
    )
    # `thermotilt campaign --twin` runs each position as a cycle with 60 s holds, ending with its program.
    position_s = build("cycle", ScenarioOptions()).duration_s
    minutes = CAMPAIGN_POSITIONS * position_s / speed / CORES / 60
    figures.add(
        f"the paper's campaign in the twin ({CAMPAIGN_POSITIONS} positions, 60 s holds), estimated",
        f"{minutes:.0f} min",
        f"each position at most {position_s:.0f} s simulated, at the campaign position's speed, "
        f"{CORES} at a time; estimated, not run; target <= {CAMPAIGN_TARGET_MINUTES:.0f} min on a "
        f"2-core machine",
    )
    batch_speed = speed_line(
        figures,
        f"one campaign position carrying {BATCH_SENSORS} sensors, 1 s holds (one chamber run, "
        f"{BATCH_SENSORS} IMU boards)",
        batch_position.sim_seconds,
        batch_position.wall_seconds,
    )
    batch_minutes = CAMPAIGN_POSITIONS * position_s / batch_speed / CORES / 60
    figures.add(
        f"a batch campaign in the twin ({BATCH_SENSORS} sensors, {CAMPAIGN_POSITIONS} positions, 60 s holds), "
        "estimated",
        f"{batch_minutes:.0f} min, {batch_minutes / BATCH_SENSORS:.0f} min a sensor",
        f"at the batch position's speed, {CORES} positions at a time; {BATCH_SENSORS} separate campaigns: "
        f"{BATCH_SENSORS * minutes:.0f} min; estimated, not run; target <= {BATCH_TARGET_MINUTES:.0f} min on a "
        "2-core machine",
    )
    # What no change on the host side can beat: simavr executing every IMU's
    # awake cycles, at the rate it executes them in the IMU-alone run.
    imu_report = imu.boards[simulate.IMU]
    awake_per_s = imu_report.awake_cycles / imu.sim_seconds
    executed_per_s = imu_report.awake_cycles / imu_timing.seconds["boards"]
    floor_minutes = CAMPAIGN_POSITIONS * position_s * BATCH_SENSORS * awake_per_s / executed_per_s / CORES / 60
    figures.add(
        "simavr executing the imu_reader's awake cycles",
        f"{executed_per_s / 1e6:.0f} M cycles per wall second",
        f"the IMU-alone run's {imu_report.awake_cycles / 1e6:.0f} M awake cycles over the wall time of its "
        "run_until calls (sleep skipped, TWI and UART models included)",
    )
    figures.add(
        f"a batch campaign's floor ({BATCH_SENSORS} sensors, {CAMPAIGN_POSITIONS} positions, 60 s holds)",
        f"{floor_minutes:.0f} min",
        f"the IMUs' awake cycles alone ({awake_per_s / 1e6:.2f} M a simulated second each) at that rate, "
        f"{CORES} positions at a time: no chamber, no Python; the firmware's awake share is fixed",
    )
    awake_line(
        figures,
        "imu_reader",
        imu.boards[simulate.IMU],
        "100 Hz sampling, decimation 10, a 10 min field run from boot",
        f"; target <= {100 * IMU_AWAKE_TARGET:.0f} %",
    )
    awake_line(
        figures, "thermal_chamber", fig8.boards[simulate.CHAMBER], "running fig8's program (control every 250 ms)"
    )


# Where the IMU's awake cycles go, by the first function up a sample's stack
# that belongs to a stage. Vector numbers are the ATmega328P's.
IMU_STAGES = (
    ("I2C: the TWI master and its ISR, the LSM9DS0 reads", r"SleepingTwi::|Lsm9ds0Accel::|__vector_24$"),
    (
        "Kalman filters and compensation (lib/ImuProcessing)",
        r"ImuProcessing::|KalmanFilter::|surfaceCorrection|TrendDetector::",
    ),
    (
        "frame formatting and printing: FrameWriter, float to text, CRC",
        r"FrameWriter::|SerialLink::|dtostr|dtoa_prf|crc16Xmodem",
    ),
    ("UART: Uart0 and its ISRs", r"Uart0::|__vector_1[89]$"),
    ("clock tick: Clock's Timer1 compare ISR", r"__vector_11$"),
)
# Reading the clock is charged to whoever reads it (the TWI master reads it for its timeout).
CLOCK_READS = ("Clock::nowMs", "Clock::tickMs")
OTHER_STAGE = "other: loop and main, with what LTO inlined into them, and the rest"
# After the Kalman filters' gain has settled (about 5500 samples after the
# sensor connects; lib/Kalman), as it is for nearly all of a long run.
PROFILE_START_S = 60.0
PROFILE_SECONDS = 10.0


def without_parameters(name: str) -> str:
    """A demangled name without its parameter list: the parentheses that close it."""
    if not name.endswith(")"):
        return name
    depth = 0
    for index in range(len(name) - 1, -1, -1):
        depth += {")": 1, "(": -1}.get(name[index], 0)
        if depth == 0:
            return name[:index]
    return name


def imu_stage(names: tuple[str, ...]) -> str:
    for name in names:
        if is_runtime_routine(name) or name in CLOCK_READS:
            continue
        for stage, pattern in IMU_STAGES:
            if re.match(pattern, name):
                return stage
    return OTHER_STAGE


def imu_profile(figures: Figures, model: Model) -> None:
    """The twin's sampling profiler on the IMU streaming at 100 Hz with the
    default decimation, its sensor level and noisy, grouped into stages."""
    # Each 10 ms sample gets fresh noise of the model's `noise` term, as a real
    # sensor gives: a constant input makes the filters' arithmetic cheaper
    # than it ever is (soft float's shortcuts for zero).
    noise = np.random.default_rng(1)
    sigma_lsb = list(model.terms["noise"]["sigma_lsb"].values())
    *steady_axes, temperature_raw = STEADY_SENSOR

    def sample_until(board: Board, seconds: float) -> None:
        for step in range(round(board.seconds / simulate.STEP_S), round(seconds / simulate.STEP_S)):
            axes = np.add(steady_axes, noise.normal(0.0, sigma_lsb)).round().astype(int)
            board.set_lsm9ds0(*axes.tolist(), temperature_raw)
            board.run_until((step + 1) * simulate.STEP_S)

    with Board.imu_reader() as board:
        board.attach_lsm9ds0()
        sample_until(board, PROFILE_START_S)
        awake_before, asleep_before = board.cycle_counts()
        board.start_profile()
        sample_until(board, PROFILE_START_S + PROFILE_SECONDS)
        profile = board.profile()
        awake, asleep = board.cycle_counts()
        awake, asleep = awake - awake_before, asleep - asleep_before
        symbols = FirmwareSymbols(board.elf)
    stacks = profile.stacks(symbols)
    stages = Counter()
    for names, samples in stacks.items():
        stages[imu_stage(names)] += samples
    kept = len(profile.samples)
    window = f"{PROFILE_START_S:.0f}..{PROFILE_START_S + PROFILE_SECONDS:.0f} s"
    figures.add(
        "imu_reader CPU awake, once the Kalman gain has settled",
        f"{100 * awake / (awake + asleep):.1f} % of cycles",
        f"{window}, sensor level with the model's noise, profiler on; target <= {100 * IMU_AWAKE_TARGET:.0f} %",
    )
    sampling = f"{kept} profiler samples over {window}, one every {profile.period_cycles} awake cycles"
    for stage, samples in stages.most_common():
        figures.add(f"imu_reader awake cycles: {stage}", f"{100 * samples / kept:.1f} %", sampling)
    figures.add(
        "imu_reader awake cycles: top functions",
        ", ".join(
            f"{without_parameters(name)} {100 * samples / kept:.1f} %"
            for name, samples in profile.by_function(symbols).most_common(6)
        ),
        "the profiler sees functions, not source lines: code LTO inlined counts as its caller's, e.g. "
        "the Kalman filters as ImuProcessing::update's and the sample path as loop's; soft float and "
        "division routines count as their caller's, and in the stages so do Clock's reads",
    )


STACK_HEADROOM_TARGET_B = 300
STATIC_SECTIONS = (".data", ".bss", ".noinit")


def static_ram(name: str) -> int:
    """Bytes of SRAM the image takes before the stack: .data, .bss and .noinit (avr-size)."""
    sizes = subprocess.run(
        ["avr-size", "-A", str(firmware_elf(name))], check=True, capture_output=True, text=True
    ).stdout
    return sum(
        int(fields[1]) for fields in map(str.split, sizes.splitlines()) if fields and fields[0] in STATIC_SECTIONS
    )


# One command at a time, as a host waits for each answer: sent back to back,
# they overrun the board's 64-byte receive buffer while it answers the first.
# SAVECOE's EEPROM writes take the longest, about 0.6 s on the chip.
COMMAND_GAP_S = 0.6
IMU_COMMANDS = [
    ("GETCOE", ["W", "X"]),
    ("STATUS", []),
    ("SETCOE", ["W", "X", 571.5, -20.23, 1.569e-3, -0.1044, -6.936e-5, 6.327e-9]),
    ("RESEED", []),
    ("SAVECOE", []),
    ("SETID", ["NODE-07"]),
    ("RESET", []),
]
CHAMBER_COMMANDS = [("SETPRG", [20, 30, 2, 60, 1200, 1, "A"]), ("START", []), ("STATUS", [])]


def send_commands(board: Board, commands: list[tuple[str, list]]) -> None:
    for seq, (command, fields) in enumerate(commands, start=1):
        board.write_uart(build_frame(command, seq, fields).encode())
        board.run_until(board.seconds + COMMAND_GAP_S)


def stack_use() -> list[tuple[str, int, int]]:
    """Each board's stack high-water mark (painted SRAM, sim/board.c) after
    10 s of streaming and controlling, with the commands a host sends; the
    IMU's end with an upload's SAVECOE, SETID (which decodes and checks the
    stored block inside a command, its deepest path) and RESET, so that it
    also boots from a stored block."""
    imu = Board.imu_reader()
    imu.attach_lsm9ds0()
    imu.set_lsm9ds0(*STEADY_SENSOR)
    imu.run_until(1.0)
    send_commands(imu, IMU_COMMANDS)
    imu.run_until(10.0)
    chamber = Board.thermal_chamber()
    chamber.attach_l298n()
    for channel in (0, 1):
        chamber.set_adc_millivolts(channel, 2500.0)
    chamber.run_until(1.0)
    send_commands(chamber, CHAMBER_COMMANDS)
    chamber.run_until(10.0)
    use = [(name, *board.stack_headroom()) for name, board in (("imu_reader", imu), ("thermal_chamber", chamber))]
    for board in (imu, chamber):
        board.close()
    return use


FIT_POINTS = 500_000


def fit_seconds() -> float:
    """One set and axis of `thermotilt fit` (OLS, HAC bounds, statistics) on
    synthetic rows: 10 positions through -10..45 degC with noise."""
    rng = np.random.default_rng(1)
    per_position = FIT_POINTS // 10
    temperature = np.tile(np.linspace(-10.0, 45.0, per_position), 10)
    acceleration = np.repeat(np.linspace(-11592.0, 11592.0, 10), per_position)
    residual = -20.0 * (temperature - 25.0) + 1e-4 * (temperature - 25.0) * acceleration
    residual += rng.standard_normal(FIT_POINTS)
    data = SetData(temperature, {"X": acceleration}, {"X": residual}, np.repeat(np.arange(10), per_position))
    begin = time.perf_counter()
    fit_surface(data, "W", "X")
    return time.perf_counter() - begin


# `fit --compare-families` of a whole campaign may cost this many times what
# pandas takes to parse its logs, plus this much for imports and figures.
FIT_PARSE_FACTOR = 5.0
FIT_FIXED_S = 6.0
FIT_TARGET_S = 30.0

# The paper's campaign: 37 positions, 57 one-minute holds at 10 Hz, half of them per set.
CAMPAIGN_POSITIONS = 37
ROWS_PER_POSITION_AND_SET = 57 * 60 * 10 // 2


def families_seconds() -> tuple[float, int]:
    """`fit --compare-families` on synthetic rows the size of the paper's
    full campaign: four families, both sets and axes, leave-one-position-out."""
    rng = np.random.default_rng(2)
    rows = ROWS_PER_POSITION_AND_SET
    temperature = np.tile(np.linspace(-10.0, 45.0, rows), CAMPAIGN_POSITIONS)
    angles = np.radians(np.linspace(-45.0, 45.0, CAMPAIGN_POSITIONS))
    acceleration = np.repeat(16393.0 * np.sin(angles), rows)
    residual = -20.0 * (temperature - 25.0) + rng.standard_normal(temperature.size)
    data = SetData(
        temperature,
        {"X": acceleration, "Y": acceleration},
        {"X": residual, "Y": residual},
        np.repeat(np.arange(CAMPAIGN_POSITIONS), rows),
        rng.normal(0.0, 0.01, temperature.size),
    )
    campaign = Campaign(tuple(map(str, range(CAMPAIGN_POSITIONS))), {"W": data, "C": data}, 0)
    begin = time.perf_counter()
    compare_families(campaign, ("X", "Y"))
    return time.perf_counter() - begin, temperature.size


# The campaign subset of docs/calibration.md and docs/physics-model.md, fitted
# like `thermotilt fit --settle-seconds 5`.
SCATTER_POSITIONS = ("0", "X+30", "X-30", "X+15", "X-15", "Y+30", "Y-30")
SCATTER_OPTIONS = ScenarioOptions(hold_s=30, rest_s=60, positions=SCATTER_POSITIONS)
SCATTER_SETTLE_S = 5.0
# Section 4.3 compensated each field run with one column of Tables 2-3.
FIELD_SETS = {"field-warming": "W", "field-cooling": "C"}


def scatter(model: Model, seed: int) -> None:
    """What the twin's sensor leaves to the paper's fit (Tables 2-3) and
    field check (section 4.3)."""
    off = [name for name in model.terms if not model.enabled(name)]
    print(f"scatter, seed {seed}, terms off: {', '.join(off) or 'none'}")
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "campaign"
        summary = simulate.run(build("campaign", SCATTER_OPTIONS), model, out, seed=seed).summary
        campaign = load(out, settle_s=SCATTER_SETTLE_S)
        print(
            f"campaign {','.join(SCATTER_POSITIONS)}, {SCATTER_OPTIONS.hold_s} s holds: "
            f"{summary.sim_seconds:.0f} s simulated in {summary.wall_seconds:.0f} s"
        )
        for axis in ("X", "Y"):
            for set_name in ("W", "C"):
                fit = fit_surface(campaign.sets[set_name], set_name, axis)
                paper = TABLES[(axis, set_name)].rmse
                print(
                    f"  {axis} {set_name}: RMSE {fit.rmse:5.2f} LSB, Tables 2-3 {paper:5.2f} "
                    f"(x {fit.rmse / paper:.2f}), {fit.points} points"
                )
        for name, set_name in FIELD_SETS.items():
            out = Path(scratch) / name
            summary = simulate.run(build(name, ScenarioOptions()), model, out, seed=seed).summary
            validation = validate(out)
            low, high = validation.temperature_range_c
            print(
                f"{name}: the IMU read {low:.2f}..{high:.2f} degC; "
                f"{summary.sim_seconds:.0f} s simulated in {summary.wall_seconds:.0f} s"
            )
            for axis in ("X", "Y"):
                result = validation.result(set_name, axis)
                before, after = FIELD_RMS_LSB[(name, axis)]
                print(
                    f"  {axis}: RMS before {result.rms_before_lsb:6.1f} (paper {before:3.0f}), "
                    f"after {result.rms_after_lsb:5.2f} (paper {after:2.0f}) LSB"
                )


def memory(figures: Figures) -> None:
    for name, untouched, capacity in stack_use():
        figures.add(
            f"{name} RAM",
            f"static {static_ram(name)} B, stack peak {capacity - untouched} B, untouched {untouched} B",
            f"target: untouched >= {STACK_HEADROOM_TARGET_B} B",
        )


def integrity(figures: Figures) -> None:
    """build/native/integrity_bench's figures: frames shaped like IMU, CHS,
    SETPRG and SETCOE through the twin's corruption code into the
    firmware's parser (docs/protocol.md, "Why a CRC")."""
    output = subprocess.run(
        [str(build_dir() / "native" / "integrity_bench")], check=True, capture_output=True, text=True
    ).stdout
    for line in output.splitlines():
        rate = re.match(r"\s*byte error rate ([0-9.]+): (.*)", line)
        if rate:
            figures.add(
                f"corrupted frames accepted at {100 * float(rate[1]):g} % byte errors",
                rate[2],
                "target: at most 1 per million at 0.1 %",
            )


# The live view's figure: a twin campaign of about 40 s (two positions of
# 30 s holds timed from each step's start, one at a time), its median wall
# time of LIVE_REPEATS with and without --serve, the two kinds taken in
# turn, and the processor time of the campaign and its children (the server
# among them), which a busy machine does not blur.
LIVE_CAMPAIGN = ["--positions", "0,X+15", "--hold-seconds", "30", "--rest-seconds", "0", "--hold-start", "T"]
LIVE_REPEATS = 5
LIVE_STATIC = ("app.js", "app.css", "uPlot.iife.min.js", "uPlot.min.css")


def _live_campaign_seconds(out: Path, serve: bool) -> tuple[float, float]:
    """One campaign's wall time and processor time; served, with a page's
    event stream open from the live view's first line to the campaign's end."""
    import resource
    import urllib.request

    def children_cpu_s() -> float:
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        return usage.ru_utime + usage.ru_stime

    command = [sys.executable, "-m", "thermotilt", "campaign", "--twin", "--out", str(out), "--jobs", "1"]
    command += [*LIVE_CAMPAIGN, "--registry", "off", "--force", *(["--serve", "127.0.0.1:0"] if serve else [])]
    begin, cpu_begin = time.perf_counter(), children_cpu_s()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    if serve:
        url = process.stdout.readline().split()[2]

        def read_events() -> None:
            try:
                with urllib.request.urlopen(f"{url}api/events", timeout=60) as stream:
                    for _line in stream:
                        pass
            except OSError:
                pass  # the server stops with the campaign

        threading.Thread(target=read_events, daemon=True).start()
    process.communicate()
    return time.perf_counter() - begin, children_cpu_s() - cpu_begin


def _first_load_seconds(folder: Path) -> tuple[float, int]:
    """`thermotilt watch folder`'s page as a browser first loads it: GET /,
    the static files and the first /api/state, one after another; the
    seconds and the bytes."""
    import urllib.request

    process = subprocess.Popen(
        [sys.executable, "-m", "thermotilt", "watch", str(folder), "--serve", "127.0.0.1:0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        url = next(word for word in process.stdout.readline().split() if word.startswith("http://"))
        begin = time.perf_counter()
        size = 0
        for path in ("", *(f"static/{name}" for name in LIVE_STATIC), "api/state"):
            with urllib.request.urlopen(url + path, timeout=30) as answer:
                size += len(answer.read())
        return time.perf_counter() - begin, size
    finally:
        process.terminate()
        process.wait(timeout=30)


def live_view(figures: Figures) -> None:
    """What serving the live view costs a twin campaign, and the page's first load."""
    with tempfile.TemporaryDirectory(prefix="thermotilt-bench-") as scratch:
        out = Path(scratch) / "campaign"
        plain, served = [], []
        for _ in range(LIVE_REPEATS):
            plain.append(_live_campaign_seconds(out, serve=False))
            served.append(_live_campaign_seconds(out, serve=True))
        plain_s, served_s = (statistics.median(wall for wall, _ in runs) for runs in (plain, served))
        plain_cpu, served_cpu = (statistics.median(cpu for _, cpu in runs) for runs in (plain, served))
        figures.add(
            "twin campaign with the live view served (--serve, a page open)",
            f"{served_s:.2f} s against {plain_s:.2f} s without: x {served_s / plain_s:.2f}; "
            f"processor time {served_cpu:.2f} s against {plain_cpu:.2f} s: x {served_cpu / plain_cpu:.2f}",
            f"2 positions, 30 s holds timed from each step's start, --jobs 1, the server in its own process; "
            f"median of {LIVE_REPEATS} each, in turn; target <= x 1.05 in wall time",
        )
        loads = [_first_load_seconds(out) for _ in range(LIVE_REPEATS)]
        load_s, size = statistics.median(load for load, _ in loads), loads[0][1]
        figures.add(
            "live view's first load",
            f"{1000 * load_s:.0f} ms",
            f"GET /, {len(LIVE_STATIC)} static files and the first /api/state of that campaign ({size / 1e6:.1f} MB); "
            f"median of {LIVE_REPEATS}; target < 1 s",
        )


def write_campaign_logs(folder: Path, seed: int = 3) -> int:
    """A campaign of the paper's size as run logs in the twin's layout, one
    folder per position (section 3.2's 37): every position through the
    -10..45..-10 degC staircase in 2 degC steps held 60 s, logged at 10 Hz,
    the IMU's temperature lagging the face and its readings drifting by
    Tables 2-3's surfaces with autocorrelated noise. Returns the rows."""
    rng = np.random.default_rng(seed)
    warming = np.arange(CALIBRATION_MIN_C, CALIBRATION_MAX_C + PAPER_STEP_C / 2, PAPER_STEP_C)
    setpoints = np.concatenate([warming, warming[-2::-1]])
    hold_rows = PAPER_HOLD_S * 10
    setpoint = np.repeat(setpoints, hold_rows)
    rows = setpoint.size
    time_s = 120.0 + 0.1 * np.arange(rows)
    face = np.empty(rows)
    face[0] = setpoint[0]
    for row in range(1, rows):
        face[row] = face[row - 1] + (setpoint[row] - face[row - 1]) * 0.02
    temperature = face - 1.0
    phase = np.where(np.arange(rows) < warming.size * hold_rows, "W", "C")
    total = 0
    for label, incl_x, incl_y in campaign_positions():
        with open(_position_log(folder, label), "w", newline="", encoding="utf-8") as stream:
            writer = RunLogWriter(stream, with_truth=False, flush_each_row=False)
            readings = {}
            for axis, angle in (("X", incl_x), ("Y", incl_y)):
                level = 16393.0 * np.sin(np.radians(angle))
                noise = np.cumsum(rng.normal(0.0, 0.3, rows)) * 0.05
                drift = np.where(
                    phase == "W",
                    PAPER_DEFAULTS.surface("W", axis).evaluate(temperature, level),
                    PAPER_DEFAULTS.surface("C", axis).evaluate(temperature, level),
                )
                readings[axis] = level + drift + noise
            for row in range(rows):
                writer.write_row(
                    {
                        "time_s": f"{time_s[row]:.3f}",
                        "ambient_c": "22.000",
                        "setpoint_c": f"{setpoint[row]:.2f}",
                        "chamber_c": f"{face[row]:.2f}",
                        "phase": phase[row],
                        "imu_temp_c": f"{temperature[row]:.3f}",
                        "incl_x_deg": f"{incl_x:.2f}",
                        "incl_y_deg": f"{incl_y:.2f}",
                        "since_move_s": f"{time_s[row]:.2f}",
                        "ax_filt": f"{readings['X'][row]:.1f}",
                        "ay_filt": f"{readings['Y'][row]:.1f}",
                        "comp_set": phase[row],
                        "coef_source": "D",
                    }
                )
            total += writer.rows
    return total


def _position_log(folder: Path, label: str) -> Path:
    (folder / label).mkdir(parents=True, exist_ok=True)
    return folder / label / LOG_FILE


def fit_end_to_end(figures: Figures) -> None:
    """`thermotilt fit --compare-families` as a user runs it (a process of
    its own: imports, parsing, fits, figures) against parsing the same logs
    with pandas alone."""
    import pandas as pd

    with tempfile.TemporaryDirectory(prefix="thermotilt-bench-") as scratch:
        campaign = Path(scratch) / "campaign"
        rows = write_campaign_logs(campaign)
        begin = time.perf_counter()
        for log in sorted(campaign.glob(f"*/{LOG_FILE}")):
            pd.read_csv(log)
        parse_s = time.perf_counter() - begin
        begin = time.perf_counter()
        subprocess.run(
            [
                sys.executable,
                "-m",
                "thermotilt",
                "fit",
                str(campaign),
                "--out",
                str(Path(scratch) / "fit"),
                "--compare-families",
                # The fit alone: a scratch folder is nothing for the lab's registry.
                "--registry",
                "off",
            ],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        fit_s = time.perf_counter() - begin
    budget_s = FIT_PARSE_FACTOR * parse_s + FIT_FIXED_S
    figures.add(
        "fit --compare-families, 37 positions end to end",
        f"{fit_s:.1f} s",
        f"{rows} rows; pandas parses them in {parse_s:.2f} s; target <= {FIT_PARSE_FACTOR:g} x that "
        f"+ {FIT_FIXED_S:g} s = {budget_s:.1f} s, and < {FIT_TARGET_S:g} s",
    )


# discover end to end (its command: reading the run, the search, writing
# the report and the found model) on a run of at least DISCOVER_ROWS rows:
# the sensor's staircase of hide.staircase_inputs at 8 table positions, 60 s
# holds, the model's noise and nothing hidden.
DISCOVER_ROWS = 100_000
DISCOVER_POSITIONS = (
    (-45.0, 0.0),
    (-30.0, 0.0),
    (-15.0, 0.0),
    (15.0, 0.0),
    (30.0, 0.0),
    (45.0, 0.0),
    (0.0, 30.0),
    (0.0, -30.0),
)
DISCOVER_REPEATS = 3


def discover_end_to_end(figures: Figures) -> None:
    from thermotilt.discovery.hide import hide_effect, staircase_inputs
    from thermotilt.run.log import read_run_columns

    with tempfile.TemporaryDirectory(prefix="thermotilt-bench-") as scratch:
        base = Path(scratch)
        inputs = staircase_inputs(base / "inputs" / "run.csv", positions=DISCOVER_POSITIONS, hold_s=60.0)
        run = base / "run"
        hide_effect(inputs, run, "none", seed=1)
        rows = read_run_columns(str(run / LOG_FILE)).rows
        if rows < DISCOVER_ROWS:
            raise SystemExit(f"bench: the discover run has {rows} rows, fewer than {DISCOVER_ROWS}")
        times = []
        for _ in range(DISCOVER_REPEATS):
            begin = time.perf_counter()
            subprocess.run(
                [sys.executable, "-m", "thermotilt", "discover", str(run), "--out", str(base / "found")],
                check=True,
                stdout=subprocess.DEVNULL,
            )
            times.append(time.perf_counter() - begin)
    figures.add(
        "discover end to end",
        f"{statistics.median(times):.1f} s",
        f"{rows} rows (a staircase at {len(DISCOVER_POSITIONS)} positions, the model's noise, nothing hidden): "
        f"the command, from reading the run to writing the report; median of {DISCOVER_REPEATS}; target <= 10 s",
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scatter",
        action="store_true",
        help="the twin's scatter against Tables 2-3 and section 4.3 instead (about 40 min)",
    )
    parser.add_argument("--memory", action="store_true", help="only each board's static RAM and stack peak")
    parser.add_argument("--live", action="store_true", help="only the live view's cost to a campaign and first load")
    parser.add_argument("--discover", action="store_true", help="only discover's time end to end on 100 000 rows")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--disable", action="append", default=[], metavar="TERM")
    parser.add_argument("--page", type=Path, default=PAGE, help=f"the page to write (default {PAGE})")
    args = parser.parse_args()
    if args.scatter:
        scatter(Model.load().with_terms({name: False for name in args.disable}), args.seed)
        return
    figures = Figures()
    if args.memory:
        memory(figures)
        return
    if args.live:
        live_view(figures)
        return
    if args.discover:
        discover_end_to_end(figures)
        return
    started, load_at_start = generated_page.now(), generated_page.load_average()
    model = Model.load()
    chamber_us, sensor_us = physics_step_us(model)
    figures.add(
        "physics model step",
        f"chamber {chamber_us:.1f} us, sensor {sensor_us:.1f} us",
        "one of each per 10 ms simulated",
    )
    speed_and_awake(figures, model)
    imu_profile(figures, model)
    memory(figures)
    figures.add(
        "fit, one surface with statistics", f"{fit_seconds():.2f} s", f"{FIT_POINTS} synthetic points; target <= 1 s"
    )
    seconds, points = families_seconds()
    figures.add(
        "fit --compare-families",
        f"{seconds:.1f} s",
        f"4 families x 2 sets x 2 axes, leave-one-position-out over {CAMPAIGN_POSITIONS} positions, "
        f"{points} synthetic points per set, no run logs to parse; target <= 30 s",
    )
    fit_end_to_end(figures)
    discover_end_to_end(figures)
    live_view(figures)
    integrity(figures)
    write_page(args.page, figures.rows, started, load_at_start)
    nano_ram.write()


if __name__ == "__main__":
    main()
