"""``thermotilt log``: real boards (or the twin's pseudo-terminals) to run.csv.

The IMU reader's frames make the rows; the chamber's CHS frames, when its
port is given, fill the chamber columns. Each row, and each chunk of raw
bytes when they are kept, is flushed as it is written, so stopping with
Ctrl-C, the board going away or the logger being killed loses nothing
already received.
"""

from __future__ import annotations

import os
import sys
import time
from contextlib import ExitStack, contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Mapping

import serial

from .protocol import Frame, FrameReader, SequenceCounter, build_frame
from ..run.log import ChamberState, RunLogWriter

# Long enough for a 10 Hz stream to fill a read; short enough to watch both ports.
READ_TIMEOUT_S = 0.05
SILENCE_WARNING_S = 5.0
INTERRUPTED = "interrupted"


class LogError(RuntimeError):
    """A log that cannot start or that received nothing; one readable line."""


@dataclass(frozen=True)
class LogResult:
    rows: int
    frames: int
    rejected: int
    gaps: int
    end_reason: str


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
    out_path: Path,
    chamber_port: str | serial.Serial | None = None,
    baud: int = 115200,
    duration_s: float | None = None,
    max_rows: int | None = None,
    raw_dir: Path | None = None,
    context: Mapping[str, str] | None = None,
    force: bool = False,
    program: ProgramWatch | None = None,
) -> LogResult:
    """Logs until the duration, the row count, a closed port, Ctrl-C or, with
    ``program``, the chamber's program ending. A port given open stays open."""
    # os.path answers False where pathlib raises (a parent that cannot be
    # searched); opening the file then says why.
    if os.path.isdir(out_path):
        raise LogError(f"{out_path} is a folder; --out names the run.csv to write")
    if os.path.exists(out_path) and not force:
        raise LogError(f"{out_path} exists; choose another --out or add --force")
    context = dict(context or {})
    imu_reader, chamber_reader = FrameReader(), FrameReader()
    chamber_state = ChamberState.unknown()
    first_ms: int | None = None
    last_ms = 0
    stop = end_reason = ""
    started = time.monotonic()
    warned = False
    with ExitStack() as stack:
        imu = _opened(stack, imu_port, baud)
        chamber = _opened(stack, chamber_port, baud) if chamber_port is not None else None
        raw_imu = raw_chamber = None
        if raw_dir is not None:
            try:
                raw_dir.mkdir(parents=True, exist_ok=True)
            except OSError as error:
                raise LogError(f"cannot create folder {raw_dir}: {error.strerror or error}") from None
            raw_imu = _open_output(stack, raw_dir / "imu_reader.txt", "ab")
            if chamber is not None:
                raw_chamber = _open_output(stack, raw_dir / "thermal_chamber.txt", "ab")
        writer = RunLogWriter(_open_output(stack, out_path, "w", newline=""), with_truth=False)
        try:
            while True:
                if chamber is not None:
                    data = _read_available(chamber, wait=False)
                    _save_raw(raw_chamber, data)
                    for frame in chamber_reader.feed(data):
                        if frame.type == "CHS":
                            chamber_state.update(frame)
                            if program is not None:
                                stop = program.ended(frame) or stop
                    if program is not None:
                        program.keep_alive(chamber)
                data = _read_available(imu, wait=True)
                _save_raw(raw_imu, data)
                for frame in imu_reader.feed(data):
                    if frame.type != "IMU":
                        continue
                    last_ms = frame["t_ms"]
                    first_ms = last_ms if first_ms is None else first_ms
                    if program is not None:
                        # The table was set and the filters restarted just before the log began.
                        context["since_move_s"] = f"{(last_ms - first_ms) / 1000.0:.2f}"
                    if duration_s is not None and (last_ms - first_ms) / 1000.0 > duration_s:
                        stop = f"{duration_s:g} s of board time"
                        break
                    writer.write_imu_frame(frame, chamber_state, context)
                    if max_rows is not None and writer.rows >= max_rows:
                        stop = f"{max_rows} rows"
                        break
                if stop:
                    end_reason = stop
                    break
                if not warned and writer.rows == 0 and time.monotonic() - started > SILENCE_WARNING_S:
                    warned = True
                    print(f"thermotilt: no IMU frames from {imu_port} yet "
                          f"({imu_reader.malformed} malformed; is the baud rate {baud}?)",
                          file=sys.stderr)
        except EOFError:
            end_reason = "port closed"
        except KeyboardInterrupt:
            end_reason = INTERRUPTED
    if writer.rows == 0 and end_reason != INTERRUPTED:
        raise LogError(f"no IMU frames received from {imu_port} ({end_reason}); "
                       f"{imu_reader.malformed} malformed lines")
    return LogResult(writer.rows, imu_reader.frames + chamber_reader.frames,
                     imu_reader.malformed + chamber_reader.malformed,
                     imu_reader.gaps + chamber_reader.gaps, end_reason)


def _opened(stack: ExitStack, port: str | serial.Serial, baud: int) -> serial.Serial:
    return stack.enter_context(_open_port(port, baud)) if isinstance(port, str) else port


class ProgramWatch:
    """For a chamber program the host started: ends the log when the CHS
    phase reaches done (D) or idle (I) after running, or a fault (F), and
    sends the chamber a STATUS every ``heartbeat_s`` wall seconds so that
    its heartbeat (SETHB) sees the host alive."""

    def __init__(self, heartbeat_s: float | None, seq: SequenceCounter):
        self.heartbeat_s = heartbeat_s
        self._seq = seq
        self._last_beat = time.monotonic()
        self._ran = False
        self.fault = ""

    def ended(self, frame: Frame) -> str:
        phase = frame["phase"]
        if phase == "F":
            self.fault = frame["fault"]
            return f"chamber fault {self.fault}"
        self._ran |= phase in ("W", "C", "R")
        return "program done" if self._ran and phase in ("D", "I") else ""

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


def _save_raw(capture: _OutputFile | None, data: bytes) -> None:
    if capture is not None and data:
        capture.write(data)
        capture.flush()
