"""The registry's commands: ``registry rebuild FOLDER...`` and ``registry
ingest FOLDER...`` (the folders into the database), ``sensors`` (the
fleet, one line per sensor) and ``history ID`` (a sensor's calibrations
and how its drift surfaces changed between them); and, for the command
line, ``--registry`` on the commands that make something and the record
of what they made (``recording``); docs/registry.md. The database loads
only when a command runs."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..options import PROGRAM, as_usage_error, existing_folder, one_line, within
from . import DEFAULT_INTERVAL_DAYS, ENVIRONMENT_VARIABLE, OFF
from .recalibration import previous_fit_finder
from .recording import RECORDED_COMMANDS, record_made

if TYPE_CHECKING:
    from .database import Registry
    from .ingest import Ingestion


def add_commands(commands: argparse._SubParsersAction) -> None:
    registry = commands.add_parser(
        "registry", help="the lab registry of sensors, fits, campaigns and runs (docs/registry.md)"
    )
    actions = registry.add_subparsers(dest="action", required=True, metavar="ACTION")
    rebuild = actions.add_parser(
        "rebuild", help="empty the registry and record every campaign, fit, run and validation in FOLDER..."
    )
    ingest = actions.add_parser(
        "ingest",
        help="record the campaigns, fits, runs and validations in FOLDER... (a folder recorded before: only its changes)",
    )
    for action, run in ((rebuild, _rebuild), (ingest, _ingest)):
        action.add_argument(
            "folders", nargs="+", metavar="FOLDER", type=existing_folder, help="a folder to walk, its subfolders too"
        )
        _add_registry_option(action)
        action.set_defaults(run=run)
    sensors = commands.add_parser(
        "sensors", help="every sensor in the registry: last calibration, U, fit, last validation, recalibration due"
    )
    sensors.add_argument(
        "--interval-days",
        metavar="N",
        type=within(int, 1),
        default=DEFAULT_INTERVAL_DAYS,
        help=f"recalibration due N days after the last calibration (default {DEFAULT_INTERVAL_DAYS})",
    )
    _add_registry_option(sensors)
    sensors.set_defaults(run=_sensors)
    history = commands.add_parser(
        "history",
        help="a sensor's calibrations over time and the change of its drift surfaces between them (RMS, largest)",
    )
    history.add_argument("sensor_id", metavar="ID", help="the sensor, as thermotilt sensors lists it")
    history.add_argument("--out", metavar="DIR", help="also write history.json and history.png here")
    _add_registry_option(history)
    history.set_defaults(run=_history)


def add_recording_options(commands: argparse._SubParsersAction) -> None:
    """--registry on each command whose making the command line records."""
    for name in RECORDED_COMMANDS:
        commands.choices[name].add_argument(
            "--registry",
            metavar="URL",
            help=f"record what this makes in this registry (default: ${ENVIRONMENT_VARIABLE}, else "
            f"runs/registry.sqlite3 here); {OFF}: record nothing",
        )


def prepare(args: argparse.Namespace) -> None:
    """Before a command: fit asks the registry for each sensor's previous calibration (recalibration.py)."""
    if getattr(args, "command", None) == "fit":
        args.find_previous_fit = previous_fit_finder(args)


def record_what_was_made(args: argparse.Namespace, status: int) -> None:
    """After a command: what it made recorded in the registry, or one warning line on stderr."""
    warning = record_made(args, status)
    if warning is not None:
        print(f"{PROGRAM}: warning: {one_line(warning)}", file=sys.stderr)


def _add_registry_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--registry",
        metavar="URL",
        help="database URL, e.g. sqlite:///lab.sqlite3 or postgresql+psycopg://host/lab "
        f"(default: ${ENVIRONMENT_VARIABLE}, else runs/registry.sqlite3 here)",
    )


def _rebuild(args: argparse.Namespace) -> int:
    from .ingest import rebuild

    return _record(args, rebuild)


def _ingest(args: argparse.Namespace) -> int:
    from .ingest import ingest

    return _record(args, ingest)


def _record(args: argparse.Namespace, workflow: Callable[[Registry, Sequence[Path]], Ingestion]) -> int:
    from .database import Registry, RegistryError, registry_url
    from .folders import FolderError

    with as_usage_error(RegistryError, FolderError), Registry.open(registry_url(args.registry)) as registry:
        ingestion = workflow(registry, [Path(folder) for folder in args.folders])
    print(ingestion.summary())
    return 0


def _sensors(args: argparse.Namespace) -> int:
    from .database import Registry, RegistryError, registry_url
    from .fleet import fleet

    with as_usage_error(RegistryError), Registry.open(registry_url(args.registry)) as registry:
        listing = fleet(registry, args.interval_days)
    print(listing.summary())
    return 0


def _history(args: argparse.Namespace) -> int:
    from .database import Registry, RegistryError, registry_url
    from .history import HistoryError, history

    with as_usage_error(RegistryError, HistoryError), Registry.open(registry_url(args.registry)) as registry:
        result = history(registry, args.sensor_id)
        written = result.write(Path(args.out)) if args.out else []
    print(result.summary())
    if written:
        print(f"wrote {', '.join(str(path) for path in written)}")
    return 0
