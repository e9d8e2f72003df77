"""``thermotilt simulate``: a paper experiment in the digital twin, both
firmware images in simavr against the physics model."""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from ..options import (
    UsageError,
    add_model_options,
    add_program_options,
    board_seconds,
    inclination,
    interrupted,
    read_at_most,
)

if TYPE_CHECKING:
    from ..physics import Model
    from ..run.summary import RunSummary
    from .scenarios import Scenario
    from .simulate import ImuRun


def add_commands(commands: argparse._SubParsersAction) -> None:
    simulate = commands.add_parser(
        "simulate", help="run both firmware images in the digital twin against the physics model"
    )
    simulate.add_argument(
        "scenario",
        help="fig8, cycle, campaign, field-warming, field-cooling, field-alternating, "
        "field-days (days of weather, seeded by --seed) or idle (both boards, no commands: for --pty)",
    )
    simulate.add_argument("--out", help="output folder (default runs/SCENARIO-DATE-TIME)")
    simulate.add_argument("--force", action="store_true", help="overwrite an earlier run in --out")
    add_model_options(simulate)
    add_program_options(simulate)
    simulate.add_argument("--incl-x", type=inclination, default=0.0, help="table angle on X, degrees")
    simulate.add_argument("--incl-y", type=inclination, default=0.0, help="table angle on Y, degrees")
    simulate.add_argument("--positions", help="campaign subset, e.g. 0,X+30,Y-15")
    simulate.add_argument(
        "--duration",
        type=board_seconds,
        help="field scenarios: compress the day's profile (field-days: all its --days) into this many seconds; "
        "idle: run this long (default 3600)",
    )
    simulate.add_argument(
        "--days",
        type=float,
        help="field-days: days of weather from local midnight, fractions allowed, up to 49 (default 2); "
        "DAYS x 86400 simulated seconds, or compressed into --duration seconds when that is given",
    )
    simulate.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="NAME[=RATE][@START[-END]]",
        help="inject a fault, e.g. inner_open@120-180 or imu_uart_corrupt=0.001",
    )
    simulate.add_argument(
        "--pty",
        action="store_true",
        help="also expose each board's serial port as a pseudo-terminal "
        "(paced to the wall clock unless --realtime off)",
    )
    simulate.add_argument(
        "--realtime",
        choices=("on", "off"),
        help="on: a simulated second takes a wall second, as on a board; "
        "off: as fast as the host can (default on with --pty, off without)",
    )
    simulate.add_argument(
        "--eeprom",
        metavar="FILE",
        help="start the IMU with this coefficient block in its EEPROM (coefficients.bin from thermotilt fit)",
    )
    simulate.add_argument(
        "--sensor",
        metavar="ID",
        help="simulate this sensor of the model's [[sensors]] batch; its IMU board holds the ID",
    )
    simulate.set_defaults(run=_simulate)


def announced_ports(lines: Iterable[str], boards: int = 2) -> dict[str, str]:
    """The pseudo-terminals `simulate --pty` announces ("imu_reader:
    /dev/pts/3") among its output lines, by board; EOFError when the lines
    end first."""
    ports = {}
    for line in lines:
        board, _, path = line.strip().partition(": ")
        if path.startswith("/dev/"):
            ports[board] = path
            if len(ports) == boards:
                return ports
    raise EOFError("the twin ended before announcing its ports")


def _eeprom_block(path: str) -> bytes:
    """The --eeprom file: a coefficient block (coefficients.bin) or the whole
    EEPROM a twin run saved (imu_reader_eeprom.bin). What it holds is the
    firmware's to judge at boot, as with a real EEPROM."""
    from ..run.folder import IMU_EEPROM_FILE
    from ..wire.coefficients import BLOCK_SIZE, V1_BLOCK_SIZE
    from .simulate import IMU_EEPROM_BYTES

    data = read_at_most(path, IMU_EEPROM_BYTES)
    if len(data) not in (BLOCK_SIZE, V1_BLOCK_SIZE, IMU_EEPROM_BYTES):
        size = f"more than {IMU_EEPROM_BYTES}" if len(data) > IMU_EEPROM_BYTES else str(len(data))
        raise UsageError(
            f"{path}: {size} bytes; --eeprom takes the {BLOCK_SIZE}-byte coefficient block "
            f"that thermotilt fit writes (coefficients.bin; {V1_BLOCK_SIZE} bytes in version 1) or the "
            f"{IMU_EEPROM_BYTES}-byte EEPROM a run saved ({IMU_EEPROM_FILE})"
        )
    return data


