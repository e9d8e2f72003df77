"""A campaign's plan: the paper's positions chosen, the sensors (units) that
each need every position, their records in each unit's campaign.json, and
the one interface through which a runner runs the positions not yet done
(in this process, in worker processes, on a Dask cluster or on real boards).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any, Protocol

from ...program import CALIBRATION_MAX_C, CALIBRATION_MIN_C, PAPER_STEP_C
from ...twin.scenarios import ScenarioOptions, campaign_positions
from .folder import (
    DONE,
    FAILED,
    FORMAT,
    CampaignError,
    CampaignFile,
    CampaignFolder,
    Position,
    PositionRecord,
    utc_now,
)


@dataclass(frozen=True)
class Unit:
    """One sensor a campaign calibrates: its ID (None for a model's only
    sensor) and its campaign's folder inside the campaign's ("" for DIR)."""

    sensor: str | None
    folder: str


# A position to run and the sensors that still need it.
Task = tuple[Position, tuple[Unit, ...]]
Progress = Callable[[float], None]
Finished = Callable[[PositionRecord], None]


class RunEnd(Enum):
    FINISHED = "finished"  # every task ran (some may have failed)
    STOPPED = "stopped"  # a person or a failure on real boards stopped it: the rest waits for --resume
    INTERRUPTED = "interrupted"  # Ctrl-C


class PositionRunner(Protocol):
    """Runs positions: each finished unit's record goes to ``finished`` as
    it comes (its folder moved into place when done), simulated seconds to
    ``progress`` as they pass."""

    def run(
        self, tasks: list[Task], folder: CampaignFolder, progress: Progress | None, finished: Finished
    ) -> RunEnd: ...


def select_positions(text: str | None) -> list[Position]:
    """``all`` (or None), or labels separated by commas, e.g. ``0,X+15,Y-30``."""
    known = [Position(label, x, y, index) for index, (label, x, y) in enumerate(campaign_positions())]
    if text is None or text.strip() == "all":
        return known
    by_label = {position.label: position for position in known}
    labels = [label.strip() for label in text.split(",") if label.strip()]
    if not labels:
        raise CampaignError("--positions names no position; use all or labels like 0,X+15,Y-30")
    unknown = [label for label in labels if label not in by_label]
    if unknown:
        raise CampaignError(
            f"unknown position(s) {', '.join(unknown)}; use labels like 0, X+5, X-45, Y+30 "
            f"(the paper's: 0 and +-5..45 in 5 deg steps on X and Y)"
        )
    duplicates = sorted({label for label in labels if labels.count(label) > 1})
    if duplicates:
        raise CampaignError(f"position(s) {', '.join(duplicates)} listed twice")
    return [by_label[label] for label in labels]


def program_settings(options: ScenarioOptions) -> dict[str, Any]:
    """The chamber program every position runs, as campaign.json states it."""
    return {
        "start_c": CALIBRATION_MIN_C,
        "max_c": CALIBRATION_MAX_C,
        "step_c": PAPER_STEP_C,
        "hold_s": options.hold_s,
        "rest_s": options.rest_s,
        "hold_start": options.hold_start,
        "controller": options.controller,
        "ambient_c": options.ambient_c,
    }


def campaign_header(rig: str, options: ScenarioOptions, unit: Unit, **details: Any) -> dict[str, Any]:
    """A unit's campaign.json settings: what --resume must find the same."""
    header = {"format": FORMAT, "rig": rig, "created_utc": utc_now(), "program": program_settings(options), **details}
    return header | ({"sensor": unit.sensor} if unit.sensor else {})


def failed_records(task: Task, error: str) -> list[PositionRecord]:
    """A position whose runner died or raised: the position failed, not the campaign."""
    position, units = task
    return [
        PositionRecord(
            position.label, position.incl_x_deg, position.incl_y_deg, status=FAILED, error=error, sensor_id=unit.sensor
        )
        for unit in units
    ]


@dataclass(frozen=True)
class CampaignOutcome:
    folder: CampaignFolder
    records: list[PositionRecord]
    interrupted: bool
    batch: bool = False

    def failures(self) -> list[str]:
        # A batch's sensors share each position's chamber run, and so its failure.
        return list(
            dict.fromkeys(f"{record.name()}: {record.error}" for record in self.records if record.status == FAILED)
        )

    def left(self) -> list[str]:
        return [record.name() for record in self.records if record.status != DONE]

    def problem(self) -> str | None:
        """Why the campaign is not complete, as one line; None when it is (or was interrupted)."""
        if self.interrupted:
            return None
        failed = self.failures()
        if failed:
            return f"{len(failed)} position(s) failed: " + "; ".join(failed) + "; fix it, then add --resume"
        left = self.left()
        if left:
            return f"stopped with {len(left)} position(s) to run ({', '.join(left)}); add --resume to run them"
        return None

    def summary(self) -> str:
        if self.interrupted:
            return "kept every finished position; add --resume to run the others"
        what = "sensor positions" if self.batch else "positions"
        per_sensor = " (a folder per sensor)" if self.batch else ""
        return (
            f"all {len(self.records)} {what} done; fit them with: "
            f"thermotilt fit {self.folder.path} --out FIT_DIR{per_sensor}"
        )


class Campaign:
    """Each unit's campaign.json started (or resumed) in its folder;
    ``todo`` the positions some unit has not yet done, which ``run`` hands
    to a runner."""

    def __init__(
        self,
        folder: CampaignFolder,
        positions: list[Position],
        headers: dict[Unit, dict[str, Any]],
        resume: bool,
        force: bool,
    ) -> None:
        self.folder, self.positions = folder, positions
        self.files: dict[Unit, CampaignFile] = {
            unit: folder.sensor(unit.folder).start(header, positions, resume, force) for unit, header in headers.items()
        }
        for file in self.files.values():
            file.save()
        self.todo = [position for position in positions if self.pending_units(position)]
        self.batch = any(unit.folder for unit in self.files)

    @property
    def done(self) -> int:
        return len(self.positions) - len(self.todo)

    def pending_units(self, position: Position) -> tuple[Unit, ...]:
        return tuple(unit for unit, file in self.files.items() if file.records[position.label].status != DONE)

    def records(self) -> list[PositionRecord]:
        return [file.records[p.label] for file in self.files.values() for p in self.positions]

    def run_with(
        self, runner: PositionRunner, progress: Progress | None = None, on_position: Finished | None = None
    ) -> CampaignOutcome:
        def finished(record: PositionRecord) -> None:
            self._save(record)
            if on_position is not None:
                on_position(record)

        tasks = [(position, self.pending_units(position)) for position in self.todo]
        end = runner.run(tasks, self.folder, progress, finished)
        if end is RunEnd.FINISHED:
            for unit in self.files:
                self.folder.sensor(unit.folder).drop_partials()
        return CampaignOutcome(self.folder, self.records(), end is RunEnd.INTERRUPTED, self.batch)

    def _save(self, record: PositionRecord) -> None:
        """The record saved in its sensor's campaign.json (a batch's are
        known by their ID; one sensor's reports whatever ID its board has)."""
        if len(self.files) == 1:
            (file,) = self.files.values()
        else:
            file = next(file for unit, file in self.files.items() if unit.sensor == record.sensor_id)
        file.records[record.label] = record
        file.save()
