"""What every command shares: the one-line error, the argument types with
their ranges, reading an input file, and the options of the twin's model and
the chamber program. Imports nothing heavy, so a typo is answered before any
wing loads numpy, statsmodels or matplotlib.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import IO, NoReturn, TypeVar

from .program import (
    CONTROLLERS,
    DEFAULT_CONTROLLER,
    DEFAULT_HOLD_START,
    DEFAULT_REST_S,
    HOLD_SECONDS_RANGE,
    HOLD_STARTS,
    PAPER_HOLD_S,
    REST_SECONDS_RANGE,
)
from .run.folder import RunFolder, RunFolderError

PROGRAM = "thermotilt"
# 128 + SIGINT, what a shell reports for a command stopped by Ctrl-C.
EXIT_INTERRUPTED = 130
_READ_CHUNK = 65536

# The LSM9DS0's operating range: the ambient of any rig it works in lies within it.
AMBIENT_RANGE_C = (-40.0, 85.0)
INCLINATION_RANGE_DEG = (-90.0, 90.0)
# The boards count time in uint32 milliseconds, which wrap after 49.7 days.
BOARD_SECONDS_RANGE = (0.001, (2**32 - 1) / 1000.0)
# The twin's UART corruption generator takes a 64-bit seed.
SEED_RANGE = (0, 2**64 - 1)
SETTLE_SECONDS_RANGE = (0.0, 3600.0)

_Number = TypeVar("_Number", int, float)


class UsageError(Exception):
    """Bad input that the user can fix; reported as one line."""


class ArgumentParser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        # argparse would print the usage too; one line is easier to read in logs.
        self.exit(2, f"{PROGRAM}: error: {one_line(message)} (see --help)\n")

    def _print_message(self, message: str, file: IO[str] | None = None) -> None:
        # argparse drops write errors; --help on a full disk is reported like any output.
        if message:
            (file or sys.stderr).write(message)


def one_line(message: str) -> str:
    """An error with a file name or argument that holds a line break is
    still one line: control characters are escaped."""
    return "".join(char if char.isprintable() else repr(char)[1:-1] for char in message)


@contextmanager
def as_usage_error(*errors: type[Exception]) -> Iterator[None]:
    """What a workflow raises of these is bad input the user can fix: one line."""
    try:
        yield
    except errors as error:
        raise UsageError(str(error)) from None


def interrupted() -> int:
    print(f"{PROGRAM}: interrupted", file=sys.stderr)
    return EXIT_INTERRUPTED


def within(
    parse: Callable[[str], _Number], low: _Number, high: _Number | None = None, unit: str = ""
) -> Callable[[str], _Number]:
    """An argparse type: a number from low to high (None: no upper limit)."""

    def show(value: _Number) -> str:
        return f"{value:.10g}" if isinstance(value, float) else str(value)

    def checked(text: str) -> _Number:
        value = parse(text)
        if not (low <= value and (high is None or value <= high)):
            span = f"at least {show(low)}" if high is None else f"from {show(low)} to {show(high)}"
            raise argparse.ArgumentTypeError(f"must be {span}{unit}, got {text}")
        return value

    # argparse names the type in "invalid float value: 'x'".
    checked.__name__ = parse.__name__
    return checked


def existing_folder(text: str) -> str:
    """An argparse type: a folder that exists."""
    if not os.path.isdir(text):
        why = "not a folder" if os.path.exists(text) else "no such folder"
        raise argparse.ArgumentTypeError(f"{text}: {why}")
    return text


def existing_run(text: str) -> str:
    """An argparse type: a run folder (with its run.csv) or a run.csv."""
    try:
        RunFolder.of(text)
    except RunFolderError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return text


ambient = within(float, *AMBIENT_RANGE_C, " degC")
inclination = within(float, *INCLINATION_RANGE_DEG, " deg")
board_seconds = within(float, *BOARD_SECONDS_RANGE, " s")
settle_seconds = within(float, *SETTLE_SECONDS_RANGE, " s")
seed = within(int, *SEED_RANGE)


def input_chunks(path: str) -> Iterator[bytes]:
    """The bytes of a file, or of standard input for "-", as they arrive
    (unbuffered, so a live stream is counted up to the moment it stops)."""
    name = "standard input" if path == "-" else path
    if path == "-" and sys.stdin is None:
        raise UsageError("standard input is closed")
    try:
        if path == "-":
            stream = open(sys.stdin.fileno(), "rb", buffering=0, closefd=False)
        else:
            stream = open(path, "rb", buffering=0)
        with stream:
            while chunk := stream.read(_READ_CHUNK):
                yield chunk
    except OSError as error:
        raise UsageError(f"cannot read {name}: {error.strerror or error}") from None


def read_at_most(path: str, limit: int) -> bytes:
    """A file's bytes up to one more than limit: enough to tell a wrong
    size without reading a device file forever."""
    data = b""
    for chunk in input_chunks(path):
        data += chunk
        if len(data) > limit:
            break
    return data


def add_model_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=seed, default=1, help="noise seed (default 1)")
    parser.add_argument("--model", help="physics model file (default: the packaged default.toml)")
    parser.add_argument(
        "--enable", action="append", default=[], metavar="TERM", help="switch a model term on (repeatable)"
    )
    parser.add_argument(
        "--disable", action="append", default=[], metavar="TERM", help="switch a model term off (repeatable)"
    )


def add_program_options(parser: argparse.ArgumentParser) -> None:
    """The chamber program's settings, shared by simulate and campaign."""
    parser.add_argument(
        "--hold-seconds",
        type=within(int, *HOLD_SECONDS_RANGE),
        default=PAPER_HOLD_S,
        help=f"time per chamber step (default {PAPER_HOLD_S}, the paper's)",
    )
    parser.add_argument(
        "--rest-seconds",
        type=within(int, *REST_SECONDS_RANGE),
        default=DEFAULT_REST_S,
        help=f"Peltier-off rest after each cycle (default {DEFAULT_REST_S})",
    )
    parser.add_argument("--ambient", type=ambient, help="ambient temperature for chamber scenarios")
    parser.add_argument(
        "--controller",
        choices=tuple(CONTROLLERS),
        default=DEFAULT_CONTROLLER,
        help="chamber control law: float (the paper's P law, the firmware default) or "
        "rounded-error (P on the error rounded to whole degC, a hypothesis about "
        "the paper's code)",
    )
    parser.add_argument(
        "--hold-start",
        choices=HOLD_STARTS,
        default=DEFAULT_HOLD_START,
        help="when a step's hold starts: T timed, F the first step of each cycle waits "
        "for its setpoint, A every step waits (default)",
    )
