"""Command line: ``thermotilt SUBCOMMAND ...``. Errors are one line on stderr."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import NoReturn, Sequence

from tqdm import tqdm

from . import __version__
from .coefficients import (
    PAPER_DEFAULTS,
    CoefficientBlockError,
    decode_block,
    encode_block,
    setcoe_frames,
)
from .protocol import PROTOCOL_VERSION, FrameReader

PROGRAM = "thermotilt"


class UsageError(Exception):
    """Bad input that the user can fix; reported as one line."""


class _ArgumentParser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        # argparse would print the usage too; one line is easier to read in logs.
        self.exit(2, f"{PROGRAM}: error: {message} (see --help)\n")


def _read_capture(path: str) -> bytes:
    if path == "-":
        return sys.stdin.buffer.read()
    try:
        with open(path, "rb") as capture:
            return capture.read()
    except OSError as error:
        raise UsageError(f"cannot read {path}: {error.strerror or error}") from None


def _command_frames(args: argparse.Namespace) -> int:
    reader = FrameReader()
    reader.feed(_read_capture(args.capture))
    # A capture may end without a line end: the last line still counts.
    reader.feed(b"\n")
    if reader.frames == 0:
        raise UsageError(f"{args.capture}: no valid frames ({reader.malformed} malformed)")
    print(f"frames: {reader.frames}")
    for frame_type, count in sorted(reader.frames_by_type.items()):
        print(f"  {frame_type}: {count}")
    print(f"malformed: {reader.malformed}")
    for reason, count in sorted(reader.malformed_by_reason.items()):
        print(f"  {reason}: {count}")
    print(f"gaps: {reader.gaps} (lost frames: {reader.lost_frames})")
    return 0


def _command_coefficients(args: argparse.Namespace) -> int:
    if args.block:
        try:
            table = decode_block(_read_capture(args.block))
        except CoefficientBlockError as error:
            raise UsageError(f"{args.block}: {error}") from None
    else:
        table = PAPER_DEFAULTS
    if args.write_block:
        try:
            with open(args.write_block, "wb") as output:
                output.write(encode_block(table))
        except OSError as error:
            raise UsageError(
                f"cannot write {args.write_block}: {error.strerror or error}"
            ) from None
    for line in setcoe_frames(table):
        sys.stdout.write(line.rstrip("\r\n") + "\n")
    return 0


def _command_simulate(args: argparse.Namespace) -> int:
    from . import simulate
    from .physics import Model, ModelError, parse_fault
    from .runlog import read_run_log
    from .scenarios import ScenarioError, ScenarioOptions, build
    from .twin import TwinError

    try:
        model = Model.load(args.model)
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
            ),
        )
    except (ModelError, ScenarioError) as error:
        raise UsageError(str(error)) from None
    out_dir = Path(args.out or f"runs/{scenario.name}-{time.strftime('%Y%m%d-%H%M%S')}")
    if (out_dir / "run.csv").exists() and not args.force:
        raise UsageError(f"{out_dir}/run.csv exists; choose another --out or add --force")

    def announce_pty(board: str, path: str) -> None:
        print(f"{board}: {path}", flush=True)

    print(f"{scenario.description}: {scenario.duration_s:.0f} s simulated -> {out_dir}", flush=True)
    with tqdm(total=round(scenario.duration_s), unit="sim s", disable=None, file=sys.stderr) as bar:
        try:
            result = simulate.run(
                scenario, model, out_dir, seed=args.seed, pty=args.pty, on_pty=announce_pty,
                progress=lambda t: bar.update(round(t) - bar.n),
            )
        except (TwinError, simulate.SimulationError) as error:
            raise UsageError(str(error)) from None
        except OSError as error:
            raise UsageError(f"cannot write {out_dir}: {error.strerror or error}") from None
    summary = result.summary
    print(f"rows: {summary['rows']}  simulated: {summary['sim_seconds']:.0f} s  "
          f"wall: {summary['wall_seconds']:.1f} s  ({summary['speed_x_real_time']}x real time)")
    for board, report in summary["boards"].items():
        print(f"{board}: {report['frames']} frames, {report['rejected']} rejected, "
              f"{report['cycles']} cycles")
        for refusal in report["refused_commands"]:
            print(f"{board} refused {refusal}")
    _print_figures(scenario.name, read_run_log(str(out_dir / "run.csv")))
    return 0


def _print_figures(scenario_name: str, rows: list[dict[str, str]]) -> None:
    """The paper's numbers for the scenarios that have them."""
    from .figures import drift_figures, fig8_figures

    if scenario_name == "fig8":
        figures = fig8_figures(rows)
        for hold in figures["holds"]:
            print(f"hold {hold['setpoint_c']:g} degC: settled {hold['settled_c']:.2f}, "
                  f"offset {hold['offset_c']:+.2f} degC")
        for step in figures["steps"]:
            print(f"step {step['from_c']:g} -> {step['to_c']:g} degC: {step['completion_s']:.1f} s, "
                  f"overshoot {step['overshoot_c']:.2f} degC")
    elif scenario_name == "cycle":
        figures = drift_figures(rows)
        for axis in ("x", "y"):
            print(f"{axis.upper()}: raw drift {figures[axis]['raw_span_lsb']:.0f} LSB, "
                  f"compensated {figures[axis]['compensated_span_lsb']:.0f} LSB")


