"""The campaign folder, as ``thermotilt campaign`` writes it and ``fit``
reads it (docs/calibration.md):

- ``DIR/<label>/``: one run folder per position (run.csv, serial/,
  summary.json), written under ``DIR/.partial/<label>/`` and moved into
  place only when the position is complete, so a folder named after a
  position always holds a whole run;
- ``DIR/campaign.json``: the plan, the settings and per position its
  record (status, seed, start, the boards' firmware, on real boards the
  IMU's sensor ID), rewritten whole after every position, so an interrupted
  campaign keeps every finished position and ``--resume`` redoes the others;
- a batch: ``DIR/batch.json`` names the sensors, each with its own
  campaign folder ``DIR/<id>/``; in the twin ``DIR/model.toml`` is the
  batch's model as it ran.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from ...run.folder import LOG_FILE

CAMPAIGN_FILE = "campaign.json"
BATCH_FILE = "batch.json"
BATCH_MODEL_FILE = "model.toml"
PARTIAL_DIR = ".partial"
FORMAT = 1
DONE, PENDING, INTERRUPTED, FAILED = "done", "pending", "interrupted", "failed"


class CampaignError(RuntimeError):
    """A campaign that cannot start or resume; one readable line."""


@dataclass(frozen=True)
class Position:
    label: str
    incl_x_deg: float
    incl_y_deg: float
    index: int  # among the paper's 37 positions: the seed offset


@dataclass
class PositionRecord:
    label: str
    incl_x_deg: float
    incl_y_deg: float
    status: str = PENDING
    seed: int | None = None
    started_utc: str | None = None
    sim_seconds: float | None = None
    wall_seconds: float | None = None
    firmware: dict[str, str] = field(default_factory=dict)
    reported_errors: list[str] = field(default_factory=list)
    error: str | None = None
    # The IMU's sensor ID as its ICF gave it ("" none); None where the
    # campaign did not ask (the twin, a campaign from before IDs).
    sensor_id: str | None = None

    @classmethod
    def started(cls, position: Position, sensor_id: str | None, seed: int | None = None) -> PositionRecord:
        return cls(
            position.label,
            position.incl_x_deg,
            position.incl_y_deg,
            seed=seed,
            started_utc=utc_now(),
            sensor_id=sensor_id,
        )

    def name(self) -> str:
        """The position's label, after its sensor's ID where it has one."""
        return f"{self.sensor_id} {self.label}" if self.sensor_id else self.label

    def line(self) -> str:
        """One line of what became of the position."""
        line = f"{self.name()}: {self.status}"
        if self.status == DONE:
            line += f" in {self.wall_seconds:.0f} s"
        if self.error:
            line += f" ({self.error})"
        return line


def utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


class CampaignFile:
    """campaign.json: written whole to a temporary file and renamed, so a
    crash leaves the previous version, never half of one."""

    def __init__(self, folder: CampaignFolder, header: dict[str, Any], records: list[PositionRecord]):
        self.path = folder.path / CAMPAIGN_FILE
        self.header = header
        self.records = {record.label: record for record in records}

    @classmethod
    def start(
        cls, folder: CampaignFolder, header: dict[str, Any], positions: list[Position], resume: bool, force: bool
    ) -> CampaignFile:
        path = folder.path / CAMPAIGN_FILE
        fresh = [PositionRecord(p.label, p.incl_x_deg, p.incl_y_deg) for p in positions]
        if not path.exists():
            if resume:
                raise CampaignError(f"nothing to resume: {path} does not exist")
            return cls(folder, header, fresh)
        if force:
            for record in fresh:
                shutil.rmtree(folder.path / record.label, ignore_errors=True)
            return cls(folder, header, fresh)
        if not resume:
            raise CampaignError(f"{path} exists; add --resume to finish that campaign or --force to start again")
        return cls._resumed(folder, header, fresh)

    @classmethod
    def _resumed(cls, folder: CampaignFolder, header: dict[str, Any], fresh: list[PositionRecord]) -> CampaignFile:
        path = folder.path / CAMPAIGN_FILE
        try:
            earlier = json.loads(path.read_text())
            settings = {key: earlier[key] for key in header if key != "created_utc"}
            records = [PositionRecord(**entry) for entry in earlier["positions"]]
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise CampaignError(f"cannot resume from {path}: {error}") from None
        wanted = {key: value for key, value in header.items() if key != "created_utc"}
        changed = [key for key in wanted if settings[key] != wanted[key]]
        if changed:
            raise CampaignError(
                f"cannot resume {folder.path}: its {', '.join(changed)} differ from this "
                f"command's; give the same settings or start again with --force"
            )
        known = {record.label for record in records}
        records += [record for record in fresh if record.label not in known]
        campaign = cls(folder, {**header, "created_utc": earlier.get("created_utc")}, records)
        for record in campaign.records.values():
            if record.status == DONE and not folder.position_done(record.label):
                record.status = PENDING
        campaign.sensor_id()
        return campaign

    def sensor_id(self) -> str | None:
        """The sensor ID the done positions were logged with; None if none recorded one."""
        return _one_sensor_id(self.path, [asdict(record) for record in self.records.values()])

    def save(self) -> None:
        document = {**self.header, "positions": [asdict(record) for record in self.records.values()]}
        temporary = self.path.with_name(self.path.name + ".tmp")
        temporary.write_text(json.dumps(document, indent=2) + "\n")
        os.replace(temporary, self.path)


def _one_sensor_id(path: Path, positions: list[Any]) -> str | None:
    recorded = {
        entry["sensor_id"]
        for entry in positions
        if isinstance(entry, dict) and entry.get("status") == DONE and entry.get("sensor_id") is not None
    }
    if len(recorded) > 1:
        names = ", ".join(repr(sensor_id) for sensor_id in sorted(recorded))
        raise CampaignError(
            f"{path}: its positions were logged with different sensors ({names}); one campaign is one sensor's"
        )
    return next(iter(recorded), None)


class CampaignFolder:
    """DIR of a campaign: its position folders, the partial ones a running
    campaign writes, campaign.json, and for a batch each sensor's campaign
    folder and batch.json."""

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"CampaignFolder({str(self.path)!r})"

    def sensor(self, sensor_id: str) -> CampaignFolder:
        """A batch sensor's own campaign folder ("" for this one)."""
        return CampaignFolder(self.path / sensor_id) if sensor_id else self

    def create(self) -> None:
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise CampaignError(f"cannot create {self.path}: {error.strerror or error}") from None

    def start(
        self, header: dict[str, Any], positions: list[Position], resume: bool = False, force: bool = False
    ) -> CampaignFile:
        """campaign.json for these positions: a new one, or the earlier one to resume."""
        self.create()
        return CampaignFile.start(self, header, positions, resume, force)

    def position_done(self, label: str) -> bool:
        return (self.path / label / LOG_FILE).exists()

    def partial(self, label: str) -> Path:
        """An empty folder for a position about to run."""
        partial = self.path / PARTIAL_DIR / label
        shutil.rmtree(partial, ignore_errors=True)
        partial.mkdir(parents=True)
        return partial

    def keep(self, label: str) -> None:
        """The complete position from .partial/ into its own folder."""
        final = self.path / label
        shutil.rmtree(final, ignore_errors=True)
        os.replace(self.path / PARTIAL_DIR / label, final)

    def drop_partials(self) -> None:
        shutil.rmtree(self.path / PARTIAL_DIR, ignore_errors=True)

    def recorded_sensor_id(self) -> str | None:
        """The sensor ID campaign.json says its done positions were logged
        with ("" for a board without one); None when there is no
        campaign.json or it recorded none. CampaignError when it cannot be
        read or names two."""
        path = self.path / CAMPAIGN_FILE
        try:
            document = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None
        except (OSError, ValueError) as error:
            raise CampaignError(f"cannot read {path}: {error}") from None
        positions = document.get("positions") if isinstance(document, dict) else None
        if not isinstance(positions, list):
            raise CampaignError(f"{path}: not a campaign file (no list of positions)")
        sensor_id = _one_sensor_id(path, positions)
        if sensor_id is not None and not isinstance(sensor_id, str):
            raise CampaignError(f"{path}: sensor_id {sensor_id!r} is not text")
        return sensor_id

    def batch(self) -> tuple[str, ...]:
        """The sensors a batch campaign folder holds (its BATCH_FILE), none
        for a single sensor's; ValueError, one line, for a BATCH_FILE that is
        not one."""
        path = self.path / BATCH_FILE
        if not path.is_file():
            return ()
        try:
            sensors = json.loads(path.read_text(encoding="utf-8"))["sensors"]
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise ValueError(f"{path}: not a batch file ({error})") from None
        if not isinstance(sensors, list) or not all(isinstance(s, str) and s for s in sensors):
            raise ValueError(f"{path}: sensors must be a list of sensor IDs")
        return tuple(sensors)

    def check_batch(self, sensors: Iterable[str | None]) -> None:
        """CampaignError unless the batch this folder holds (if any) is these sensors."""
        if not (self.path / BATCH_FILE).is_file():
            return
        try:
            earlier = self.batch()
        except ValueError as error:
            raise CampaignError(str(error)) from None
        sensors = tuple(sensors)
        if sorted(earlier) != sorted(sensors):
            raise CampaignError(
                f"cannot resume {self.path}: its batch is {', '.join(earlier)}, this command's "
                f"{', '.join(sensors)}; give the same sensors or start again with --force"
            )

    def write_batch(self, sensors: Iterable[str | None], details: dict[str, Any], model: Any = None) -> None:
        """BATCH_FILE, which sensors the folder holds (one campaign folder
        each) with the details given, and in the twin the batch's model as it runs."""
        from ...physics.document import write_model

        document = {"format": FORMAT, "sensors": list(sensors), **details}
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            if model is not None:
                document.update(model=model.source, model_file=BATCH_MODEL_FILE)
                write_model(
                    model,
                    self.path / BATCH_MODEL_FILE,
                    f"The model of this batch campaign as it ran ({model.source}), each sensor's terms in "
                    "[[sensors]]:\nthermotilt compare FIT/<id> --reference this file compares a sensor's fit with "
                    "its own drift.",
                )
            (self.path / BATCH_FILE).write_text(json.dumps(document, indent=2) + "\n")
        except OSError as error:
            raise CampaignError(f"cannot write {error.filename or self.path}: {error.strerror or error}") from None
