"""What a command made, recorded in the registry as it finishes
(docs/registry.md). The folder a command wrote is found from its parsed
arguments and ingested as ``registry ingest`` would (``upload`` wrote its
record into the fit's folder); ``assign-id``, which writes no folder,
leaves a row of what it did.

The command line calls ``record_made`` after every command. A folder is
recorded once its command ended well, or was interrupted and said so (a
campaign, a run or a log stopped by Ctrl-C keeps what it finished, and
``log`` and ``simulate --pty`` end no other way); an assignment only once
it ended well. A registry that cannot take the record
costs the command a warning and nothing more: the folder is the source of
truth, and ``registry ingest`` records it later. Importing this module
loads nothing of the database.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

from ..options import EXIT_INTERRUPTED
from . import OFF, configured_url

if TYPE_CHECKING:
    from .schema import IdAssignment


def _out(args: argparse.Namespace) -> Path:
    """The folder --out names (simulate's own choice when given none; a batch's sensors in theirs below it)."""
    return Path(args.out)


def _validated_run(args: argparse.Namespace) -> Path:
    """The run folder validate wrote validation.json into (its --out holds only the report)."""
    from ..run.folder import RunFolder

    return RunFolder.of(args.run_path).path


def _logged_run(args: argparse.Namespace) -> Path:
    """log's --out: the run folder, or its run.csv."""
    out = Path(args.out)
    return out.parent if out.suffix.lower() == ".csv" else out


def _uploaded_fit(args: argparse.Namespace) -> Path:
    """upload's fit folder, whose uploads.jsonl it appended to."""
    return Path(args.fit_dir)


MADE_FOLDERS: dict[str, Callable[[argparse.Namespace], Path]] = {
    "campaign": _out,
    "fit": _out,
    "upload": _uploaded_fit,
    "validate": _validated_run,
    "simulate": _out,
    "log": _logged_run,
}


def _assignment(args: argparse.Namespace, when: datetime) -> IdAssignment:
    from .schema import IdAssignment

    return IdAssignment(assigned_utc=when, sensor_id=args.sensor_id, port=args.port)


MADE_EVENTS: dict[str, Callable[[argparse.Namespace, datetime], IdAssignment]] = {
    "assign-id": _assignment,
}
RECORDED_COMMANDS = (*MADE_FOLDERS, *MADE_EVENTS)


def record_made(args: argparse.Namespace, status: int) -> str | None:
    """Records what the command args ran made, given its exit status; what
    to warn of when the registry could not take it, else None."""
    command = getattr(args, "command", None)
    folders_made = command in MADE_FOLDERS and status in (0, EXIT_INTERRUPTED)
    if not (folders_made or (command in MADE_EVENTS and status == 0)) or configured_url(args.registry) == OFF:
        return None
    from .database import Registry, RegistryError, registry_url, shown
    from .folders import FolderError
    from .ingest import ingest

    try:
        with Registry.open(registry_url(args.registry)) as registry:
            if folders_made:
                ingest(registry, [MADE_FOLDERS[command](args)])
            else:
                with registry.writing() as session:
                    session.add(MADE_EVENTS[command](args, datetime.now(UTC).replace(tzinfo=None, microsecond=0)))
    except RegistryError as error:
        reason = error.reason
    except FolderError as error:
        reason = str(error)
    except OSError as error:
        reason = f"{error.filename or 'the registry'}: {error.strerror or error}"
    except KeyboardInterrupt:
        reason = "interrupted"
    else:
        return None
    return f"not recorded in the registry {shown(configured_url(args.registry))}: {reason}"
