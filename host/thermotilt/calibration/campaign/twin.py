"""A campaign in the digital twin: its setup (plain data a worker process
or a Dask worker can take), one position run in the twin, and the campaign
that runs the positions not yet done, here, in worker processes or on a
Dask cluster. Each position's noise seed is the campaign's seed plus the
position's index among the paper's 37 (plus a number from a batch sensor's
ID), so a subset reproduces the same positions of the full campaign.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...twin.scenarios import ScenarioError, ScenarioOptions, cycle
from .folder import DONE, FAILED, INTERRUPTED, CampaignError, CampaignFolder, Position, PositionRecord
from .plan import Campaign, CampaignOutcome, Finished, PositionRunner, Progress, Unit, campaign_header

if TYPE_CHECKING:
    from distributed import Client

SEED_MODULUS = 2**64


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
        from ...physics import Model

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


def position_scenario(options: ScenarioOptions, position: Position) -> Any:
    return cycle(replace(options, incl_x_deg=position.incl_x_deg, incl_y_deg=position.incl_y_deg))


def run_twin_position(
    setup: TwinSetup,
    position: Position,
    units: tuple[Unit, ...],
    folder: CampaignFolder,
    progress_queue: Any = None,
    stop_event: Any = None,
) -> list[PositionRecord]:
    """One position in the twin, in this process: one chamber run carrying
    each unit's sensor, into each unit's campaign folder; puts the
    simulated seconds into ``progress_queue`` as they pass (a whole
    position's by its end) and stops when ``stop_event`` is set."""
    from ...twin import simulate
    from ...twin.boards import TwinError

    # The twin's board holds the ID of the batch's sensor the unit names.
    records = [
        PositionRecord.started(position, unit.sensor, setup.position_seed(position, unit.sensor)) for unit in units
    ]
    partials = [folder.sensor(unit.folder).partial(position.label) for unit in units]
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
        _finish_record(record, summary, folder.sensor(unit.folder))
    return records


def _finish_record(record: PositionRecord, summary: Any, folder: CampaignFolder) -> None:
    """What the position's run says of it; a done one moved into place."""
    from ...run.summary import CHAMBER_FAULT

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
        folder.keep(record.label)
        record.status = DONE


def twin_build_problem() -> str | None:
    """Why this machine cannot run the twin (the build missing or older than
    the host), or None; each Dask worker is asked before a campaign."""
    from ...twin.boards import Board, TwinError

    try:
        for board in (Board.imu_reader, Board.thermal_chamber):
            board().close()
    except TwinError as error:
        return str(error)
    return None


class TwinCampaign(Campaign):
    """A campaign in the twin: the plan checked and each sensor's
    campaign.json started on construction, the positions not yet done run
    by ``run``, each one chamber run for every sensor that still needs it."""

    def __init__(
        self, out_dir: Path, positions: list[Position], setup: TwinSetup, resume: bool = False, force: bool = False
    ):
        from ...physics import ModelError

        folder = CampaignFolder(out_dir)
        try:
            self.units = setup.units()
            chamber_model, models = setup.models(self.units)
            self.position_seconds = position_scenario(setup.options, positions[0]).duration_s
        except (ModelError, ScenarioError) as error:
            raise CampaignError(str(error)) from None
        batch = any(unit.folder for unit in self.units)
        if batch and resume:
            folder.check_batch(unit.sensor for unit in self.units)
        headers = {
            unit: campaign_header(
                "twin",
                setup.options,
                unit,
                seed=setup.seed,
                model=model.source,
                terms={name: model.enabled(name) for name in model.terms},
            )
            for unit, model in models.items()
        }
        self.setup = setup
        super().__init__(folder, positions, headers, resume, force)
        if self.batch:
            folder.write_batch(
                (unit.sensor for unit in self.units),
                {"rig": "twin", "drawn": setup.population or None, "seed": setup.seed},
                chamber_model,
            )

    def describe(self, running_on: str) -> str:
        lines = []
        if self.batch:
            sensors = [unit.sensor for unit in self.units]
            lines.append(
                f"a batch of {len(sensors)} sensors ({', '.join(sensors)}) on one tilt table, "
                f"each its own campaign in {self.folder.path}/<ID>"
            )
        lines.append(
            f"campaign of {len(self.positions)} positions -> {self.folder.path}"
            + (f" ({self.done} already done)" if self.done else "")
            + f": {len(self.todo)} to run, {self.position_seconds:.0f} s simulated each at most, {running_on}"
        )
        return "\n".join(lines)

    def runner(self, jobs: int, cluster: Client | None = None) -> PositionRunner:
        """Where the positions run: on a Dask ``cluster`` (``connect_cluster``),
        in ``jobs`` worker processes, or here."""
        if cluster is not None:
            from .dask import DaskRunner

            return DaskRunner(self.setup, cluster)
        from .local import InProcessRunner, ProcessPoolRunner

        if jobs <= 1 or len(self.todo) <= 1:
            return InProcessRunner(self.setup)
        return ProcessPoolRunner(self.setup, min(jobs, len(self.todo)))

    def run(
        self,
        jobs: int,
        progress: Progress | None = None,
        on_position: Finished | None = None,
        cluster: Client | None = None,
    ) -> CampaignOutcome:
        """``progress`` gets simulated seconds as they pass, all positions
        together; from a Dask ``cluster`` each position's once it is back."""
        return self.run_with(self.runner(jobs, cluster), progress, on_position)
