"""Command line: ``thermotilt SUBCOMMAND ...``. Errors are one line on stderr."""

from __future__ import annotations

import argparse
import sys
from typing import NoReturn, Sequence

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
