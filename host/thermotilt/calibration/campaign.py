"""``thermotilt campaign``: the paper's calibration (section 3.2) — the tilt
table at each position, each through a full -10 -> 45 -> -10 degC staircase.

Every position is its own run folder, ``DIR/<label>/`` with run.csv,
serial/ and summary.json, written under ``DIR/.partial/`` and moved into
place only when the position is complete, so a folder named after a position
always holds a whole run and ``thermotilt fit DIR`` never sees half of one.
``DIR/campaign.json`` records the plan, the settings, and per position its
status, seed, start time, the firmware versions the boards reported and,
on real boards, the IMU's sensor ID (ICF's sensor_id, "" for none);
it is rewritten after every position, so an interrupted campaign keeps every
finished position and ``--resume`` redoes only the others.

A batch (a model's [[sensors]], or sensors drawn about it) is one campaign
per sensor, ``DIR/<id>/``, beside ``DIR/batch.json``; the table carries
them all, so each position is one chamber run driving every sensor's IMU
board.

In the twin positions are independent runs, so they run in parallel worker
processes, or on the workers of a Dask cluster (``--scheduler``), which send
each position's files back to be written here the same way. Each position's
noise seed is the campaign's seed plus the position's index among the
paper's 37 (plus a number from a batch sensor's ID), so a subset
reproduces the same positions of the full campaign.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import queue
import shutil
import signal
import tempfile
import threading
import time
import uuid
import zlib
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import ExitStack
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..ctrl_c import ctrl_c_as_flag
from ..program import CALIBRATION_MAX_C, CALIBRATION_MIN_C, PAPER_STEP_C
from ..run.summary import CHAMBER_FAULT, PROGRAM_DONE
from ..run.summary import INTERRUPTED as RUN_INTERRUPTED
from ..twin.scenarios import ScenarioError, ScenarioOptions, campaign_positions, cycle

if TYPE_CHECKING:
    from distributed import Client

CAMPAIGN_FILE = "campaign.json"
# A batch campaign's folder: which sensors it holds, each in FOLDER/ID/, and
# in the twin the batch's model as it ran (its [[sensors]], drawn or given).
BATCH_FILE = "batch.json"
BATCH_MODEL_FILE = "model.toml"
PARTIAL_DIR = ".partial"
FORMAT = 1
SEED_MODULUS = 2**64
DONE, PENDING, INTERRUPTED, FAILED = "done", "pending", "interrupted", "failed"
# A running position on a Dask worker asks the scheduler this often whether to stop.
STOP_POLL_S = 1.0
# A worker process looks this often whether its campaign is still there.
ORPHAN_POLL_S = 1.0


class CampaignError(RuntimeError):
    """A campaign that cannot start or resume; one readable line."""


@dataclass(frozen=True)
class Position:
    label: str
    incl_x_deg: float
    incl_y_deg: float
    index: int  # among the paper's 37 positions: the seed offset


@dataclass(frozen=True)
class TwinSetup:
    """Everything a worker process needs to run one position in the twin;
    plain data, because a loaded model does not cross process boundaries."""

    options: ScenarioOptions
    seed: int = 1
    model_path: str | None = None
    enable: tuple[str, ...] = ()
    disable: tuple[str, ...] = ()
    # One sensor of the model's batch, and a batch of this many drawn about
    # the model (seeded by seed) instead of its [[sensors]].
    sensor: str | None = None
    population: int = 0

    def batch_model(self) -> Any:
        from ..physics import Model

        model = Model.load(self.model_path)
        return model.with_population(self.population, self.seed) if self.population else model

    def chamber_model(self) -> Any:
        """The model as loaded and switched, with the chamber's terms every
        sensor of its batch shares."""
        changes = {name: True for name in self.enable} | {name: False for name in self.disable}
        return self.batch_model().with_terms(changes)

    def models(self, units: Sequence[Unit]) -> tuple[Any, dict[Unit, Any]]:
        """The chamber's model and each unit's sensor model (the model
        itself for a unit without an ID), from one load of the model file."""
        chamber = self.chamber_model()
        return chamber, {unit: chamber.for_sensor(unit.sensor) if unit.sensor else chamber for unit in units}

    def units(self) -> tuple[Unit, ...]:
        """The sensors a campaign with this setup calibrates: a batch's
        (each its campaign in DIR/<id>/), or one in DIR."""
        if self.sensor:
            self.chamber_model().for_sensor(self.sensor)
            return (Unit(self.sensor, ""),)
        return tuple(Unit(sensor_id, sensor_id) for sensor_id in self.batch_model().sensor_ids) or (Unit(None, ""),)

    def position_seed(self, position: Position, sensor: str | None = None) -> int:
        # Each sensor of a batch its own draws, the same for the same ID.
        sensor = sensor or self.sensor
        offset = zlib.crc32(sensor.encode()) if sensor else 0
        return (self.seed + position.index + offset) % SEED_MODULUS


@dataclass(frozen=True)
class Unit:
    """One sensor a campaign calibrates: its ID (None for a model's only
    sensor) and its campaign's folder inside the campaign's ("" for DIR)."""

    sensor: str | None
    folder: str


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


class CampaignFile:
    """campaign.json: written whole to a temporary file and renamed, so a
    crash leaves the previous version, never half of one."""

    def __init__(self, out_dir: Path, header: dict[str, Any], records: list[PositionRecord]):
        self.path = out_dir / CAMPAIGN_FILE
        self.header = header
        self.records = {record.label: record for record in records}

    @classmethod
    def start(
        cls, out_dir: Path, header: dict[str, Any], positions: list[Position], resume: bool, force: bool
    ) -> CampaignFile:
        path = out_dir / CAMPAIGN_FILE
        fresh = [PositionRecord(p.label, p.incl_x_deg, p.incl_y_deg) for p in positions]
        if not path.exists():
            if resume:
                raise CampaignError(f"nothing to resume: {path} does not exist")
            return cls(out_dir, header, fresh)
        if force:
            for record in fresh:
                shutil.rmtree(out_dir / record.label, ignore_errors=True)
            return cls(out_dir, header, fresh)
        if not resume:
            raise CampaignError(f"{path} exists; add --resume to finish that campaign or --force to start again")
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
                f"cannot resume {out_dir}: its {', '.join(changed)} differ from this "
                f"command's; give the same settings or start again with --force"
            )
        known = {record.label for record in records}
        records += [record for record in fresh if record.label not in known]
        campaign = cls(out_dir, {**header, "created_utc": earlier.get("created_utc")}, records)
        for record in campaign.records.values():
            if record.status == DONE and not (out_dir / record.label / "run.csv").exists():
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


def recorded_sensor_id(folder: Path) -> str | None:
    """The sensor ID FOLDER/campaign.json says its done positions were logged
    with ("" for a board without one); None when there is no campaign.json or
    it recorded none. CampaignError when it cannot be read or names two."""
    path = folder / CAMPAIGN_FILE
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


def _utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def position_scenario(options: ScenarioOptions, position: Position) -> Any:
    return cycle(replace(options, incl_x_deg=position.incl_x_deg, incl_y_deg=position.incl_y_deg))


def _fresh_partial(out_dir: Path, label: str) -> Path:
    partial = out_dir / PARTIAL_DIR / label
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True)
    return partial


def _move_into_place(out_dir: Path, label: str) -> None:
    """The complete position from .partial/ into its own folder."""
    final = out_dir / label
    shutil.rmtree(final, ignore_errors=True)
    os.replace(out_dir / PARTIAL_DIR / label, final)


# Set in each worker process by _start_worker.
_progress_queue: Any = None
_stop_event: Any = None


def _start_worker(progress_queue: Any, stop_event: Any) -> None:
    global _progress_queue, _stop_event
    _progress_queue, _stop_event = progress_queue, stop_event
    # Ctrl-C reaches the whole process group; the parent decides, and tells
    # the workers through the stop event so each one still writes its summary.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_when_orphaned, args=(os.getppid(),), daemon=True).start()


def _exit_when_orphaned(parent: int) -> None:
    """A worker whose campaign died without telling it (killed, its terminal
    closed) stops: nobody would take its position, and at exit it would
    wait forever on the progress it could not send. The position stays in
    .partial/ for --resume to run again."""
    while os.getppid() == parent:
        time.sleep(ORPHAN_POLL_S)
    os._exit(1)


def _run_in_worker(
    setup: TwinSetup, position: Position, units: tuple[Unit, ...], out_dir: Path
) -> list[PositionRecord]:
    return run_twin_position(setup, position, units, out_dir, _progress_queue, _stop_event)


def run_twin_position(
    setup: TwinSetup,
    position: Position,
    units: tuple[Unit, ...],
    out_dir: Path,
    progress_queue: Any = None,
    stop_event: Any = None,
) -> list[PositionRecord]:
    """One position in the twin, in this process: one chamber run carrying
    each unit's sensor, into each unit's campaign folder; puts the
    simulated seconds into ``progress_queue`` as they pass (a whole
    position's by its end) and stops when ``stop_event`` is set."""
    from ..twin import simulate
    from ..twin.boards import TwinError

    records = [
        PositionRecord(
            position.label,
            position.incl_x_deg,
            position.incl_y_deg,
            seed=setup.position_seed(position, unit.sensor),
            started_utc=_utc_now(),
            # The twin's board holds the ID of the batch's sensor the unit names.
            sensor_id=unit.sensor,
        )
        for unit in units
    ]
    partials = [_fresh_partial(out_dir / unit.folder, position.label) for unit in units]
    reported = 0.0

    def progress(sim_seconds: float) -> None:
        nonlocal reported
        if progress_queue is not None:
            progress_queue.put(sim_seconds - reported)
            reported = sim_seconds
        if stop_event is not None and stop_event.is_set():
            raise KeyboardInterrupt

    scenario = position_scenario(setup.options, position)
    chamber_model, models = setup.models(units)
    imus = [
        simulate.ImuRun(models[unit], partial, record.seed, sensor_id=unit.sensor or "")
        for unit, partial, record in zip(units, partials, records)
    ]
    try:
        summaries = [result.summary for result in simulate.run_sensors(scenario, chamber_model, imus, progress)]
    except (TwinError, simulate.SimulationError, OSError) as error:
        for record in records:
            record.status, record.error = FAILED, str(error)
        return records
    if progress_queue is not None and not summaries[0].interrupted:
        # The run ends with the chamber's program, before the scenario's bound.
        progress_queue.put(scenario.duration_s - reported)
    for unit, record, summary in zip(units, records, summaries):
        _finish_record(record, summary, out_dir / unit.folder)
    return records


def _finish_record(record: PositionRecord, summary: Any, folder: Path) -> None:
    """What the position's run says of it; a done one moved into place."""
    record.sim_seconds = summary.sim_seconds
    record.wall_seconds = summary.wall_seconds
    record.firmware = {
        board: report.firmware for board, report in summary.boards.items() if report.firmware is not None
    }
    record.reported_errors = [
        f"{board}: {error}" for board, report in summary.boards.items() for error in report.reported_errors
    ]
    if summary.interrupted:
        record.status = INTERRUPTED
    elif summary.end_reason.startswith(CHAMBER_FAULT):
        record.status, record.error = FAILED, f"the program ended early: {summary.end_reason}"
    else:
        _move_into_place(folder, record.label)
        record.status = DONE


@dataclass(frozen=True)
class CampaignOutcome:
    records: list[PositionRecord]
    interrupted: bool


class _Campaign:
    """Each unit's campaign.json started (or resumed) in its folder;
    ``todo`` the positions some unit has not yet done."""

    def _start(
        self,
        out_dir: Path,
        positions: list[Position],
        headers: dict[Unit, dict[str, Any]],
        resume: bool,
        force: bool,
    ) -> None:
        self.out_dir, self.positions = out_dir, positions
        self.files: dict[Unit, CampaignFile] = {}
        for unit, header in headers.items():
            folder = out_dir / unit.folder
            try:
                folder.mkdir(parents=True, exist_ok=True)
            except OSError as error:
                raise CampaignError(f"cannot create {folder}: {error.strerror or error}") from None
            self.files[unit] = CampaignFile.start(folder, header, positions, resume, force)
        for file in self.files.values():
            file.save()
        self.todo = [position for position in positions if self.pending_units(position)]

    def pending_units(self, position: Position) -> tuple[Unit, ...]:
        return tuple(unit for unit, file in self.files.items() if file.records[position.label].status != DONE)

    def _finished(self, record: PositionRecord) -> None:
        """The record saved in its sensor's campaign.json (a batch's are
        known by their ID; one sensor's reports whatever ID its board has)."""
        if len(self.files) == 1:
            (file,) = self.files.values()
        else:
            file = next(file for unit, file in self.files.items() if unit.sensor == record.sensor_id)
        file.records[record.label] = record
        file.save()

    def records(self) -> list[PositionRecord]:
        return [file.records[p.label] for file in self.files.values() for p in self.positions]


def check_same_batch(out_dir: Path, units: tuple[Unit, ...]) -> None:
    """CampaignError unless the batch out_dir holds (if any) is these sensors."""
    if not (out_dir / BATCH_FILE).is_file():
        return
    try:
        earlier = batch_of(out_dir)
    except ValueError as error:
        raise CampaignError(str(error)) from None
    sensors = tuple(unit.sensor for unit in units)
    if sorted(earlier) != sorted(sensors):
        raise CampaignError(
            f"cannot resume {out_dir}: its batch is {', '.join(earlier)}, this command's "
            f"{', '.join(sensors)}; give the same sensors or start again with --force"
        )


def write_batch(out_dir: Path, units: tuple[Unit, ...], details: dict[str, Any], model: Any = None) -> None:
    """BATCH_FILE, which sensors the folder holds (one campaign folder
    each) with the details given, and in the twin the batch's model as it runs."""
    from ..physics.document import write_model

    document = {"format": FORMAT, "sensors": [unit.sensor for unit in units], **details}
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        if model is not None:
            document.update(model=model.source, model_file=BATCH_MODEL_FILE)
            write_model(
                model,
                out_dir / BATCH_MODEL_FILE,
                f"The model of this batch campaign as it ran ({model.source}), each sensor's terms in "
                "[[sensors]]:\nthermotilt compare FIT/<id> --reference this file compares a sensor's fit with "
                "its own drift.",
            )
        (out_dir / BATCH_FILE).write_text(json.dumps(document, indent=2) + "\n")
    except OSError as error:
        raise CampaignError(f"cannot write {error.filename or out_dir}: {error.strerror or error}") from None


def batch_of(folder: Path) -> tuple[str, ...]:
    """The sensors a batch campaign folder holds (its BATCH_FILE), none for
    a single sensor's; ValueError, one line, for a BATCH_FILE that is not one."""
    path = folder / BATCH_FILE
    if not path.is_file():
        return ()
    try:
        sensors = json.loads(path.read_text(encoding="utf-8"))["sensors"]
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise ValueError(f"{path}: not a batch file ({error})") from None
    if not isinstance(sensors, list) or not all(isinstance(s, str) and s for s in sensors):
        raise ValueError(f"{path}: sensors must be a list of sensor IDs")
    return tuple(sensors)


class TwinCampaign(_Campaign):
    """A campaign in the twin: the plan checked and each sensor's
    campaign.json started on construction, the positions not yet done run
    by ``run``, each one chamber run for every sensor that still needs it."""

    def __init__(
        self, out_dir: Path, positions: list[Position], setup: TwinSetup, resume: bool = False, force: bool = False
    ):
        from ..physics import ModelError

        try:
            self.units = setup.units()
            chamber_model, models = setup.models(self.units)
            self.position_seconds = position_scenario(setup.options, positions[0]).duration_s
        except (ModelError, ScenarioError) as error:
            raise CampaignError(str(error)) from None
        self.batch = any(unit.folder for unit in self.units)
        if self.batch and resume:
            check_same_batch(out_dir, self.units)
        headers = {
            unit: {
                "format": FORMAT,
                "rig": "twin",
                "created_utc": _utc_now(),
                "program": program_settings(setup.options),
                "seed": setup.seed,
                "model": model.source,
                "terms": {name: model.enabled(name) for name in model.terms},
                **({"sensor": unit.sensor} if unit.sensor else {}),
            }
            for unit, model in models.items()
        }
        self.setup = setup
        self._start(out_dir, positions, headers, resume, force)
        if self.batch:
            write_batch(
                out_dir,
                self.units,
                {"rig": "twin", "drawn": setup.population or None, "seed": setup.seed},
                chamber_model,
            )

    def run(
        self,
        jobs: int,
        progress: Callable[[float], None] | None = None,
        on_position: Callable[[PositionRecord], None] | None = None,
        cluster: Client | None = None,
    ) -> CampaignOutcome:
        """``progress`` gets simulated seconds as they pass, all positions
        together; from a Dask ``cluster`` (``connect_cluster``) each
        position's once it is back."""

        def finished(record: PositionRecord) -> None:
            self._finished(record)
            if on_position is not None:
                on_position(record)

        tasks = [(position, self.pending_units(position)) for position in self.todo]
        if cluster is not None:
            interrupted = _run_on_cluster(tasks, self.setup, self.out_dir, cluster, progress, finished)
        elif jobs <= 1 or len(tasks) <= 1:
            interrupted = _run_here(tasks, self.setup, self.out_dir, progress, finished)
        else:
            interrupted = _run_in_workers(tasks, self.setup, self.out_dir, min(jobs, len(tasks)), progress, finished)
        if not interrupted:
            for unit in self.units:
                shutil.rmtree(self.out_dir / unit.folder / PARTIAL_DIR, ignore_errors=True)
        return CampaignOutcome(self.records(), interrupted)


# A position to run and the sensors that still need it.
Task = tuple[Position, tuple[Unit, ...]]


class _ProgressNow:
    """What a worker's progress queue is when the position runs in this
    process: each put reaches the progress bar at once."""

    def __init__(self, progress: Callable[[float], None] | None) -> None:
        self._progress = progress

    def put(self, seconds: float) -> None:
        if self._progress is not None:
            self._progress(seconds)


def _run_here(
    tasks: list[Task],
    setup: TwinSetup,
    out_dir: Path,
    progress: Callable[[float], None] | None,
    finished: Callable[[PositionRecord], None],
) -> bool:
    for position, units in tasks:
        records = run_twin_position(setup, position, units, out_dir, _ProgressNow(progress))
        for record in records:
            finished(record)
        if any(record.status == INTERRUPTED for record in records):
            return True
    return False


def _run_in_workers(
    tasks: list[Task],
    setup: TwinSetup,
    out_dir: Path,
    jobs: int,
    progress: Callable[[float], None] | None,
    finished: Callable[[PositionRecord], None],
) -> bool:
    # spawn: a forked child would inherit the parent's threads (tqdm's) and locks.
    context = multiprocessing.get_context("spawn")
    progress_queue, stop = context.Queue(), context.Event()
    interrupted = False
    # Ctrl-C stops the loop at its next look, never inside the bookkeeping
    # of a finished position (its record saved, its line printed).
    with (
        ctrl_c_as_flag() as pressed,
        ProcessPoolExecutor(
            jobs, mp_context=context, initializer=_start_worker, initargs=(progress_queue, stop)
        ) as pool,
    ):
        running: dict[Future[list[PositionRecord]], Task] = {
            pool.submit(_run_in_worker, setup, position, units, out_dir): (position, units) for position, units in tasks
        }
        while running:
            if pressed() and not interrupted:
                interrupted = True
                stop.set()
                for future in running:
                    future.cancel()
            done, _ = wait(running, timeout=0.25, return_when=FIRST_COMPLETED)
            _drain(progress_queue, progress)
            for future in done:
                task = running.pop(future)
                if future.cancelled():
                    continue
                try:
                    records = future.result()
                except Exception as error:
                    records = _worker_failed(task, error)
                for record in records:
                    interrupted |= record.status == INTERRUPTED
                    finished(record)
        _drain(progress_queue, progress)
    return interrupted


def _drain(progress_queue: Any, progress: Callable[[float], None] | None) -> None:
    while True:
        try:
            seconds = progress_queue.get_nowait()
        except queue.Empty:
            return
        if progress is not None:
            progress(seconds)


def _worker_failed(task: Task, error: Exception) -> list[PositionRecord]:
    """A worker that died or raised: the position failed, not the campaign."""
    position, units = task
    return [
        PositionRecord(
            position.label,
            position.incl_x_deg,
            position.incl_y_deg,
            status=FAILED,
            error=f"worker failed: {error}",
            sensor_id=unit.sensor,
        )
        for unit in units
    ]


def twin_build_problem() -> str | None:
    """Why this machine cannot run the twin (the build missing or older than
    the host), or None; each Dask worker is asked before a campaign."""
    from ..twin.boards import Board, TwinError

    try:
        for board in (Board.imu_reader, Board.thermal_chamber):
            board().close()
    except TwinError as error:
        return str(error)
    return None


@dataclass(frozen=True)
class ShippedPosition:
    """A position run on a Dask worker, whose disk this machine may not see:
    each unit's record, the simulated seconds its progress counted, and each
    unit's position folder's files by their path inside it."""

    records: list[PositionRecord]
    sim_seconds: float
    files: list[dict[str, bytes]]


class _SecondsCounted:
    """A progress queue that only adds up what is put into it."""

    def __init__(self) -> None:
        self.total = 0.0

    def put(self, seconds: float) -> None:
        self.total += seconds


class _ClusterStop:
    """The campaign's stop event on the Dask scheduler, asked at most once per
    STOP_POLL_S: every ask is a round trip."""

    def __init__(self, name: str) -> None:
        from distributed import Event

        self._event = Event(name)
        self._asked_at = -STOP_POLL_S
        self._set = False

    def is_set(self) -> bool:
        now = time.monotonic()
        if not self._set and now - self._asked_at >= STOP_POLL_S:
            self._asked_at = now
            self._set = self._event.is_set()
        return self._set


def run_twin_position_shipped(
    setup: TwinSetup, position: Position, units: tuple[Unit, ...], stop_name: str
) -> ShippedPosition:
    """One position on a Dask worker, in a temporary folder there."""
    from distributed import get_worker

    counted = _SecondsCounted()
    with tempfile.TemporaryDirectory(prefix="thermotilt-position-") as scratch:
        records = run_twin_position(setup, position, units, Path(scratch), counted, _ClusterStop(stop_name))
        files = []
        for unit, record in zip(units, records):
            written = Path(scratch) / unit.folder
            folder = (written if record.status == DONE else written / PARTIAL_DIR) / position.label
            files.append(
                {
                    path.relative_to(folder).as_posix(): path.read_bytes()
                    for path in sorted(folder.rglob("*"))
                    if path.is_file()
                }
            )
    for record in records:
        if record.error is not None:
            record.error = f"on Dask worker {get_worker().address}: {record.error}"
    return ShippedPosition(records, counted.total, files)


def _run_on_cluster(
    tasks: list[Task],
    setup: TwinSetup,
    out_dir: Path,
    client: Client,
    progress: Callable[[float], None] | None,
    finished: Callable[[PositionRecord], None],
) -> bool:
    from distributed import Event, as_completed

    campaign_id = uuid.uuid4().hex
    stop = Event(f"thermotilt-stop-{campaign_id}", client=client)
    running = {
        client.submit(
            run_twin_position_shipped,
            setup,
            position,
            units,
            stop.name,
            key=f"thermotilt-{position.label}-{campaign_id}",
        ): (position, units)
        for position, units in tasks
    }
    try:
        for future in as_completed(running, loop=client.loop):
            for record in _write_shipped(out_dir, running[future], future, progress):
                finished(record)
    except KeyboardInterrupt:
        # The running positions stop at their next look at the event; what
        # they simulated is not waited for, and they stay pending.
        stop.set()
        client.cancel(list(running))
        return True
    return False


def _write_shipped(
    out_dir: Path, task: Task, future: Any, progress: Callable[[float], None] | None
) -> list[PositionRecord]:
    """A position back from a Dask worker, written as run_twin_position
    writes one here."""
    try:
        shipped: ShippedPosition = future.result()
    except Exception as error:
        return _worker_failed(task, error)
    if progress is not None:
        progress(shipped.sim_seconds)
    position, units = task
    records = []
    for unit, record, files in zip(units, shipped.records, shipped.files):
        folder = out_dir / unit.folder
        try:
            partial = _fresh_partial(folder, position.label)
            for name, data in files.items():
                (partial / name).parent.mkdir(parents=True, exist_ok=True)
                (partial / name).write_bytes(data)
            if record.status == DONE:
                _move_into_place(folder, position.label)
        except OSError as error:
            record = replace(record, status=FAILED, error=f"cannot write {position.label}: {error.strerror or error}")
        records.append(record)
    return records


# A Nano resets when its port opens and its bootloader waits ~1-2 s; a Mega the same.
BOOT_WAIT_S = 10.0
DEFAULT_HEARTBEAT_S = 60


@dataclass(frozen=True)
class BoardsSetup:
    """Real boards: the IMU readers the tilt table carries and the chamber,
    on their serial ports; the table is moved by hand, so ``confirm`` asks
    the user at each position (False stops the campaign, keeping what is
    done). Several IMU readers are a batch: each must have its own sensor
    ID (``assign-id``), which names its campaign folder."""

    imu_ports: tuple[str, ...]
    chamber_port: str
    options: ScenarioOptions
    confirm: Callable[[Position], bool]
    baud: int = 115200
    heartbeat_s: int = DEFAULT_HEARTBEAT_S


class BoardsCampaign(_Campaign):
    """A campaign on real boards, one position after another."""

    def __init__(
        self, out_dir: Path, positions: list[Position], setup: BoardsSetup, resume: bool = False, force: bool = False
    ):
        self.setup = setup
        # The port each unit's IMU reader is on.
        self.ports = {Unit(None, ""): setup.imu_ports[0]}
        if len(setup.imu_ports) > 1:
            ids = identify_sensors(setup.imu_ports, setup.baud)
            self.ports = {Unit(sensor_id, sensor_id): port for sensor_id, port in sorted(ids.items())}
        self.batch = len(self.ports) > 1
        if self.batch and resume:
            check_same_batch(out_dir, tuple(self.ports))
        headers = {
            unit: {
                "format": FORMAT,
                "rig": "boards",
                "created_utc": _utc_now(),
                "program": program_settings(setup.options),
                "ports": {"imu_reader": port, "thermal_chamber": setup.chamber_port},
                **({"sensor": unit.sensor} if unit.sensor else {}),
            }
            for unit, port in self.ports.items()
        }
        self._start(out_dir, positions, headers, resume, force)
        if self.batch:
            write_batch(out_dir, tuple(self.ports), {"rig": "boards"})

    def run(self, on_position: Callable[[PositionRecord], None] | None = None) -> CampaignOutcome:
        for position in self.todo:
            if not self.setup.confirm(position):
                return CampaignOutcome(self.records(), False)
            imus = [
                (unit, self.ports[unit], unit.sensor if self.batch else self.files[unit].sensor_id())
                for unit in self.pending_units(position)
            ]
            records = run_boards_position(self.setup, position, self.out_dir, imus)
            for record in records:
                self._finished(record)
                if on_position is not None:
                    on_position(record)
            if any(record.status != DONE for record in records):
                # With hardware a failure needs a person: the next position waits for --resume.
                return CampaignOutcome(self.records(), any(record.status == INTERRUPTED for record in records))
        for unit in self.files:
            shutil.rmtree(self.out_dir / unit.folder / PARTIAL_DIR, ignore_errors=True)
        return CampaignOutcome(self.records(), False)


def identify_sensors(ports: tuple[str, ...], baud: int) -> dict[str, str]:
    """The sensor ID of the IMU reader on each port, by ID; CampaignError
    for a board without one or two with the same."""
    import serial

    from ..wire.client import CommandClient, CommandError

    ids: dict[str, str] = {}
    for port in ports:
        try:
            with serial.serial_for_url(port, baudrate=baud, timeout=0.05) as imu:
                client = CommandClient(imu)
                _board_version(client, port)
                sensor_id = _board_sensor_id(client, port)
        except (serial.SerialException, OSError) as error:
            raise CampaignError(f"serial port {port}: {error}") from None
        except CommandError as error:
            raise CampaignError(f"{port}: {error}") from None
        if not sensor_id:
            raise CampaignError(
                f"the IMU reader on {port} has no sensor ID; a batch needs one per board: "
                f"thermotilt assign-id ID --port {port}"
            )
        if sensor_id in ids:
            raise CampaignError(f"the IMU readers on {ids[sensor_id]} and {port} are both sensor {sensor_id}")
        ids[sensor_id] = port
    return ids


def _board_version(client: Any, port: str) -> str:
    """VERSION until the board, maybe still in its bootloader, answers."""
    from ..wire.client import CommandTimeout

    deadline = time.monotonic() + BOOT_WAIT_S
    while True:
        try:
            answer = client.command("VERSION")
        except CommandTimeout:
            if time.monotonic() > deadline:
                raise CampaignError(f"no board answers on {port} (VERSION, {BOOT_WAIT_S:g} s)") from None
            continue
        frame = next((frame for frame in answer.data if frame.type == "VER"), None)
        if frame is None:
            raise CampaignError(f"the board on {port} answered VERSION without a VER frame")
        return f"{frame['device']} {frame['firmware_version']} protocol {frame['protocol_version']}"


def _board_sensor_id(client: Any, port: str) -> str:
    """The IMU's sensor ID from its ICF ("" for none)."""
    answer = client.command("STATUS")
    frame = next((frame for frame in answer.data if frame.type == "ICF"), None)
    if frame is None:
        raise CampaignError(
            f"the IMU reader on {port} answered STATUS without an ICF frame that has a sensor_id "
            "(firmware before imu_reader 0.3.0? update it)"
        )
    return frame["sensor_id"]


def run_boards_position(
    setup: BoardsSetup, position: Position, out_dir: Path, imus: list[tuple[Unit, str, str | None]]
) -> list[PositionRecord]:
    """The table is set: for each unit, its IMU reader's port and the sensor
    ID it must report (None: any, the campaign's first position), check
    each IMU, restart its filters, run the chamber's program and log every
    board until it ends, each IMU into its unit's campaign folder."""
    import serial

    from ..twin.scenarios import chamber_program
    from ..wire.client import CommandClient, CommandError
    from ..wire.logger import LogError, ProgramWatch, Rig, log_imus
    from ..wire.protocol import SequenceCounter

    records = [
        # Until its board reports one: the ID of the batch sensor the unit is.
        PositionRecord(
            position.label, position.incl_x_deg, position.incl_y_deg, started_utc=_utc_now(), sensor_id=unit.sensor
        )
        for unit, _, _ in imus
    ]
    partials = [_fresh_partial(out_dir / unit.folder, position.label) for unit, _, _ in imus]
    begin = time.monotonic()
    chamber = None

    def failed(status: str, error: str | None = None) -> list[PositionRecord]:
        for record in records:
            record.status, record.error = status, error
        return records

    try:
        with ExitStack() as ports:
            chamber = ports.enter_context(serial.serial_for_url(setup.chamber_port, baudrate=setup.baud, timeout=0.05))
            chamber_seq = SequenceCounter()
            chamber_client = CommandClient(chamber, seq=chamber_seq)
            chamber_version = _board_version(chamber_client, setup.chamber_port)
            logs = []
            for (_, port, expected_id), record, partial in zip(imus, records, partials):
                imu = ports.enter_context(serial.serial_for_url(port, baudrate=setup.baud, timeout=0.05))
                imu_client = CommandClient(imu)
                record.firmware = {
                    "imu_reader": _board_version(imu_client, port),
                    "thermal_chamber": chamber_version,
                }
                record.sensor_id = _board_sensor_id(imu_client, port)
                if expected_id is not None and record.sensor_id != expected_id:
                    raise CampaignError(
                        f"the IMU reader on {port} is sensor {record.sensor_id or '(no ID)'}, "
                        f"this campaign's positions so far were logged with {expected_id or '(no ID)'}"
                    )
                imu_client.command("RESEED")
                logs.append((imu, partial, record.firmware))
            for command in chamber_program(CALIBRATION_MIN_C, CALIBRATION_MAX_C, setup.options, 1):
                chamber_client.command(command.frame_type, command.values)
            chamber_client.command("SETHB", (setup.heartbeat_s,))
            chamber_client.command("START")
            rig = Rig(setup.options.ambient_c, position.incl_x_deg, position.incl_y_deg, position.label)
            watch = ProgramWatch(setup.heartbeat_s / 4 if setup.heartbeat_s else None, chamber_seq)
            options = replace(setup.options, incl_x_deg=position.incl_x_deg, incl_y_deg=position.incl_y_deg)
            summaries = log_imus(
                logs,
                chamber,
                rig=rig,
                program=watch,
                description=f"campaign position {position.label} on real boards",
                scenario="cycle",
                options=asdict(options),
            )
            if summaries[0].end_reason != PROGRAM_DONE:
                _stop_chamber(chamber)
    except (serial.SerialException, OSError) as error:
        return failed(FAILED, f"serial port: {error}")
    except (CampaignError, CommandError, LogError) as error:
        _stop_chamber(chamber)
        return failed(FAILED, str(error))
    except KeyboardInterrupt:
        _stop_chamber(chamber)
        return failed(INTERRUPTED)
    for (unit, _, _), record, summary in zip(imus, records, summaries):
        record.wall_seconds = round(time.monotonic() - begin, 3)
        record.reported_errors = [
            f"{board}: {error}" for board, report in summary.boards.items() for error in report.reported_errors
        ]
        if summary.end_reason == RUN_INTERRUPTED:
            record.status = INTERRUPTED
        elif summary.end_reason != PROGRAM_DONE:
            record.status, record.error = FAILED, f"the log ended early: {summary.end_reason}"
        else:
            _move_into_place(out_dir / unit.folder, position.label)
            record.status = DONE
    return records


def _stop_chamber(chamber: Any) -> None:
    """Best effort: the chamber's own heartbeat stops it anyway."""
    import serial

    from ..wire.protocol import build_frame

    if chamber is None:
        return
    try:
        if chamber.is_open:
            chamber.write(build_frame("STOP", 0, ()).encode("ascii"))
    except (serial.SerialException, OSError):
        pass  # the port may be what failed; the chamber's heartbeat is the real safeguard
