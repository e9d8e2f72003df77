"""``thermotilt log``: real boards (or the twin's pseudo-terminals) to run.csv.

The IMU reader's frames make the rows; the chamber's CHS frames, when its
port is given, fill the chamber columns. Each row is flushed as it is
written and the raw bytes can be kept, so stopping with Ctrl-C, or the board
going away, loses nothing already received.
"""

from __future__ import annotations

import sys
import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import serial

from .protocol import FrameReader
from .runlog import ChamberState, RunLogWriter

# Long enough for a 10 Hz stream to fill a read; short enough to watch both ports.
READ_TIMEOUT_S = 0.05
SILENCE_WARNING_S = 5.0


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
    except (serial.SerialException, ValueError) as error:
        raise LogError(f"cannot open {port}: {error}") from None


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
    imu_port: str,
    out_path: Path,
    chamber_port: str | None = None,
    baud: int = 115200,
    duration_s: float | None = None,
    max_rows: int | None = None,
    raw_dir: Path | None = None,
    context: Mapping[str, str] | None = None,
    force: bool = False,
) -> LogResult:
    if out_path.exists() and not force:
        raise LogError(f"{out_path} exists; choose another --out or add --force")
    context = dict(context or {})
    imu_reader, chamber_reader = FrameReader(), FrameReader()
    chamber_state = ChamberState.unknown()
    first_ms: int | None = None
    last_ms = 0
    stop = ""
    end_reason = "interrupted"
    started = time.monotonic()
    warned = False
    with ExitStack() as stack:
        imu = stack.enter_context(_open_port(imu_port, baud))
        chamber = stack.enter_context(_open_port(chamber_port, baud)) if chamber_port else None
        raw_imu = raw_chamber = None
        if raw_dir is not None:
            raw_dir.mkdir(parents=True, exist_ok=True)
            raw_imu = stack.enter_context(open(raw_dir / "imu_reader.txt", "ab"))
            if chamber is not None:
                raw_chamber = stack.enter_context(open(raw_dir / "thermal_chamber.txt", "ab"))
        stream = stack.enter_context(open(out_path, "w", newline=""))
        writer = RunLogWriter(stream, with_truth=False)
        try:
            while True:
                if chamber is not None:
                    data = _read_available(chamber, wait=False)
                    if raw_chamber is not None and data:
                        raw_chamber.write(data)
                    for frame in chamber_reader.feed(data):
                        if frame.type == "CHS":
                            chamber_state.update(frame)
                data = _read_available(imu, wait=True)
                if raw_imu is not None and data:
                    raw_imu.write(data)
                for frame in imu_reader.feed(data):
                    if frame.type != "IMU":
                        continue
                    last_ms = frame["t_ms"]
                    first_ms = last_ms if first_ms is None else first_ms
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
            end_reason = "interrupted"
    if writer.rows == 0:
        raise LogError(f"no IMU frames received from {imu_port} ({end_reason}); "
                       f"{imu_reader.malformed} malformed lines")
    return LogResult(writer.rows, imu_reader.frames + chamber_reader.frames,
                     imu_reader.malformed + chamber_reader.malformed,
                     imu_reader.gaps + chamber_reader.gaps, end_reason)
