"""``thermotilt log``: real boards (or the twin's pseudo-terminals) to a
run folder: run.csv, serial/ and summary.json (docs/run-log.md).

The IMU reader's frames make the rows (several readers on one table each
into their own run folder: ``log_imus``); the chamber's CHS frames, when its
port is given, fill the chamber columns; both go through the recorder the
twin uses (``thermotilt.wire.recorder``). Each row, and each chunk of raw
bytes, is flushed as it is written, so stopping with Ctrl-C, the board going
away or the logger being killed loses nothing already received; the summary
is written when the log ends, which a kill does not let it do.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import serial

from ..run.folder import CHAMBER_BOARD, IMU_BOARD, RunFolder
from ..run.log import RunLogWriter
from ..run.summary import BOARDS, INTERRUPTED, BoardReport, RunSummary
from .protocol import SequenceCounter, build_frame
from .recorder import BoardStream, FrameRecorder

# Long enough for a 10 Hz stream to fill a read; short enough to watch both ports.
READ_TIMEOUT_S = 0.05
SILENCE_WARNING_S = 5.0


class LogError(RuntimeError):
    """A log that cannot start or that received nothing; one readable line."""


@dataclass(frozen=True)
class Rig:
    """What the host knows of the rig it logs (None: not known), for the
    rows and the summary. ``position``: the table was set to this position,
    and the IMU's filters restarted, right before the log began, so
    since_move_s counts from the first IMU frame."""

    ambient_c: float | None = None
    incl_x_deg: float | None = None
    incl_y_deg: float | None = None
    position: str | None = None

    def positions(self) -> list[dict[str, Any]]:
        if self.position is None and self.incl_x_deg is None and self.incl_y_deg is None:
            return []
        return [{"at_s": 0.0, "label": self.position, "incl_x_deg": self.incl_x_deg, "incl_y_deg": self.incl_y_deg}]


def _open_port(port: str, baud: int) -> serial.Serial:
    try:
        return serial.serial_for_url(port, baudrate=baud, timeout=READ_TIMEOUT_S)
    # pyserial's URL handlers raise whatever their parsing meets
    # (loop://?x gives a KeyError), so any failure here is the port's.
    except Exception as error:
        raise LogError(f"cannot open {port}: {error}") from None


class _OutputFile:
    """A file the logger writes: a failure is one LogError naming the file,
    and closing it after a failed write does not fail a second time."""

    def __init__(self, path: Path, mode: str, **options: Any) -> None:
        self._path = path
        with self._reported():
            self._stream = open(path, mode, **options)

    def write(self, data: Any) -> None:
        with self._reported():
            self._stream.write(data)

    def flush(self) -> None:
        with self._reported():
            self._stream.flush()

    def close(self) -> None:
        # Everything written was flushed; what is left failed and was reported.
        with suppress(OSError):
            self._stream.close()

    @contextmanager
    def _reported(self) -> Iterator[None]:
        try:
            yield
        except OSError as error:
            raise LogError(f"cannot write {self._path}: {error.strerror or error}") from None


def _read_available(port: serial.Serial, wait: bool) -> bytes:
    """What the port holds; waits up to the read timeout when asked to.
    A port that went away (a closed pseudo-terminal, an unplugged board)
    raises EOFError."""
    try:
        if wait:
            return port.read(max(1, port.in_waiting))
        return port.read(port.in_waiting) if port.in_waiting else b""
    except (serial.SerialException, OSError):
        raise EOFError from None


def log_boards(
    imu_port: str | serial.Serial,
    out_dir: Path,
    chamber_port: str | serial.Serial | None = None,
    firmware: Mapping[str, str] | None = None,
    **settings: Any,
) -> RunSummary:
    """Logs into the run folder out_dir until the duration, the row count,
    a closed port, Ctrl-C or, with ``program``, the chamber's program
    ending (done, or a fault: ProgramEnd); the settings are LogSettings'. A
    port given open stays open. ``firmware``: each board's VER as the
    caller asked it, for boards that sent theirs before the log began."""
    return log_imus([(imu_port, out_dir, firmware)], chamber_port, **settings)[0]


# One IMU reader of a log: its port, the run folder its rows go to, and the
# boards' VER as the caller asked them (log_boards' firmware).
ImuReader = tuple[str | serial.Serial, Path, Mapping[str, str] | None]


@dataclass(frozen=True)
class LogSettings:
    """How a log runs and what its summaries say: the ports' baud rate; the
    log's end after ``duration_s`` of board time or ``max_rows`` rows (None:
    no such end); the rig; ``force``: a run folder's earlier log may be
    overwritten; ``program``: the chamber's program the log follows (None:
    none); ``description``, ``scenario`` and ``options`` go to the summary
    as they are."""

    baud: int = 115200
    duration_s: float | None = None
    max_rows: int | None = None
    rig: Rig = Rig()
    force: bool = False
    program: ProgramWatch | None = None
    description: str = "thermotilt log"
    scenario: str | None = None
    options: Mapping[str, Any] | None = None


def log_imus(
    imus: Sequence[ImuReader], chamber_port: str | serial.Serial | None = None, **settings: Any
) -> list[RunSummary]:
    """log_boards for several IMU readers on one tilt table, each into its
    own run folder; the chamber's frames go to every folder. The log ends
    for all when it ends for one (its duration or row count, its port
    closing). The settings are LogSettings', by name."""
    chosen = LogSettings(**settings)
    folders = [RunFolder.at(out_dir) for _, out_dir, _ in imus]
    for folder in folders:
        # os.path answers False where pathlib raises (a parent that cannot be
        # searched); creating the folder then says why.
        if os.path.exists(folder.log) and not chosen.force:
            raise LogError(f"{folder.log} exists; choose another --out or add --force")
    with ExitStack() as stack:
        session = _Session.open(stack, [port for port, _, _ in imus], chamber_port, folders, chosen)
        end_reason = session.read_until_end()
    summaries = []
    for (_, _, firmware), log, folder in zip(imus, session.logs, folders):
        summary = session.summary(log, firmware, end_reason)
        try:
            summary.write(folder.path)
        except OSError as error:
            raise LogError(f"cannot write {folder.summary_path}: {error.strerror or error}") from None
        summaries.append(summary)
    for log in session.logs:
        if log.recorder.rows == 0 and end_reason != INTERRUPTED:
            raise LogError(
                f"no IMU frames received from {log.name} ({end_reason}); {log.stream.reader.malformed} malformed lines"
            )
    return summaries


