"""Twin positions on the workers of a Dask cluster (``--scheduler``), whose
disks this machine may not see: each worker runs its position in a
temporary folder and sends the files back, and they are written here as a
position run here would be."""

from __future__ import annotations

import tempfile
import time
import uuid
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .folder import DONE, FAILED, PARTIAL_DIR, CampaignFolder, Position, PositionRecord
from .plan import Finished, Progress, RunEnd, Task, Unit, failed_records
from .twin import TwinSetup, run_twin_position

if TYPE_CHECKING:
    from distributed import Client

# A running position on a Dask worker asks the scheduler this often whether to stop.
STOP_POLL_S = 1.0


@dataclass(frozen=True)
class ShippedPosition:
    """A position run on a Dask worker: each unit's record, the simulated
    seconds its progress counted, and each unit's position folder's files
    by their path inside it."""

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
        records = run_twin_position(setup, position, units, CampaignFolder(scratch), counted, _ClusterStop(stop_name))
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


class DaskRunner:
    def __init__(self, setup: TwinSetup, client: Client) -> None:
        self.setup, self.client = setup, client

    def run(self, tasks: list[Task], folder: CampaignFolder, progress: Progress | None, finished: Finished) -> RunEnd:
        from distributed import Event, as_completed

        campaign_id = uuid.uuid4().hex
        stop = Event(f"thermotilt-stop-{campaign_id}", client=self.client)
        running = {
            self.client.submit(
                run_twin_position_shipped,
                self.setup,
                position,
                units,
                stop.name,
                key=f"thermotilt-{position.label}-{campaign_id}",
            ): (position, units)
            for position, units in tasks
        }
        try:
            for future in as_completed(running, loop=self.client.loop):
                for record in _write_shipped(folder, running[future], future, progress):
                    finished(record)
        except KeyboardInterrupt:
            # The running positions stop at their next look at the event; what
            # they simulated is not waited for, and they stay pending.
            stop.set()
            self.client.cancel(list(running))
            return RunEnd.INTERRUPTED
        return RunEnd.FINISHED


def _write_shipped(
    campaign: CampaignFolder, task: Task, future: Any, progress: Progress | None
) -> list[PositionRecord]:
    """A position back from a Dask worker, written as run_twin_position
    writes one here."""
    try:
        shipped: ShippedPosition = future.result()
    except Exception as error:
        return failed_records(task, f"worker failed: {error}")
    if progress is not None:
        progress(shipped.sim_seconds)
    position, units = task
    records = []
    for unit, record, files in zip(units, shipped.records, shipped.files):
        folder = campaign.sensor(unit.folder)
        try:
            partial = folder.partial(position.label)
            for name, data in files.items():
                (partial / name).parent.mkdir(parents=True, exist_ok=True)
                (partial / name).write_bytes(data)
            if record.status == DONE:
                folder.keep(position.label)
        except OSError as error:
            record = replace(record, status=FAILED, error=f"cannot write {position.label}: {error.strerror or error}")
        records.append(record)
    return records
