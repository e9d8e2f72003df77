"""What the live view shows of a folder, read from the files a campaign or
a run writes (calibration/campaign/folder.py, docs/run-log.md) and nothing
else, as plain JSON-able snapshots; no web code.

- a campaign, DIR/campaign.json: its plan, each position's record and, for
  the position being run, DIR/.partial/<label>/run.csv as it grows (then
  DIR/<label>/run.csv, the same file moved);
- a batch, DIR/batch.json: the same for each sensor's campaign in DIR/<ID>/;
  the chamber is the one all the sensors share;
- a run folder (``thermotilt simulate``): its run.csv and, once it ended,
  its summary.json.

``snapshot(cursors)`` gives the whole view and, per sensor, the rows of the
current position's log after the cursor the reader holds: an increment for
a reader that has the rest, everything for a new one.
"""

from __future__ import annotations

import json
import math
import re
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..calibration.campaign.folder import (
    BATCH_FILE,
    CAMPAIGN_FILE,
    DONE,
    FAILED,
    INTERRUPTED,
    PARTIAL_DIR,
    PENDING,
    CampaignFolder,
)
from ..run.folder import IMU_BOARD, LOG_FILE
from ..run.summary import CHAMBER_FAULT, SUMMARY_FILE, RunSummaryError, read_summary
from .registry_lines import REGISTRY_COLUMNS, RegistryLine
from .tail import PositionTail

CAMPAIGN, BATCH, RUN = "campaign", "batch", "run"
RUNNING = "running"
FINISHED = (DONE, FAILED)
# A .partial log that has not grown for this long is a position whose campaign stopped.
STALE_S = 60.0
# Folders are read again at most this often, however many pages ask.
REFRESH_S = 0.4
# A running position's share done is its log's time over the program's
# nominal length; a program that waits for its setpoints runs longer.
MOST_DONE_WHILE_RUNNING = 0.95
# The twin's and the logger's reported errors end "at T s", T the run's time.
_REPORTED_AT = re.compile(r" at (-?[0-9.]+) s$")

Cursors = dict[str, tuple[str, int]]
RegistryLookup = Callable[[Sequence[str]], dict[str, RegistryLine | None]]


class WatchError(ValueError):
    """A folder that holds no campaign and no run; one readable line."""


def folder_kind(path: Path) -> str:
    """BATCH, CAMPAIGN or RUN, from the files path holds; WatchError otherwise."""
    if not path.exists():
        raise WatchError(f"{path}: no such folder")
    if not path.is_dir():
        raise WatchError(f"{path}: not a folder (give a campaign folder or a run folder)")
    if (path / BATCH_FILE).is_file():
        return BATCH
    if (path / CAMPAIGN_FILE).is_file():
        return CAMPAIGN
    if (path / LOG_FILE).is_file():
        return RUN
    raise WatchError(
        f"{path}: neither a campaign folder ({CAMPAIGN_FILE} or {BATCH_FILE}) nor a run folder ({LOG_FILE})"
    )


def nominal_program_seconds(program: dict[str, Any]) -> float | None:
    """The chamber program's length with every hold timed: its steps'
    holds and the rest (campaign.json's "program"); None if it cannot say."""
    from ..twin.scenarios import program_steps

    try:
        steps = program_steps(float(program["start_c"]), float(program["max_c"]), float(program["step_c"]))
        return steps * float(program["hold_s"]) + float(program["rest_s"])
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None


def campaign_eta_seconds(
    finished_wall_s: Sequence[float],
    unfinished: int,
    running_done_shares: Sequence[float],
    position_s_from_pace: float | None,
) -> float | None:
    """Wall seconds until the campaign ends, by this rule:

    ETA = (positions not finished - the shares done of those running)
          x seconds per position / positions running at once (at least 1),

    seconds per position being the mean wall seconds of the finished
    (done or failed) positions, else, before any finished, the program's
    nominal length over the running log's pace (run seconds per wall
    second). A running position's share done is its log's time over the
    program's nominal length, at most MOST_DONE_WHILE_RUNNING. 0 when every
    position finished; None when nothing runs (a stopped campaign) or
    neither figure is known yet."""
    if unfinished == 0:
        return 0.0
    if not running_done_shares:
        return None
    per_position_s = sum(finished_wall_s) / len(finished_wall_s) if finished_wall_s else position_s_from_pace
    if per_position_s is None:
        return None
    left = max(0.0, unfinished - sum(running_done_shares))
    return left * per_position_s / len(running_done_shares)


def split_reported(error: str) -> tuple[str, float | None]:
    """A reported error, "CODE DETAIL at T s", as its text and T."""
    match = _REPORTED_AT.search(error)
    return (error[: match.start()], float(match[1])) if match else (error, None)


