"""Twin positions on this machine: one after another in this process, or
in parallel worker processes (positions are independent runs)."""

from __future__ import annotations

import multiprocessing
import os
import queue
import signal
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any

from ...ctrl_c import ctrl_c_as_flag
from .folder import INTERRUPTED, CampaignFolder, Position, PositionRecord
from .plan import Finished, Progress, RunEnd, Task, Unit, failed_records
from .twin import TwinSetup, run_twin_position

# A worker process looks this often whether its campaign is still there.
ORPHAN_POLL_S = 1.0


class _ProgressNow:
    """What a worker's progress queue is when the position runs in this
    process: each put reaches the progress bar at once."""

    def __init__(self, progress: Progress | None) -> None:
        self._progress = progress

    def put(self, seconds: float) -> None:
        if self._progress is not None:
            self._progress(seconds)


class InProcessRunner:
    def __init__(self, setup: TwinSetup) -> None:
        self.setup = setup

    def run(self, tasks: list[Task], folder: CampaignFolder, progress: Progress | None, finished: Finished) -> RunEnd:
        for position, units in tasks:
            records = run_twin_position(self.setup, position, units, folder, _ProgressNow(progress))
            for record in records:
                finished(record)
            if any(record.status == INTERRUPTED for record in records):
                return RunEnd.INTERRUPTED
        return RunEnd.FINISHED


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
    setup: TwinSetup, position: Position, units: tuple[Unit, ...], folder: CampaignFolder
) -> list[PositionRecord]:
    return run_twin_position(setup, position, units, folder, _progress_queue, _stop_event)


class ProcessPoolRunner:
    def __init__(self, setup: TwinSetup, jobs: int) -> None:
        self.setup, self.jobs = setup, jobs

    def run(self, tasks: list[Task], folder: CampaignFolder, progress: Progress | None, finished: Finished) -> RunEnd:
        # spawn: a forked child would inherit the parent's threads (tqdm's) and locks.
        context = multiprocessing.get_context("spawn")
        progress_queue, stop = context.Queue(), context.Event()
        interrupted = False
        # Ctrl-C stops the loop at its next look, never inside the bookkeeping
        # of a finished position (its record saved, its line printed).
        with (
            ctrl_c_as_flag() as pressed,
            ProcessPoolExecutor(
                self.jobs, mp_context=context, initializer=_start_worker, initargs=(progress_queue, stop)
            ) as pool,
        ):
            running: dict[Future[list[PositionRecord]], Task] = {
                pool.submit(_run_in_worker, self.setup, position, units, folder): (position, units)
                for position, units in tasks
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
                        records = failed_records(task, f"worker failed: {error}")
                    for record in records:
                        interrupted |= record.status == INTERRUPTED
                        finished(record)
            _drain(progress_queue, progress)
        return RunEnd.INTERRUPTED if interrupted else RunEnd.FINISHED


def _drain(progress_queue: Any, progress: Progress | None) -> None:
    while True:
        try:
            seconds = progress_queue.get_nowait()
        except queue.Empty:
            return
        if progress is not None:
            progress(seconds)