def _simulate(args: argparse.Namespace) -> int:
    from ..run.folder import RunFolder
    from ..run.log import RunLogError, read_run_columns
    from .simulate import ImuRun

    model, scenario = _model_and_scenario(args)
    eeprom = _eeprom_block(args.eeprom) if args.eeprom else None
    out_dir = Path(args.out or f"runs/{scenario.name}-{time.strftime('%Y%m%d-%H%M%S')}")
    # What the command made, for the registry's record (registry/recording.py).
    args.out = str(out_dir)
    log = RunFolder.at(out_dir).log
    if log.exists() and not args.force:
        raise UsageError(f"{log} exists; choose another --out or add --force")
    summary = _run_twin(
        args, scenario, ImuRun(model, out_dir, seed=args.seed, eeprom=eeprom, sensor_id=args.sensor or "")
    )
    _print_summary(summary)
    if summary.interrupted:
        return interrupted()
    if scenario.paper_figures is not None:
        try:
            columns = read_run_columns(str(log))
        except RunLogError as error:
            raise UsageError(str(error)) from None
        for line in scenario.paper_figures(columns):
            print(line)
    return 0


def _model_and_scenario(args: argparse.Namespace) -> tuple[Model, Scenario]:
    """The model (--model, --sensor, --enable, --disable, --fault) and the
    scenario the options ask for."""
    from ..physics import Model, ModelError, parse_fault
    from .scenarios import DRAWS_WEATHER, ScenarioError, ScenarioOptions, build

    try:
        model = Model.load(args.model)
        if args.sensor:
            model = model.for_sensor(args.sensor)
        changes = {name: True for name in args.enable} | {name: False for name in args.disable}
        model = model.with_terms(changes).with_faults(parse_fault(text) for text in args.fault)
        scenario = build(
            args.scenario,
            ScenarioOptions(
                hold_s=args.hold_seconds,
                rest_s=args.rest_seconds,
                incl_x_deg=args.incl_x,
                incl_y_deg=args.incl_y,
                positions=tuple(args.positions.split(",")) if args.positions else None,
                ambient_c=args.ambient,
                duration_s=args.duration,
                hold_start=args.hold_start,
                controller=args.controller,
                days=args.days,
                seed=args.seed if args.scenario in DRAWS_WEATHER else 0,
            ),
        )
    except (ModelError, ScenarioError) as error:
        raise UsageError(str(error)) from None
    return model, scenario


def _run_twin(args: argparse.Namespace, scenario: Scenario, imu: ImuRun) -> RunSummary:
    """Runs the twin as --pty and --realtime say, its progress on stderr."""
    from tqdm import tqdm

    from .boards import TwinError
    from .simulate import Playback, SimulationError, run_imu

    realtime = args.pty if args.realtime is None else args.realtime == "on"
    in_real_time = " in real time" if realtime else ""
    print(f"{scenario.description}: {scenario.duration_s:.0f} s simulated{in_real_time} -> {imu.out_dir}", flush=True)
    with tqdm(total=round(scenario.duration_s), unit="sim s", disable=None, file=sys.stderr) as bar:
        playback = Playback(
            pty=args.pty,
            on_pty=_announce_pty,
            progress=lambda t: bar.update(round(t) - bar.n),
            realtime=realtime,
        )
        try:
            return run_imu(scenario, imu, playback).summary
        except (TwinError, SimulationError) as error:
            raise UsageError(str(error)) from None
        except OSError as error:
            raise UsageError(f"cannot write {imu.out_dir}: {error.strerror or error}") from None


def _announce_pty(board: str, path: str) -> None:
    print(f"{board}: {path}", flush=True)


def _print_summary(summary: RunSummary) -> None:
    print(
        f"rows: {summary.rows}  simulated: {summary.sim_seconds:.0f} s  "
        f"wall: {summary.wall_seconds:.1f} s  ({summary.speed_x_real_time}x real time)  ({summary.end_reason})"
    )
    for board, report in summary.boards.items():
        print(f"{board}: {report.frames} frames, {report.rejected} rejected, {report.cycles} cycles")
        for refusal in report.refused_commands or ():
            print(f"{board} refused {refusal}")
        for error in report.reported_errors:
            print(f"{board} reported {error}")
