"""``summary.json``: how a run was made and how it ended, one versioned
schema for every producer — the twin (``thermotilt simulate``, a campaign
position in the twin) and real boards (``thermotilt log``, a campaign
position on the rig) — read through :func:`read_summary` (docs/run-log.md).

A value the source cannot know is null, as run.csv leaves such a cell
empty: a rig has no seed, model or simulated cycles, a log that sent no
commands knows none it had refused.

A summary without a ``schema`` key was written before the schema had a
version. Such a twin summary is read as it stood, with the keys it lacked
(``end_reason``, each board's ``firmware``) null; the campaign's old summary
of a real-board position keeps its end reason, rows and firmware, and its
per-board counts are null (it kept totals only). A schema newer than
:data:`SCHEMA` is refused in one line, since its meaning is not known here.
"""

from __future__ import annotations

import json
import math
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

SUMMARY_FILE = "summary.json"
SCHEMA = 1
TWIN, BOARDS = "twin", "boards"
SOURCES = (TWIN, BOARDS)
# How a run ended (end_reason), besides the bound each producer states in
# its own words ("4082 s simulated", "100 rows", "port closed").
PROGRAM_DONE = "program done"
INTERRUPTED = "interrupted"
CHAMBER_FAULT = "chamber fault"


class RunSummaryError(ValueError):
    """A summary.json that cannot be read; one readable line."""


@dataclass
class BoardReport:
    """What the host saw of one board. Counts are of what reached the host;
    the twin-only figures (cycles, corrupted bytes) are null on a rig, and
    the command lists null where the producer sent no commands it tracked."""

    frames: int | None = None
    frames_by_type: dict[str, int] | None = None
    rejected: int | None = None
    rejected_by_reason: dict[str, int] | None = None
    sequence_gaps: int | None = None
    # Unsolicited ERR frames (cmd_seq -1), "CODE DETAIL at T s", T the
    # run's time: simulated in the twin, wall seconds since the log began on a rig.
    reported_errors: list[str] = field(default_factory=list)
    # The board's first VER: "device firmware_version protocol N".
    firmware: str | None = None
    port: str | None = None
    refused_commands: list[str] | None = None
    unanswered_commands: list[str] | None = None
    cycles: int | None = None
    awake_cycles: int | None = None
    sleep_cycles: int | None = None
    corrupted_bytes: int | None = None


@dataclass
class RunSummary:
    source: str  # TWIN or BOARDS
    rows: int
    # PROGRAM_DONE, "chamber fault NAME", INTERRUPTED or the producer's
    # bound; null only in a summary from before schema 1.
    end_reason: str | None
    wall_seconds: float
    boards: dict[str, BoardReport]
    scenario: str | None = None
    description: str | None = None
    # The scenario's options (thermotilt.twin.scenarios.ScenarioOptions), so
    # that discover --twin can build it again.
    options: dict[str, Any] | None = None
    seed: int | None = None
    model: str | None = None
    terms: dict[str, bool] | None = None
    faults: list[dict[str, Any]] = field(default_factory=list)
    imu_eeprom_preloaded_bytes: int | None = None
    realtime: bool | None = None
    sim_seconds: float | None = None
    speed_x_real_time: float | None = None
    marks: dict[str, float] = field(default_factory=dict)
    # Where the tilt table stood: at_s (from the run's start), label, incl_x_deg, incl_y_deg.
    positions: list[dict[str, Any]] = field(default_factory=list)
    schema: int = SCHEMA

    @property
    def interrupted(self) -> bool:
        return self.end_reason == INTERRUPTED

    def document(self) -> dict[str, Any]:
        """The summary as summary.json holds it: the schema first, and
        ``interrupted`` for readers of the file that want only that."""
        document = asdict(self)
        ordered = {"schema": document.pop("schema")}
        for key, value in document.items():
            ordered[key] = value
            if key == "end_reason":
                ordered["interrupted"] = self.interrupted
        return ordered

    def write(self, folder: Path) -> Path:
        path = Path(folder) / SUMMARY_FILE
        path.write_text(json.dumps(self.document(), indent=2) + "\n")
        return path


def chamber_fault(fault: str) -> str:
    """The end reason of a run whose chamber latched a fault."""
    return f"{CHAMBER_FAULT} {fault}"


