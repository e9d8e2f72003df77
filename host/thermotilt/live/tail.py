"""A run's files read as they grow, by byte offset: its run.csv (only
complete lines, so a row the writer has not finished, the twin writing
buffered and real boards a row at a time, is read on a later poll, whole)
and each board's serial capture (the errors a board reports on its own and
the fault the chamber latches). A file of another identity (device and
inode) than the last poll's, or shorter than what was read, is a new one:
read from its start. A file moved with its folder (a position from
.partial/ into place) keeps its identity, and its offset.
"""

from __future__ import annotations

import csv
import itertools
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..run.folder import CHAMBER_BOARD, IMU_BOARD, RunFolder
from ..run.log import HEADERS
from ..wire.protocol import FrameReader

# What the page draws, as time from the log's first row.
CHAMBER_SERIES = ("setpoint_c", "chamber_c", "outer_c")
SENSOR_SERIES = ("ax_filt", "ay_filt")
SERIES = ("t_s", *CHAMBER_SERIES, *SENSOR_SERIES)
# A chamber_fault cell that is not a fault.
NO_FAULT = ("", "OK")
# The chamber's CHS phase of a latched fault.
FAULT_PHASE = "F"
# The most one poll reads of a file, so that a long log already on disk is
# taken in a few polls rather than held whole in memory twice.
READ_AT_MOST = 16 << 20

# Each log's series carry a generation, so a reader can tell a log read
# again from the start (a position redone) from the same log grown.
_generations = itertools.count(1)


class GrowingFile:
    """Where the last poll of a file stopped, and which file it was."""

    def __init__(self) -> None:
        self.offset = 0
        self._identity: tuple[int, int] | None = None

    def read(self, path: Path) -> tuple[bool, bytes]:
        """Whether the file is a new one (read from its start), and its bytes
        after the offset; the caller advances the offset by what it took.
        Nothing, not new, for a file not there (yet, or any more)."""
        try:
            with open(path, "rb") as stream:
                status = os.fstat(stream.fileno())
                identity = (status.st_dev, status.st_ino)
                new = identity != self._identity or status.st_size < self.offset
                if new:
                    self._identity, self.offset = identity, 0
                stream.seek(self.offset)
                return new, stream.read(READ_AT_MOST)
        except OSError:
            return False, b""


def number(cell: str) -> float | None:
    """A cell as a number; an empty or unreadable one None (a gap in the chart)."""
    try:
        value = float(cell)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


class RunLogTail:
    """One run.csv followed across polls: the SERIES, the chamber faults
    its chamber_fault column shows, and the run's pace."""

    def __init__(self) -> None:
        self._file = GrowingFile()
        self._start()

    def _start(self) -> None:
        self.generation = next(_generations)
        self.series: dict[str, list[float | None]] = {name: [] for name in SERIES}
        # (t_s, token) of each fault the chamber_fault column latched.
        self.faults: list[tuple[float, str]] = []
        self._columns: dict[str, int] | None = None
        self._first_time_s: float | None = None
        self._latched = ""
        self._pace_start: tuple[float, float] | None = None
        self._pace_now: tuple[float, float] | None = None

    @property
    def rows(self) -> int:
        return len(self.series["t_s"])

    @property
    def run_seconds(self) -> float:
        """The log's time from its first row to its last (0 without rows)."""
        times = self.series["t_s"]
        return (times[-1] or 0.0) if times else 0.0

    def pace(self) -> float | None:
        """The run's seconds per wall second while this tail watched it grow,
        None until it grew over a second of wall time."""
        if self._pace_start is None or self._pace_now is None:
            return None
        (wall_0, run_0), (wall_1, run_1) = self._pace_start, self._pace_now
        if wall_1 - wall_0 < 1.0 or run_1 <= run_0:
            return None
        return (run_1 - run_0) / (wall_1 - wall_0)

    def poll(self, path: Path) -> int:
        """Reads the complete lines appended to path since the last poll; the rows added."""
        new, data = self._file.read(path)
        if new:
            self._start()
        end = data.rfind(b"\n")
        if end < 0:
            return 0
        self._file.offset += end + 1
        added = 0
        for cells in csv.reader(data[: end + 1].decode("utf-8", errors="replace").splitlines()):
            if self._columns is None:
                # Another header than run.csv's: the file is no run log, and no row is taken.
                self._columns = {name: index for index, name in enumerate(cells)} if tuple(cells) in HEADERS else {}
            elif self._columns and len(cells) == len(self._columns):
                added += self._add_row(cells)
        if added:
            now = time.monotonic()
            self._pace_now = (now, self.run_seconds)
            self._pace_start = self._pace_start or self._pace_now
        return added

    def _add_row(self, cells: list[str]) -> int:
        columns = self._columns or {}
        time_s = number(cells[columns["time_s"]])
        if time_s is None:
            return 0
        if self._first_time_s is None:
            self._first_time_s = time_s
        t_s = round(time_s - self._first_time_s, 3)
        self.series["t_s"].append(t_s)
        for name in (*CHAMBER_SERIES, *SENSOR_SERIES):
            self.series[name].append(number(cells[columns[name]]))
        token = cells[columns["chamber_fault"]].strip()
        token = "" if token in NO_FAULT else token
        if token and token != self._latched:
            self.faults.append((t_s, token))
        self._latched = token
        return 1


class CaptureTail:
    """One board's serial capture followed across polls: the errors it
    reported on its own (ERR with cmd_seq -1, "CODE DETAIL", in order) and
    the fault a chamber's CHS latched (phase F)."""

    def __init__(self) -> None:
        self._file = GrowingFile()
        self._start()

    def _start(self) -> None:
        self.errors: list[str] = []
        self.latched: str | None = None
        self._reader = FrameReader()

    def poll(self, path: Path) -> None:
        new, data = self._file.read(path)
        if new:
            self._start()
        self._file.offset += len(data)
        for frame in self._reader.feed(data):
            if frame.type == "ERR" and frame["cmd_seq"] == -1:
                self.errors.append(f"{frame['code']} {frame['detail']}")
            elif frame.type == "CHS" and frame["phase"] == FAULT_PHASE and self.latched is None:
                self.latched = str(frame["fault"])


@dataclass
class PositionTail:
    """A run folder followed as it grows: its run.csv and both boards' captures."""

    log: RunLogTail = field(default_factory=RunLogTail)
    captures: dict[str, CaptureTail] = field(
        default_factory=lambda: {board: CaptureTail() for board in (CHAMBER_BOARD, IMU_BOARD)}
    )

    def poll(self, folder: Path) -> None:
        # The log first: an error read from a capture is placed at the log's last row.
        run = RunFolder.at(folder)
        self.log.poll(run.log)
        for board, capture in self.captures.items():
            capture.poll(run.capture(board))
