"""`make bench`: how fast the twin runs, in simulated seconds per wall second,
how much RAM each board has left, and how many corrupted frames the line
check lets through.

Runs the Figure 8 scenario (both boards: the IMU reading its LSM9DS0 over
I2C at 100 Hz, the chamber controlling every 250 ms, both sending frames)
and a field scenario (the IMU alone), times the physics model's steps on
their own, measures each board's static RAM and stack high-water mark, and
runs build/native/integrity_bench (the twin's wire fault into the firmware's
frame parser). Prints figures; asserts nothing (the targets, 20x real time
on one core, at least 300 B of SRAM the stack never reaches, and at most one
corrupted frame accepted per million at a 0.1 % byte error rate, are for a
person to compare).

`bench.py --memory` prints only each board's RAM: its static data and the
stack's high-water mark (a few seconds).

`bench.py --scatter [--seed N] [--disable TERM ...]` instead runs issue 7's
long check of the sensor's scatter (about 40 minutes on one core): a
campaign subset through the twin and `thermotilt fit`'s RMS errors beside
Tables 2-3, and both field tests' RMS about the 25 degC reading before and
after the firmware's compensation beside section 4.3.
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from thermotilt import simulate
from thermotilt.calibration.dataset import Campaign, SetData, load
from thermotilt.calibration.families import compare_families
from thermotilt.calibration.fit import fit_surface
from thermotilt.calibration.paper import FIELD_RMS_LSB, TABLES
from thermotilt.calibration.validate import validate
from thermotilt.protocol import build_frame
from thermotilt.twin import Board, build_dir, firmware_elf
from thermotilt.physics import Chamber, Model, Sensor
from thermotilt.scenarios import ScenarioOptions, build

TARGET_X_REAL_TIME = 20.0


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


STACK_HEADROOM_TARGET_B = 300
STATIC_SECTIONS = (".data", ".bss", ".noinit")


def static_ram(name: str) -> int:
    """Bytes of SRAM the image takes before the stack: .data, .bss and .noinit (avr-size)."""
    sizes = subprocess.run(["avr-size", "-A", str(firmware_elf(name))], check=True, capture_output=True,
                           text=True).stdout
    return sum(int(fields[1]) for fields in map(str.split, sizes.splitlines())
               if fields and fields[0] in STATIC_SECTIONS)


# One command at a time, as a host waits for each answer: sent back to back,
# they overrun the board's 64-byte receive buffer while it answers the first.
# SAVECOE's EEPROM writes take the longest, about 0.5 s.
COMMAND_GAP_S = 0.6
IMU_COMMANDS = [("GETCOE", ["W", "X"]), ("STATUS", []),
                ("SETCOE", ["W", "X", 571.5, -20.23, 1.569e-3, -0.1044, -6.936e-5, 6.327e-9]),
                ("RESEED", []), ("SAVECOE", []), ("RESET", [])]
CHAMBER_COMMANDS = [("SETPRG", [20, 30, 2, 60, 1200, 1, "A"]), ("START", []), ("STATUS", [])]


def send_commands(board: Board, commands: list[tuple[str, list]]) -> None:
    for seq, (command, fields) in enumerate(commands, start=1):
        board.write_uart(build_frame(command, seq, fields).encode())
        board.run_until(board.seconds + COMMAND_GAP_S)


def stack_use() -> list[tuple[str, int, int]]:
    """Each board's stack high-water mark (painted SRAM, sim/board.c) after
    10 s of streaming and controlling, with the commands a host sends; the
    IMU's end with an upload's SAVECOE and RESET, so that it also boots from
    a stored block (decoding and checking it is its deepest path)."""
    imu = Board.imu_reader()
    imu.attach_lsm9ds0()
    imu.set_lsm9ds0(-1700, -400, 16000, 32)
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
    data = SetData(temperature, {"X": acceleration, "Y": acceleration}, {"X": residual, "Y": residual},
                   np.repeat(np.arange(CAMPAIGN_POSITIONS), rows), rng.normal(0.0, 0.01, temperature.size))
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
    """Issue 7: what the twin's sensor leaves to the paper's fit and field check."""
    off = [name for name in model.terms if not model.enabled(name)]
    print(f"scatter, seed {seed}, terms off: {', '.join(off) or 'none'}")
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "campaign"
        summary = simulate.run(build("campaign", SCATTER_OPTIONS), model, out, seed=seed).summary
        campaign = load(out, settle_s=SCATTER_SETTLE_S)
        print(f"campaign {','.join(SCATTER_POSITIONS)}, {SCATTER_OPTIONS.hold_s} s holds: "
              f"{summary['sim_seconds']:.0f} s simulated in {summary['wall_seconds']:.0f} s")
        for axis in ("X", "Y"):
            for set_name in ("W", "C"):
                fit = fit_surface(campaign.sets[set_name], set_name, axis)
                paper = TABLES[(axis, set_name)].rmse
                print(f"  {axis} {set_name}: RMSE {fit.rmse:5.2f} LSB, Tables 2-3 {paper:5.2f} "
                      f"(x {fit.rmse / paper:.2f}), {fit.points} points")
        for name, set_name in FIELD_SETS.items():
            out = Path(scratch) / name
            summary = simulate.run(build(name, ScenarioOptions()), model, out, seed=seed).summary
            validation = validate(out)
            low, high = validation.temperature_range_c
            print(f"{name}: the IMU read {low:.2f}..{high:.2f} degC; "
                  f"{summary['sim_seconds']:.0f} s simulated in {summary['wall_seconds']:.0f} s")
            for axis in ("X", "Y"):
                result = validation.result(set_name, axis)
                before, after = FIELD_RMS_LSB[(name, axis)]
                print(f"  {axis}: RMS before {result.rms_before_lsb:6.1f} (paper {before:3.0f}), "
                      f"after {result.rms_after_lsb:5.2f} (paper {after:2.0f}) LSB")


def memory() -> None:
    for name, untouched, capacity in stack_use():
        print(f"{name}: static RAM {static_ram(name)} B, stack peak {capacity - untouched} B, "
              f"untouched {untouched} B (target >= {STACK_HEADROOM_TARGET_B} B)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scatter", action="store_true", help="issue 7's long check instead")
    parser.add_argument("--memory", action="store_true", help="only each board's static RAM and stack peak")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--disable", action="append", default=[], metavar="TERM")
    args = parser.parse_args()
    if args.scatter:
        scatter(Model.load().with_terms({name: False for name in args.disable}), args.seed)
        return
    if args.memory:
        memory()
        return
    model = Model.load()
    chamber_us, sensor_us = physics_step_us(model)
    print(f"physics: chamber step {chamber_us:.1f} us, sensor step {sensor_us:.1f} us "
          f"(one of each per 10 ms simulated)")
    runs = [
        ("both boards, fig8", build("fig8", ScenarioOptions())),
        ("imu alone, field-warming (10 min)", build("field-warming", ScenarioOptions(duration_s=600))),
    ]
    with tempfile.TemporaryDirectory() as scratch:
        for label, scenario in runs:
            result = simulate.run(scenario, model, Path(scratch) / scenario.name)
            summary = result.summary
            speed = summary["speed_x_real_time"]
            verdict = "meets" if speed >= TARGET_X_REAL_TIME else "below"
            print(f"{label}: {summary['sim_seconds']:.0f} s simulated in "
                  f"{summary['wall_seconds']:.1f} s wall = {speed:.1f}x real time "
                  f"({verdict} the {TARGET_X_REAL_TIME:.0f}x target)")
    memory()
    print(f"fit: {fit_seconds():.2f} s for one surface with statistics over {FIT_POINTS} points "
          f"(target <= 1 s)")
    seconds, points = families_seconds()
    print(f"fit --compare-families: {seconds:.1f} s for 4 families x 2 sets x 2 axes, leave-one-position-out "
          f"over {CAMPAIGN_POSITIONS} positions, {points} points per set (target <= 30 s)")
    print(subprocess.run([str(build_dir() / "native" / "integrity_bench")], check=True,
                         capture_output=True, text=True).stdout, end="")
    print("integrity target: at most 1 corrupted frame accepted per million at 0.1 % byte errors")


if __name__ == "__main__":
    main()