def read_summary(folder: Path | str) -> RunSummary:
    """The run's summary.json; RunSummaryError, in one line, when there is
    none or it is not one this version reads."""
    path = Path(folder) / SUMMARY_FILE
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RunSummaryError(f"{path}: no such file") from None
    except OSError as error:
        raise RunSummaryError(f"{path}: cannot read: {error.strerror or error}") from None
    except UnicodeDecodeError as error:
        raise RunSummaryError(f"{path}: not UTF-8 text (byte {error.start})") from None
    except ValueError as error:
        raise RunSummaryError(f"{path}: not JSON ({error})") from None
    if not isinstance(document, dict):
        raise RunSummaryError(f"{path}: not a run summary (a JSON object)")
    try:
        return summary_of(document)
    except RunSummaryError as error:
        raise RunSummaryError(f"{path}: {error}") from None


def summary_of(document: dict[str, Any]) -> RunSummary:
    """A RunSummary from summary.json's object."""
    schema = document.get("schema")
    if schema is None:
        return _unversioned(document)
    if schema != SCHEMA:
        if isinstance(schema, int) and not isinstance(schema, bool) and schema > SCHEMA:
            raise RunSummaryError(
                f"summary schema {schema} is newer than this thermotilt reads ({SCHEMA}); update thermotilt"
            )
        raise RunSummaryError(f"unknown summary schema {schema!r} (this thermotilt reads {SCHEMA})")
    values = {key: value for key, value in document.items() if key != "interrupted"}
    known = {item.name for item in fields(RunSummary)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise RunSummaryError(f"unknown key '{unknown[0]}' for summary schema {SCHEMA}")
    missing = sorted(
        item.name
        for item in fields(RunSummary)
        if item.default is MISSING and item.default_factory is MISSING and item.name not in values
    )
    if missing:
        raise RunSummaryError(f"missing key '{missing[0]}'")
    if values["source"] not in SOURCES:
        raise RunSummaryError(f"source {values['source']!r} is neither {TWIN!r} nor {BOARDS!r}")
    _check_number(values, "rows", int)
    _check_number(values, "wall_seconds", float)
    values["boards"] = _boards(values["boards"])
    return RunSummary(**values)


def _check_number(values: dict[str, Any], key: str, kind: type) -> None:
    value = values[key]
    accepted = (int,) if kind is int else (int, float)
    if isinstance(value, bool) or not isinstance(value, accepted) or not math.isfinite(value):
        raise RunSummaryError(f"{key} is {value!r}, not a number")


def _boards(entries: Any) -> dict[str, BoardReport]:
    if not isinstance(entries, dict) or not all(isinstance(report, dict) for report in entries.values()):
        raise RunSummaryError("boards must map each board's name to its report")
    known = {item.name for item in fields(BoardReport)}
    boards = {}
    for name, report in entries.items():
        unknown = sorted(set(report) - known)
        if unknown:
            raise RunSummaryError(f"board {name}: unknown key '{unknown[0]}'")
        boards[name] = BoardReport(**report)
    return boards


def _unversioned(document: dict[str, Any]) -> RunSummary:
    """A summary from before schema 1: the twin's, or the campaign's for a
    position on real boards ("rig": "boards")."""
    try:
        if document.get("rig") == BOARDS:
            firmware = document.get("firmware") or {}
            return RunSummary(
                source=BOARDS,
                rows=document["rows"],
                end_reason=document["end_reason"],
                wall_seconds=document["wall_seconds"],
                boards={name: BoardReport(firmware=version) for name, version in firmware.items()},
                description=f"campaign position {document.get('position')}",
                realtime=True,
                positions=[{"at_s": 0.0, "label": document.get("position"), "incl_x_deg": None, "incl_y_deg": None}],
            )
        if "scenario" not in document or "boards" not in document:
            raise RunSummaryError("not a run summary: no schema, and neither a twin's nor a rig's keys")
        known = {item.name for item in fields(BoardReport)}
        boards = {
            name: BoardReport(**{key: value for key, value in report.items() if key in known})
            for name, report in document["boards"].items()
        }
        taken = {
            key: document[key]
            for key in (
                "scenario",
                "description",
                "options",
                "seed",
                "model",
                "terms",
                "faults",
                "imu_eeprom_preloaded_bytes",
                "realtime",
                "sim_seconds",
                "speed_x_real_time",
                "marks",
                "positions",
            )
            if key in document
        }
        return RunSummary(
            source=TWIN,
            rows=document["rows"],
            end_reason=INTERRUPTED if document.get("interrupted") else None,
            wall_seconds=document["wall_seconds"],
            boards=boards,
            **taken,
        )
    except (KeyError, TypeError, AttributeError) as error:
        raise RunSummaryError(f"an unversioned summary this thermotilt cannot read ({error!r})") from None
