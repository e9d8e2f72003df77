"""The commands of the serial line: ``frames`` (count a capture's frames),
``coefficients`` (a coefficient block as SETCOE and SETDOM frames) and ``log`` (real
boards, or the twin's pseudo-terminals, to a run folder)."""

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
    coefficients.add_argument(
        "--block", help="read an EEPROM coefficient block (coefficients.bin: 188 bytes, or 148 of version 1)"
    )
    coefficients.add_argument("--write-block", help="also write the block to this file")
    coefficients.set_defaults(run=_coefficients)

    log = commands.add_parser("log", help="log real boards (or the twin's --pty ports) to a run folder")
    log.add_argument("--port", required=True, help="the IMU reader's serial port")
    log.add_argument(
        "--out",
        required=True,
        metavar="FOLDER",
        help="run folder to write (run.csv, serial/, summary.json); FOLDER/run.csv names it too",
    )
    log.add_argument("--chamber-port", help="the thermal chamber's serial port, if logged too")
    log.add_argument("--baud", type=int, default=115200, help="line speed (default 115200)")
    log.add_argument("--duration", type=board_seconds, help="stop after this many seconds of board time")
    log.add_argument("--rows", type=within(int, 1), help="stop after this many rows")
    # Before run folders the raw bytes went to their own folder; now to FOLDER/serial/.
    log.add_argument("--raw-dir", help=argparse.SUPPRESS)
    log.add_argument("--ambient", type=ambient, help="ambient temperature to record, degC")
    log.add_argument("--incl-x", type=inclination, help="table angle on X to record, degrees")
    log.add_argument("--incl-y", type=inclination, help="table angle on Y to record, degrees")
    log.add_argument("--force", action="store_true", help="overwrite a run already in --out")
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
    from ..surfaces import PAPER_DEFAULTS, SETS
    from .coefficients import (
        BLOCK_SIZE,
        CoefficientBlock,
        CoefficientBlockError,
        decode_block,
        encode_block,
        setcoe_frames,
    )
    from .protocol import SequenceCounter, build_frame

    block = CoefficientBlock(PAPER_DEFAULTS)
    if args.block:
        try:
            block = decode_block(read_at_most(args.block, BLOCK_SIZE))
        except CoefficientBlockError as error:
            raise UsageError(f"{args.block}: {error}") from None
    if args.write_block:
        try:
            with open(args.write_block, "wb") as output:
                output.write(encode_block(block.table, block.sensor_id, block.domain))
        except OSError as error:
            raise UsageError(f"cannot write {args.write_block}: {error.strerror or error}") from None
    lines = setcoe_frames(block.table)
    # SETCOE leaves a set's domain unknown, so SETDOM follows it.
    seq = SequenceCounter(len(lines))
    lines += [
        build_frame("SETDOM", seq.next(), block.domain[set_name].setdom_values(set_name))
        for set_name in SETS
        if block.domain[set_name].temperature_centi_c is not None
    ]
    for line in lines:
        sys.stdout.write(line.rstrip("\r\n") + "\n")
    return 0


def _log_folder(out: str) -> Path:
    """--out: the run folder, or its run.csv (how --out named the log before
    it named a folder)."""
    from ..run.folder import LOG_FILE

    path = Path(out)
    if path.suffix.lower() != ".csv":
        return path
    if path.name != LOG_FILE:
        raise UsageError(
            f"--out {out}: a run folder's log is {LOG_FILE}; give the folder, e.g. --out {path.with_suffix('')}"
        )
    return path.parent


def _log(args: argparse.Namespace) -> int:
    from .logger import LogError, Rig, log_boards

    if args.raw_dir is not None:
        raise UsageError("--raw-dir is gone: log keeps each port's bytes in the run folder's serial/")
    try:
        summary = log_boards(
            imu_port=args.port,
            out_dir=_log_folder(args.out),
            chamber_port=args.chamber_port,
            baud=args.baud,
            duration_s=args.duration,
            max_rows=args.rows,
            rig=Rig(ambient_c=args.ambient, incl_x_deg=args.incl_x, incl_y_deg=args.incl_y),
            force=args.force,
        )
    except LogError as error:
        raise UsageError(str(error)) from None
    boards = summary.boards.values()
    print(
        f"rows: {summary.rows}  frames: {sum(report.frames for report in boards)}  "
        f"rejected: {sum(report.rejected for report in boards)}  "
        f"gaps: {sum(report.sequence_gaps for report in boards)}  ({summary.end_reason})"
    )
    for name, report in summary.boards.items():
        for error in report.reported_errors:
            print(f"{name} reported {error}")
    return interrupted() if summary.interrupted else 0
