"""The one way into the registry: folders walked (``folders.find_folders``),
read (``folders.read_folder``) and recorded in one transaction, each
artefact under its folder. An artefact whose defining files are as
recorded changes nothing, so ingesting a folder twice adds nothing; one
whose files changed (a campaign that ran further, a fit written again) is
updated. ``rebuild`` first empties the registry: the folders are the
source of truth, and what none of them holds any more goes.
"""

from __future__ import annotations

import sys
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from sqlalchemy import delete, inspect, select, union
from sqlalchemy.orm import Session
from tqdm import tqdm

from .database import Registry
from .folders import DEFINING_FILES, FIT_FILE, KINDS, find_folders, read_folder, read_uploads
from .schema import Artefact, Sensor, Upload

NEW, UPDATED, UNCHANGED = "new", "updated", "unchanged"
PLURALS = {"campaign": "campaigns", "fit": "fits", "board run": "board runs", "validation": "validations"}


@dataclass
class Ingestion:
    """What an ingestion recorded, by kind and outcome, and the folders it skipped."""

    registry: str
    rebuilt: bool
    counts: Counter[tuple[str, str]] = field(default_factory=Counter)
    unrecognised: list[Path] = field(default_factory=list)
    uploads: int = 0  # the uploads the fits' folders hold
    malformed_upload_lines: int = 0

    def recorded(self, kind: str) -> int:
        return sum(count for (counted, _), count in self.counts.items() if counted == kind)

    def summary(self) -> str:
        lines = [f"registry {self.registry} rebuilt:" if self.rebuilt else f"recorded in registry {self.registry}:"]
        for kind in KINDS.values():
            outcomes = [f"{self.counts[kind, outcome]} {outcome}" for outcome in (NEW, UPDATED, UNCHANGED)]
            details = ", ".join(text for text in outcomes if not text.startswith("0 "))
            lines.append(f"  {PLURALS[kind] + ':':<13}{self.recorded(kind):>5}" + (f" ({details})" if details else ""))
        lines.append(f"  {'uploads:':<13}{self.uploads:>5}")
        if self.malformed_upload_lines:
            lines.append(f"skipped {self.malformed_upload_lines} lines of uploads.jsonl that are not upload records")
        skipped = len(self.unrecognised)
        known = ", ".join(sorted(DEFINING_FILES))
        lines.append(f"skipped {skipped} folder{'' if skipped == 1 else 's'} with files but none of {known}")
        return "\n".join(lines)


def ingest(registry: Registry, folders: Sequence[Path], fresh: bool = False) -> Ingestion:
    """Every artefact in and under folders recorded; with fresh, instead of
    what the registry held. Nothing is written unless every folder could be
    read: a FolderError leaves the registry as it was."""
    found = find_folders(folders, registry.database_files())
    artefacts: list[Artefact] = []
    uploads: dict[str, list[Upload]] = {}
    malformed = 0
    # tqdm draws its bar only when stderr is a terminal (disable=None).
    with tqdm(found.artefact_folders, desc="reading", unit=" folders", disable=None, file=sys.stderr) as progress:
        for folder, names in progress:
            artefacts += read_folder(folder, names)
            if FIT_FILE in names:
                uploads[str(folder)], skipped = read_uploads(folder)
                malformed += skipped
    with registry.writing() as session:
        counts = record(session, artefacts, fresh)
        replace_uploads(session, uploads, fresh)
    held = sum(len(rows) for rows in uploads.values())
    return Ingestion(registry.shown_url, fresh, counts, found.unrecognised, held, malformed)


def rebuild(registry: Registry, folders: Sequence[Path]) -> Ingestion:
    """The registry emptied and filled from folders alone."""
    return ingest(registry, folders, fresh=True)


def record(session: Session, artefacts: Sequence[Artefact], fresh: bool = False) -> Counter[tuple[str, str]]:
    """The artefacts stored in session's transaction, by (kind, outcome)."""
    if fresh:
        for table in KINDS:
            session.execute(delete(table))
        session.execute(delete(Sensor))
    named = {artefact.sensor_id for artefact in artefacts if artefact.sensor_id}
    known = set(session.scalars(select(Sensor.sensor_id)))
    session.add_all(Sensor(sensor_id=sensor_id) for sensor_id in sorted(named - known))
    session.flush()
    counts: Counter[tuple[str, str]] = Counter()
    for artefact in artefacts:
        counts[KINDS[type(artefact)], _store(session, artefact)] += 1
    session.flush()
    # A sensor no artefact names any more (its only fit written again for another ID).
    named_anywhere = union(*(select(table.sensor_id).where(table.sensor_id.is_not(None)) for table in KINDS))
    session.execute(delete(Sensor).where(Sensor.sensor_id.not_in(named_anywhere)))
    return counts


def replace_uploads(session: Session, uploads: dict[str, list[Upload]], fresh: bool = False) -> None:
    """Each fit folder's uploads as its uploads.jsonl holds them now (all of
    the registry's, with fresh)."""
    if fresh:
        session.execute(delete(Upload))
    else:
        session.execute(delete(Upload).where(Upload.fit_folder.in_(list(uploads))))
    session.add_all(row for rows in uploads.values() for row in rows)


def _store(session: Session, artefact: Artefact) -> str:
    table = type(artefact)
    stored = session.scalars(select(table).where(table.folder == artefact.folder)).one_or_none()
    if stored is None:
        session.add(artefact)
        return NEW
    if stored.source_sha256 == artefact.source_sha256:
        return UNCHANGED
    for column in inspect(table).column_attrs:
        if column.key != "id":
            setattr(stored, column.key, getattr(artefact, column.key))
    return UPDATED