def _fault(kind: str, label: str, sensor_id: str, board: str, t_s: float | None, text: str) -> dict[str, Any]:
    """A fault as the page lists it; t_s on the chart's axis (from the log's first row)."""
    return {
        "kind": kind,
        "position": label,
        "sensor": sensor_id,
        "board": board,
        "t_s": t_s,
        "text": text,
        "seen_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return document if isinstance(document, dict) else None


@dataclass
class SensorCampaign:
    """One sensor's campaign folder and its campaign.json as last read
    (a rewrite is atomic; a read that fails keeps the one before)."""

    sensor_id: str
    folder: CampaignFolder
    document: dict[str, Any] = field(default_factory=dict)

    def load(self) -> None:
        document = _read_json(self.folder.path / CAMPAIGN_FILE)
        if document is not None and isinstance(document.get("positions"), list):
            self.document = document

    def records(self) -> dict[str, dict[str, Any]]:
        return {
            entry["label"]: entry
            for entry in self.document.get("positions", [])
            if isinstance(entry, dict) and isinstance(entry.get("label"), str)
        }

    def recorded_sensor_id(self) -> str:
        """The campaign's sensor: batch.json's, campaign.json's, else what its positions were logged with."""
        if self.sensor_id:
            return self.sensor_id
        named = self.document.get("sensor") or next(
            (entry.get("sensor_id") for entry in self.records().values() if entry.get("sensor_id")), ""
        )
        return named if isinstance(named, str) else ""

    def position_folder(self, label: str) -> Path | None:
        """The position's run folder: being written in .partial/, or in place."""
        for folder in (self.folder.path / PARTIAL_DIR / label, self.folder.path / label):
            if (folder / LOG_FILE).is_file():
                return folder
        return None

    def partial_growing(self, label: str, now: float) -> bool:
        """The position's log in .partial/ grew within STALE_S: it runs, or
        it just failed (its last bytes, the fault among them, still to read)."""
        return growing(self.folder.path / PARTIAL_DIR / label / LOG_FILE, now)

    def running(self, label: str, now: float) -> bool:
        return self.records().get(label, {}).get("status") not in FINISHED and self.partial_growing(label, now)


def growing(log: Path, now: float) -> bool:
    """A log written to within STALE_S."""
    try:
        return now - log.stat().st_mtime < STALE_S
    except OSError:
        return False


def _position_status(statuses: Iterable[str], running: bool) -> str:
    """A position's status over the sensors that share its chamber run."""
    statuses = list(statuses)
    if running:
        return RUNNING
    for status in (FAILED, INTERRUPTED):
        if status in statuses:
            return status
    return DONE if statuses and all(status == DONE for status in statuses) else PENDING


class FolderState:
    """The live view of one folder. ``refresh`` reads what changed (at most
    every REFRESH_S), ``snapshot`` says it; both are safe to call from
    several threads. A folder that holds nothing yet (a campaign about to
    start) is looked at again on every refresh."""

    def __init__(self, path: Path | str, registry_lines: RegistryLookup | None = None) -> None:
        self.path = Path(path)
        self.kind: str | None = None
        self._registry_lines = registry_lines
        self._lock = threading.Lock()
        self._refreshed_at = -math.inf
        self._sensors: list[SensorCampaign] = []
        self._tails: dict[tuple[str, str], PositionTail] = {}
        self._faults: dict[tuple[Any, ...], dict[str, Any]] = {}
        self._view: dict[str, Any] = {}
        self._current: str | None = None
        self._problem: str | None = None

    def refresh(self, max_age_s: float = REFRESH_S) -> None:
        with self._lock:
            if time.monotonic() - self._refreshed_at < max_age_s:
                return
            self._refreshed_at = time.monotonic()
            try:
                self.kind = self.kind or folder_kind(self.path)
                if self.kind == RUN:
                    self._refresh_run()
                else:
                    self._refresh_campaign()
            except WatchError as error:
                self._problem = str(error)
                return
            except (OSError, ValueError, KeyError, TypeError) as error:
                # A file the view cannot read now (moved away, written by another
                # version) is said on the page; the next refresh tries again.
                self._problem = f"cannot read {self.path}: {error}"
                return
            self._problem = None

    def snapshot(self, cursors: Cursors | None = None) -> tuple[dict[str, Any], Cursors]:
        """The view, with each sensor's rows after its cursor (all of them
        for a cursor of another position or log), and the cursors after them."""
        cursors = dict(cursors or {})
        with self._lock:
            series = []
            for sensor_id in self._sensor_ids():
                position = self._tails.get((sensor_id, self._current or ""))
                if position is None:
                    continue
                tail = position.log
                key = f"{self._current}#{tail.generation}"
                known_key, known_rows = cursors.get(sensor_id, ("", 0))
                start = known_rows if known_key == key and known_rows <= tail.rows else 0
                series.append(
                    {
                        "sensor": sensor_id,
                        "key": key,
                        "start": start,
                        "rows": tail.rows,
                        "columns": {name: values[start:] for name, values in tail.series.items()},
                    }
                )
                cursors[sensor_id] = (key, tail.rows)
            document = {
                "folder": str(self.path),
                "kind": self.kind,
                "problem": self._problem,
                "registry_columns": REGISTRY_COLUMNS,
                "updated_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                **self._view,
                "faults": list(self._faults.values()),
                "series": series,
            }
        return document, cursors

    def _sensor_ids(self) -> list[str]:
        return [sensor.sensor_id for sensor in self._sensors] or [""]

    def _sensor_campaigns(self) -> list[SensorCampaign]:
        """The campaign's sensors: batch.json's, each in its folder, or DIR's one."""
        folder = CampaignFolder(self.path)
        try:
            sensor_ids = folder.batch() if self.kind == BATCH else ()
        except ValueError:
            sensor_ids = ()
        wanted = [(sensor_id, folder.sensor(sensor_id)) for sensor_id in sensor_ids] or [("", folder)]
        known = {(sensor.sensor_id, sensor.folder.path): sensor for sensor in self._sensors}
        return [known.get((sensor_id, sub.path)) or SensorCampaign(sensor_id, sub) for sensor_id, sub in wanted]

    def _refresh_campaign(self) -> None:
        self._sensors = self._sensor_campaigns()
        for sensor in self._sensors:
            sensor.load()
        records = [sensor.records() for sensor in self._sensors]
        plan = next((list(by_label) for by_label in records if by_label), [])
        now = time.time()
        running = [label for label in plan if any(sensor.running(label, now) for sensor in self._sensors)]
        self._current = self._current_position(plan, running, records)
        watched = {
            self._current,
            *(label for label in plan if any(s.partial_growing(label, now) for s in self._sensors)),
        }
        for sensor in self._sensors:
            for label in watched:
                folder = sensor.position_folder(label) if label else None
                if folder is not None:
                    self._tails.setdefault((sensor.sensor_id, label), PositionTail()).poll(folder)
        self._tails = {key: tail for key, tail in self._tails.items() if key[1] in watched}
        self._note_tail_faults()
        self._note_record_faults(records)
        self._view = self._campaign_view(plan, running, records)

    @staticmethod
    def _current_position(plan: list[str], running: list[str], records: list[dict[str, dict[str, Any]]]) -> str | None:
        """The first position running, else the one started last, else the first."""
        if running:
            return running[0]
        started = [
            (entry.get("started_utc") or "", index, label)
            for index, label in enumerate(plan)
            for by_label in records
            if (entry := by_label.get(label)) and entry.get("status") != PENDING and entry.get("started_utc")
        ]
        if started:
            return max(started)[2]
        return plan[0] if plan else None

    def _note_tail_faults(self) -> None:
        """What the followed logs and captures show: the chamber's latched
        fault (once per position: a batch's sensors share the chamber) and
        each board's own errors, placed at the log's last row when read."""
        for (sensor_id, label), tail in self._tails.items():
            for t_s, token in tail.log.faults:
                self._note_fault(("chamber", label, token), _fault("chamber", label, "", "", t_s, token))
            for board, capture in tail.captures.items():
                # The board's ERR comes before the CHS that shows the fault latched.
                errors = [(error, tail.log.run_seconds) for error in capture.errors]
                self._note_board_errors(label, sensor_id, board, errors)
                if capture.latched:
                    fault = _fault("chamber", label, "", "", tail.log.run_seconds, capture.latched)
                    self._note_fault(("chamber", label, capture.latched), fault)

    def _note_board_errors(
        self, label: str, sensor_id: str, board: str, errors: list[tuple[str, float | None]], exact: bool = False
    ) -> None:
        """A board's errors in a position, in order: the n-th of the same
        text is one error whether a capture or campaign.json told it first."""
        who = sensor_id if board == IMU_BOARD else ""
        seen: Counter[str] = Counter()
        for text, t_s in errors:
            seen[text] += 1
            self._note_fault(
                ("board", label, who, board, text, seen[text]), _fault("board", label, who, board, t_s, text), exact
            )

    def _note_record_faults(self, records: list[dict[str, dict[str, Any]]]) -> None:
        for sensor, by_label in zip(self._sensors, records):
            for label, entry in by_label.items():
                by_board: dict[str, list[tuple[str, float | None]]] = {}
                for error in entry.get("reported_errors") or []:
                    board, _, reported = str(error).rpartition(": ")
                    by_board.setdefault(board, []).append(split_reported(reported))
                for board, errors in by_board.items():
                    self._note_board_errors(label, sensor.sensor_id, board, errors, exact=True)
                if entry.get("status") == FAILED:
                    # The position's error: a batch's sensors share its chamber run, and so its failure.
                    error = str(entry.get("error") or "failed")
                    self._note_fault(("failed", label, error), _fault("failed", label, "", "", None, error))

    def _note_fault(self, key: tuple[Any, ...], fault: dict[str, Any], exact: bool = False) -> None:
        """A fault not seen before; one seen before gets the exact time when given it."""
        known = self._faults.get(key)
        if known is None:
            self._faults[key] = {"id": len(self._faults) + 1, **fault}
        elif exact and fault["t_s"] is not None:
            known["t_s"] = fault["t_s"]

    def _campaign_view(
        self, plan: list[str], running: list[str], records: list[dict[str, dict[str, Any]]]
    ) -> dict[str, Any]:
        first = self._sensors[0].document if self._sensors else {}
        positions = []
        for index, label in enumerate(plan, start=1):
            entries = [by_label[label] for by_label in records if label in by_label]
            status = _position_status((entry.get("status", PENDING) for entry in entries), label in running)
            walls = [entry["wall_seconds"] for entry in entries if isinstance(entry.get("wall_seconds"), int | float)]
            example = entries[0] if entries else {}
            positions.append(
                {
                    "k": index,
                    "label": label,
                    "status": status,
                    "incl_x_deg": example.get("incl_x_deg"),
                    "incl_y_deg": example.get("incl_y_deg"),
                    "wall_seconds": max(walls) if walls else None,
                }
            )
        current = next((position for position in positions if position["label"] == self._current), None)
        return {
            "title": self.path.name or str(self.path),
            "rig": first.get("rig"),
            "program": first.get("program"),
            "positions": positions,
            "current": None if current is None else {**current, "n": len(plan)},
            "eta_s": self._eta(positions, running, first.get("program") or {}),
            "sensors": self._sensor_rows([(sensor.sensor_id, sensor.recorded_sensor_id()) for sensor in self._sensors]),
        }

    def _eta(self, positions: list[dict[str, Any]], running: list[str], program: dict[str, Any]) -> float | None:
        program_s = nominal_program_seconds(program)
        finished = [position for position in positions if position["status"] in FINISHED]
        shares, paces = [], []
        for label in running:
            position = self._tails.get((self._sensor_ids()[0], label))
            if position is None:
                shares.append(0.0)
                continue
            tail = position.log
            shares.append(min(MOST_DONE_WHILE_RUNNING, tail.run_seconds / program_s) if program_s else 0.0)
            if (pace := tail.pace()) is not None:
                paces.append(pace)
        from_pace = program_s / (sum(paces) / len(paces)) if program_s and paces else None
        walls = [position["wall_seconds"] for position in finished if position["wall_seconds"] is not None]
        return campaign_eta_seconds(walls, len(positions) - len(finished), shares, from_pace)

    def _sensor_rows(self, sensors: list[tuple[str, str]]) -> list[dict[str, Any]]:
        """Each sensor's row: its key (the series' "sensor"), its ID ("" none known) and its registry line."""
        named = [sensor_id for _key, sensor_id in sensors if sensor_id]
        lines = self._registry_lines(named) if self._registry_lines and named else {}
        return [{"key": key, "id": sensor_id, "registry": lines.get(sensor_id)} for key, sensor_id in sensors]

    def _refresh_run(self) -> None:
        self._sensors = []
        # The run is its own one position, named after its folder.
        self._current = self.path.name
        tail = self._tails.setdefault(("", self._current), PositionTail())
        tail.poll(self.path)
        self._note_tail_faults()
        summary = self._run_summary()
        if summary is not None:
            status = FAILED if any(fault["kind"] == "failed" for fault in self._faults.values()) else DONE
        elif growing(self.path / LOG_FILE, time.time()):
            status = RUNNING
        else:
            status = INTERRUPTED if tail.log.rows else PENDING
        self._view = {
            "title": self.path.name or str(self.path),
            "rig": None if summary is None else summary.source,
            "program": None,
            "positions": [],
            "current": {"k": None, "n": None, "label": self.path.name, "status": status},
            "eta_s": None,
            "sensors": self._sensor_rows([("", "")]),
        }

    def _run_summary(self) -> Any:
        """summary.json once the run wrote it; its reported errors and a
        chamber fault that ended it noted as faults."""
        if not (self.path / SUMMARY_FILE).is_file():
            return None
        try:
            summary = read_summary(self.path)
        except RunSummaryError:
            return None
        name = self.path.name
        for board, report in summary.boards.items():
            errors = [split_reported(error) for error in report.reported_errors]
            self._note_board_errors(name, "", board, errors, exact=True)
        reason = summary.end_reason or ""
        if reason.startswith(CHAMBER_FAULT):
            error = f"the program ended early: {reason}"
            self._note_fault(("failed", name, error), _fault("failed", name, "", "", None, error))
        return summary