@dataclass(frozen=True)
class _Session:
    """A log's open ports and where what they send goes: each IMU reader's
    run.csv and capture, and the chamber's capture in every run folder
    (chamber None: no chamber); clock counts the log's wall seconds."""

    settings: LogSettings
    logs: list[_LoggedReader]
    chamber: serial.Serial | None
    chamber_stream: BoardStream | None
    clock: Callable[[], float]

    @classmethod
    def open(
        cls,
        stack: ExitStack,
        imu_ports: Sequence[str | serial.Serial],
        chamber_port: str | serial.Serial | None,
        folders: Sequence[RunFolder],
        settings: LogSettings,
    ) -> _Session:
        """Opens the ports, then the run folders' files; stack closes them."""
        started = time.monotonic()

        def clock() -> float:
            return time.monotonic() - started

        logs = [_LoggedReader(_opened(stack, port, settings.baud), port) for port in imu_ports]
        chamber = _opened(stack, chamber_port, settings.baud) if chamber_port is not None else None
        for folder in folders:
            for made in (folder.path, folder.serial_dir):
                try:
                    made.mkdir(parents=True, exist_ok=True)
                except OSError as error:
                    raise LogError(f"cannot create folder {made}: {error.strerror or error}") from None
        for log, folder in zip(logs, folders):
            log.open_outputs(stack, folder, clock, settings)
        chamber_stream = None
        if chamber is not None:
            captures = [_open_output(stack, folder.capture(CHAMBER_BOARD), "wb") for folder in folders]
            chamber_stream = BoardStream(CHAMBER_BOARD, _Copies(captures), clock, flush=True)
        return cls(settings, logs, chamber, chamber_stream, clock)

    def read_until_end(self) -> str:
        """Records what the ports send until the log ends; returns why it ended."""
        end_reason = ""
        try:
            while not end_reason:
                self._record_chamber()
                end_reason = self._record_imus()
        except EOFError:
            end_reason = "port closed"
        except KeyboardInterrupt:
            end_reason = INTERRUPTED
        return end_reason

    def _record_chamber(self) -> None:
        if self.chamber is None:
            return
        frames = self.chamber_stream.feed(_read_available(self.chamber, wait=False))
        for log in self.logs:
            log.recorder.record_chamber(frames)
        if self.settings.program is not None:
            self.settings.program.keep_alive(self.chamber)

    def _record_imus(self) -> str:
        """Rows from what the IMU readers sent; why the log must stop, or ""."""
        settings = self.settings
        stop = self.logs[0].recorder.end_reason
        for number, log in enumerate(self.logs):
            # The first port's read waits, so an idle loop does not spin.
            data = _read_available(log.port, wait=number == 0)
            stop = log.record(data, settings.duration_s, settings.max_rows) or stop
            log.warn_if_silent(self.clock(), settings.baud)
        return stop

    def summary(self, log: _LoggedReader, firmware: Mapping[str, str] | None, end_reason: str) -> RunSummary:
        """The summary of log's run folder; firmware as in ImuReader."""
        settings = self.settings
        streams = [(log.stream, log.port)]
        if self.chamber is not None:
            streams.append((self.chamber_stream, self.chamber))
        return RunSummary(
            source=BOARDS,
            scenario=settings.scenario,
            description=settings.description,
            options=dict(settings.options) if settings.options is not None else None,
            end_reason=end_reason,
            realtime=True,
            wall_seconds=round(self.clock(), 3),
            rows=log.recorder.rows,
            positions=settings.rig.positions(),
            boards={stream.name: _board_report(stream, port, firmware) for stream, port in streams},
        )


