"""The commands of the serial line: ``frames`` (count a capture's frames),
``coefficients`` (a coefficient block as SETCOE frames) and ``log`` (real
boards, or the twin's pseudo-terminals, to run.csv)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..options import (
    UsageError,
    ambient,
    board_seconds,
    inclination,
    input_chunks,
    interrupted,
    read_at_most,
    within,
)


def add_commands(commands: argparse._SubParsersAction) -> None:
    frames = commands.add_parser(
        "frames", help="count the frames in a capture file: per type, malformed, sequence gaps"
    )
    frames.add_argument("capture", help="file of raw serial bytes, or - for standard input")
    frames.set_defaults(run=_frames)

    coefficients = commands.add_parser(
        "coefficients", help="print SETCOE frames for the paper's or a stored coefficient block"
    )
    coefficients.add_argument("--block", help="read a 148-byte EEPROM coefficient block")
    coefficients.add_argument("--write-block", help="also write the block to this file")
    coefficients.set_defaults(run=_coefficients)

    log = commands.add_parser("log", help="log real boards (or the twin's --pty ports) to run.csv")
    log.add_argument("--port", required=True, help="the IMU reader's serial port")
    log.add_argument("--out", required=True, help="run.csv to write")
    log.add_argument("--chamber-port", help="the thermal chamber's serial port, if logged too")
    log.add_argument("--baud", type=int, default=115200, help="line speed (default 115200)")
    log.add_argument("--duration", type=board_seconds, help="stop after this many seconds of board time")
    log.add_argument("--rows", type=within(int, 1), help="stop after this many rows")
    log.add_argument("--raw-dir", help="also save the raw bytes of each port in this folder")
    log.add_argument("--ambient", type=ambient, help="ambient temperature to record, degC")
    log.add_argument("--incl-x", type=inclination, help="table angle on X to record, degrees")
    log.add_argument("--incl-y", type=inclination, help="table angle on Y to record, degrees")
    log.add_argument("--force", action="store_true", help="overwrite an existing --out")
    log.set_defaults(run=_log)


def _print_frame_counts(reader) -> None:
    print(f"frames: {reader.frames}")
    for frame_type, count in sorted(reader.frames_by_type.items()):
        print(f"  {frame_type}: {count}")
    print(f"malformed: {reader.malformed}")
    for reason, count in sorted(reader.malformed_by_reason.items()):
        print(f"  {reason}: {count}")
    print(f"gaps: {reader.gaps} (lost frames: {reader.lost_frames})")


def _frames(args: argparse.Namespace) -> int:
    from .protocol import FrameReader

    reader = FrameReader()
    try:
        for chunk in input_chunks(args.capture):
            reader.feed(chunk)
    except KeyboardInterrupt:
        _print_frame_counts(reader)
        return interrupted()
    # A capture may end without a line end: the last line still counts.
    reader.feed(b"\n")
    if reader.frames == 0:
        raise UsageError(f"{args.capture}: no valid frames ({reader.malformed} malformed)")
    _print_frame_counts(reader)
    return 0


def _coefficients(args: argparse.Namespace) -> int:
    from ..surfaces import PAPER_DEFAULTS
    from .coefficients import BLOCK_SIZE, CoefficientBlockError, decode_block, encode_block, setcoe_frames

    table = PAPER_DEFAULTS
    if args.block:
        try:
            table = decode_block(read_at_most(args.block, BLOCK_SIZE))
        except CoefficientBlockError as error:
            raise UsageError(f"{args.block}: {error}") from None
    if args.write_block:
        try:
            with open(args.write_block, "wb") as output:
                output.write(encode_block(table))
        except OSError as error:
            raise UsageError(f"cannot write {args.write_block}: {error.strerror or error}") from None
    for line in setcoe_frames(table):
        sys.stdout.write(line.rstrip("\r\n") + "\n")
    return 0


def _log(args: argparse.Namespace) -> int:
    from ..run.log import format_number
    from .logger import INTERRUPTED, LogError, log_boards

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
    return interrupted() if result.end_reason == INTERRUPTED else 0