def _command_log(args: argparse.Namespace) -> int:
    from .logger import LogError, log_boards
    from .runlog import format_number

    try:
        result = log_boards(
            imu_port=args.port,
            out_path=Path(args.out),
            chamber_port=args.chamber_port,
            baud=args.baud,
            duration_s=args.duration,
            max_rows=args.rows,
            raw_dir=Path(args.raw_dir) if args.raw_dir else None,
            context={
                "ambient_c": format_number(args.ambient, 3),
                "incl_x_deg": format_number(args.incl_x, 2),
                "incl_y_deg": format_number(args.incl_y, 2),
            },
            force=args.force,
        )
    except LogError as error:
        raise UsageError(str(error)) from None
    print(f"rows: {result.rows}  frames: {result.frames}  rejected: {result.rejected}  "
          f"gaps: {result.gaps}  ({result.end_reason})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _ArgumentParser(prog=PROGRAM, description="ThermoTilt host tools.")
    parser.add_argument(
        "--version",
        action="version",
        version=f"{PROGRAM} {__version__} (protocol {PROTOCOL_VERSION})",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    frames = commands.add_parser(
        "frames", help="count the frames in a capture file: per type, malformed, sequence gaps"
    )
    frames.add_argument("capture", help="file of raw serial bytes, or - for standard input")
    frames.set_defaults(run=_command_frames)

    coefficients = commands.add_parser(
        "coefficients", help="print SETCOE frames for the paper's or a stored coefficient block"
    )
    coefficients.add_argument("--block", help="read a 148-byte EEPROM coefficient block")
    coefficients.add_argument("--write-block", help="also write the block to this file")
    coefficients.set_defaults(run=_command_coefficients)

    simulate = commands.add_parser(
        "simulate", help="run both firmware images in the digital twin against the physics model"
    )
    simulate.add_argument("scenario", help="fig8, cycle, campaign, field-warming, field-cooling "
                          "or field-alternating")
    simulate.add_argument("--out", help="output folder (default runs/SCENARIO-DATE-TIME)")
    simulate.add_argument("--force", action="store_true", help="overwrite an earlier run in --out")
    simulate.add_argument("--seed", type=int, default=1, help="noise seed (default 1)")
    simulate.add_argument("--model", help="physics model file (default: the packaged default.toml)")
    simulate.add_argument("--hold-seconds", type=int, default=60,
                          help="time per chamber step (default 60, the paper's)")
    simulate.add_argument("--rest-seconds", type=int, default=1200,
                          help="Peltier-off rest after each cycle (default 1200)")
    simulate.add_argument("--incl-x", type=float, default=0.0, help="table angle on X, degrees")
    simulate.add_argument("--incl-y", type=float, default=0.0, help="table angle on Y, degrees")
    simulate.add_argument("--positions", help="campaign subset, e.g. 0,X+30,Y-15")
    simulate.add_argument("--ambient", type=float, help="ambient temperature for chamber scenarios")
    simulate.add_argument("--duration", type=float,
                          help="field scenarios: compress the day's profile into this many seconds")
    simulate.add_argument("--enable", action="append", default=[], metavar="TERM",
                          help="switch a model term on (repeatable)")
    simulate.add_argument("--disable", action="append", default=[], metavar="TERM",
                          help="switch a model term off (repeatable)")
    simulate.add_argument("--fault", action="append", default=[], metavar="NAME[=RATE][@START[-END]]",
                          help="inject a fault, e.g. inner_open@120-180 or imu_uart_corrupt=0.001")
    simulate.add_argument("--pty", action="store_true",
                          help="also expose each board's serial port as a pseudo-terminal")
    simulate.set_defaults(run=_command_simulate)

    log = commands.add_parser("log", help="log real boards (or the twin's --pty ports) to run.csv")
    log.add_argument("--port", required=True, help="the IMU reader's serial port")
    log.add_argument("--out", required=True, help="run.csv to write")
    log.add_argument("--chamber-port", help="the thermal chamber's serial port, if logged too")
    log.add_argument("--baud", type=int, default=115200, help="line speed (default 115200)")
    log.add_argument("--duration", type=float, help="stop after this many seconds of board time")
    log.add_argument("--rows", type=int, help="stop after this many rows")
    log.add_argument("--raw-dir", help="also save the raw bytes of each port in this folder")
    log.add_argument("--ambient", type=float, help="ambient temperature to record, degC")
    log.add_argument("--incl-x", type=float, help="table angle on X to record, degrees")
    log.add_argument("--incl-y", type=float, help="table angle on Y to record, degrees")
    log.add_argument("--force", action="store_true", help="overwrite an existing --out")
    log.set_defaults(run=_command_log)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except UsageError as error:
        print(f"{PROGRAM}: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{PROGRAM}: interrupted", file=sys.stderr)
        return 130
