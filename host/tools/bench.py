"""`make bench`: how fast the twin runs, in simulated seconds per wall second,
and how many corrupted frames the line check lets through.

Runs the Figure 8 scenario (both boards: the IMU reading its LSM9DS0 over
I2C at 100 Hz, the chamber controlling every 250 ms, both sending frames)
and a field scenario (the IMU alone), times the physics model's steps on
their own, and runs build/native/integrity_bench (the twin's wire fault into
the firmware's frame parser). Prints figures; asserts nothing (the targets,
20x real time on one core and at most one corrupted frame accepted per
million at a 0.1 % byte error rate, are for a person to compare).

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
from thermotilt.twin import Board
from thermotilt.physics import Chamber, Model, Sensor
from thermotilt.scenarios import ScenarioOptions, build
from thermotilt.twin import build_dir

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


def stack_use() -> list[tuple[str, int, int]]:
    """Each board's stack high-water mark (painted SRAM, sim/board.c) after
    10 s of streaming and controlling, with the commands a host sends."""
    imu = Board.imu_reader()
    imu.attach_lsm9ds0()
    imu.set_lsm9ds0(-1700, -400, 16000, 32)
    imu.run_until(1.0)
    imu.write_uart("".join([build_frame("GETCOE", 1, ["W", "X"]), build_frame("STATUS", 2),
                            build_frame("SETCOE", 3, ["W", "X", 571.5, -20.23, 1.569e-3, -0.1044,
                                                      -6.936e-5, 6.327e-9]),
                            build_frame("RESEED", 4)]).encode())
    imu.run_until(10.0)
    chamber = Board.thermal_chamber()
    chamber.attach_l298n()
    for channel in (0, 1):
        chamber.set_adc_millivolts(channel, 2500.0)
    chamber.run_until(1.0)
    chamber.write_uart("".join([build_frame("SETPRG", 1, [20, 30, 2, 60, 1200, 1, "A"]),
                                build_frame("START", 2), build_frame("STATUS", 3)]).encode())
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scatter", action="store_true", help="issue 7's long check instead")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--disable", action="append", default=[], metavar="TERM")
    args = parser.parse_args()
    if args.scatter:
        scatter(Model.load().with_terms({name: False for name in args.disable}), args.seed)
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


    for name, untouched, capacity in stack_use():
        print(f"{name}: the stack reached {capacity - untouched} of the {capacity} B above the static "
              f"data; {untouched} B never touched (target >= {STACK_HEADROOM_TARGET_B} B)")
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