class _LoggedReader:
    """One IMU reader's port, the stream of what it sends and its run.csv."""

    def __init__(self, port: serial.Serial, name: str | serial.Serial) -> None:
        self.port = port
        self.name = name if isinstance(name, str) else port.port
        self.stream: BoardStream
        self.recorder: FrameRecorder
        self.first_ms: int | None = None
        self.warned = False

    def open_outputs(
        self, stack: ExitStack, folder: RunFolder, clock: Callable[[], float], settings: LogSettings
    ) -> None:
        """The stream of what the reader sends, captured in folder's serial/,
        and the recorder of its rows in folder's run.csv."""
        self.stream = BoardStream(IMU_BOARD, _open_output(stack, folder.capture(IMU_BOARD), "wb"), clock, flush=True)
        self.recorder = FrameRecorder(
            RunLogWriter(_open_output(stack, folder.log, "w", newline=""), with_truth=False),
            watch_program=settings.program is not None,
        )
        rig = settings.rig
        self.recorder.set_ambient(rig.ambient_c)
        self.recorder.move_table(rig.incl_x_deg, rig.incl_y_deg, first_frame=rig.position is not None)

    def record(self, data: bytes, duration_s: float | None, max_rows: int | None) -> str:
        """Rows from the IMU frames in data; why the log must stop, or ""."""
        for frame in self.stream.feed(data):
            if frame.type != "IMU":
                continue
            self.first_ms = frame["t_ms"] if self.first_ms is None else self.first_ms
            if duration_s is not None and (frame["t_ms"] - self.first_ms) / 1000.0 > duration_s:
                return f"{duration_s:g} s of board time"
            self.recorder.record_imu(frame)
            if max_rows is not None and self.recorder.rows >= max_rows:
                return f"{max_rows} rows"
        return ""

    def warn_if_silent(self, seconds: float, baud: int) -> None:
        if not self.warned and self.recorder.rows == 0 and seconds > SILENCE_WARNING_S:
            self.warned = True
            print(
                f"thermotilt: no IMU frames from {self.name} yet "
                f"({self.stream.reader.malformed} malformed; is the baud rate {baud}?)",
                file=sys.stderr,
            )


class _Copies:
    """A capture written to several files at once (the chamber's, into each IMU's run folder)."""

    def __init__(self, files: Sequence[_OutputFile]) -> None:
        self._files = files

    def write(self, data: bytes) -> None:
        for file in self._files:
            file.write(data)

    def flush(self) -> None:
        for file in self._files:
            file.flush()


def _board_report(stream: BoardStream, port: serial.Serial, firmware: Mapping[str, str] | None) -> BoardReport:
    report = stream.report(port=port.port)
    if report.firmware is None and firmware is not None:
        report.firmware = firmware.get(stream.name)
    return report


def _opened(stack: ExitStack, port: str | serial.Serial, baud: int) -> serial.Serial:
    return stack.enter_context(_open_port(port, baud)) if isinstance(port, str) else port


class ProgramWatch:
    """For a chamber program the host started: the log ends with it
    (ProgramEnd), and the chamber gets a STATUS every ``heartbeat_s`` wall
    seconds so that its heartbeat (SETHB) sees the host alive."""

    def __init__(self, heartbeat_s: float | None, seq: SequenceCounter):
        self.heartbeat_s = heartbeat_s
        self._seq = seq
        self._last_beat = time.monotonic()

    def keep_alive(self, chamber: serial.Serial) -> None:
        if self.heartbeat_s is None or time.monotonic() - self._last_beat < self.heartbeat_s:
            return
        self._last_beat = time.monotonic()
        try:
            chamber.write(build_frame("STATUS", self._seq.next(), ()).encode("ascii"))
        except (serial.SerialException, OSError):
            raise EOFError from None


def _open_output(stack: ExitStack, path: Path, mode: str, **options: Any) -> _OutputFile:
    output = _OutputFile(path, mode, **options)
    stack.callback(output.close)
    return output
