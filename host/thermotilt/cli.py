"""Command line: ``thermotilt COMMAND ...``. Each wing registers its own
commands (``wire``, ``twin``, ``calibration``, ``discovery``,
``registry``, ``live``); this module parses, runs the one chosen (with the
live view of its folder served while it runs when it has ``--serve``,
docs/live.md), turns what it raises into one line on stderr
(docs/reliability.md lists them) and has the registry record what the
command made (docs/registry.md)."""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from . import __version__
from .calibration import cli as calibration
from .discovery import cli as discovery
from .live import cli as live
from .options import PROGRAM, ArgumentParser, UsageError, interrupted, one_line
from .registry import cli as registry
from .twin import cli as twin
from .wire import cli as wire
from .wire.protocol_spec import PROTOCOL_VERSION


def build_parser() -> ArgumentParser:
    parser = ArgumentParser(prog=PROGRAM, description="ThermoTilt host tools.")
    parser.add_argument("--version", action="version", version=f"{PROGRAM} {__version__} (protocol {PROTOCOL_VERSION})")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for wing in (wire, twin, calibration, discovery, registry, live):
        wing.add_commands(commands)
    registry.add_recording_options(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    if sys.stdout is None:
        return _error("standard output is closed")
    try:
        return _run(argv)
    except KeyboardInterrupt:
        return interrupted()
    except BrokenPipeError:
        # The reader left (`thermotilt ... | head`): nobody is left to tell.
        _discard_stdout()
        return 1
    except OSError as error:
        # Every file a command writes reports its own errors; what is left is
        # standard output, e.g. on a full disk.
        _discard_stdout()
        return _error(f"cannot write standard output: {error.strerror or error}")


def _run(argv: Sequence[str] | None) -> int:
    # A file name that is not UTF-8 is still printable.
    sys.stdout.reconfigure(errors="backslashreplace")
    try:
        args = build_parser().parse_args(argv)
    finally:
        # --help and --version print and exit: a failed write shows here.
        sys.stdout.flush()
    registry.prepare(args)
    try:
        with live.serving_while_it_runs(args):
            status = args.run(args)
    except UsageError as error:
        status = _error(str(error))
    sys.stdout.flush()
    registry.record_what_was_made(args, status)
    return status


def _error(message: str) -> int:
    print(f"{PROGRAM}: error: {one_line(message)}", file=sys.stderr)
    return 1


def _discard_stdout() -> None:
    """Point standard output at /dev/null, so the interpreter's last flush of
    what could not be written raises nothing more."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
