"""Frames in, run.csv rows out: the one path from what the boards send to
the run log, fed by the twin's board links (``thermotilt simulate``) or by
serial ports (``thermotilt log``, a campaign on real boards), so that the
two cannot disagree (docs/run-log.md).

A :class:`BoardStream` takes one board's bytes: it saves them to the
board's capture, parses them into frames and notes the board's firmware
(its first VER) and what it reported on its own. The :class:`FrameRecorder`
keeps the chamber's latest CHS frame, writes a row per IMU frame with the
ambient, the table's angles and the time since the table moved, and, for a
chamber program the host started, says when it is over.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol

from ..run.log import RunLogWriter, format_number
from ..run.summary import PROGRAM_DONE, BoardReport, chamber_fault
from .protocol import FRAMES, Frame, FrameReader

# (IMU frame field, run.csv column): copied as the board wrote them.
_IMU_FIELDS = (
    ("temp_c", "imu_temp_c"),
    ("ax_raw", "ax_raw"),
    ("ay_raw", "ay_raw"),
    ("az_raw", "az_raw"),
    ("ax_filt", "ax_filt"),
    ("ay_filt", "ay_filt"),
    ("az_filt", "az_filt"),
    ("ax_comp", "ax_comp"),
    ("ay_comp", "ay_comp"),
    ("az_comp", "az_comp"),
    ("comp_set", "comp_set"),
    ("coef_source", "coef_source"),
    ("temp_domain", "temp_domain"),
)

_CHS_FIELDS = (
    ("setpoint_c", "setpoint_c"),
    ("inner_c", "chamber_c"),
    ("outer_c", "outer_c"),
    ("pwm", "pwm"),
    ("dir", "direction"),
    ("phase", "phase"),
    ("fault", "chamber_fault"),
)

# Where each field sits in its frame, looked up once rather than per row.
_FIELD_INDEX = {
    frame_type: {name: index for index, name in enumerate(FRAMES[frame_type].field_names)}
    for frame_type in ("IMU", "CHS")
}


def _raw_field(frame: Frame, name: str) -> str:
    text = frame.raw_fields[_FIELD_INDEX[frame.type][name]]
    return "" if text.lower() == "nan" else text


def firmware_version(frame: Frame) -> str:
    """A VER frame as one line: "device firmware_version protocol N"."""
    return f"{frame['device']} {frame['firmware_version']} protocol {frame['protocol_version']}"


class Capture(Protocol):
    def write(self, data: bytes, /) -> Any: ...

    def flush(self) -> Any: ...


class BoardStream:
    """One board's bytes as they reach the host: saved to its capture
    (flushed at once with ``flush``, so a killed logger loses nothing
    received), parsed, and what the board said of itself noted. ``clock``
    gives the run's time for a reported error: simulated in the twin, wall
    seconds since the log began on a rig."""

    def __init__(self, name: str, capture: Capture | None, clock: Callable[[], float], flush: bool = False) -> None:
        self.name = name
        self.reader = FrameReader()
        self.firmware: str | None = None
        self.reported: list[str] = []
        self._capture = capture
        self._clock = clock
        self._flush = flush

    def feed(self, data: bytes) -> list[Frame]:
        if not data:
            return []
        if self._capture is not None:
            self._capture.write(data)
            if self._flush:
                self._capture.flush()
        frames = self.reader.feed(data)
        for frame in frames:
            if frame.type == "ERR" and frame["cmd_seq"] == -1:
                self.reported.append(f"{frame['code']} {frame['detail']} at {self._clock():.2f} s")
            elif frame.type == "VER" and self.firmware is None:
                self.firmware = firmware_version(frame)
        return frames

    def report(self, **more: Any) -> BoardReport:
        """The counts of what arrived; ``more`` adds what the producer knows
        (a port, the twin's cycles and commands)."""
        reader = self.reader
        return BoardReport(
            frames=reader.frames,
            frames_by_type=dict(sorted(reader.frames_by_type.items())),
            rejected=reader.malformed,
            rejected_by_reason=dict(sorted(reader.malformed_by_reason.items())),
            sequence_gaps=reader.gaps,
            reported_errors=self.reported,
            firmware=self.firmware,
            **more,
        )


class ProgramEnd:
    """When a chamber program the host started is over, from its CHS
    phases: done (D) or idle (I) after warming, cooling or rest (W, C, R),
    or a fault (F) at any time. A fault latches until the host sends CLEAR
    (docs/protocol.md), which no producer sends while it records, so the
    program cannot go on after F."""

    def __init__(self) -> None:
        self._ran = False

    def reason(self, status: Frame) -> str:
        """PROGRAM_DONE, "chamber fault NAME", or "" while it runs."""
        phase = status["phase"]
        if phase == "F":
            return chamber_fault(status["fault"])
        self._ran |= phase in ("W", "C", "R")
        return PROGRAM_DONE if self._ran and phase in ("D", "I") else ""


class FrameRecorder:
    """Writes a run.csv row per IMU frame: the frame's fields as the board
    wrote them, the chamber's latest CHS frame (empty cells before the
    first), and what the host knows of the rig: ambient, the table's
    angles and the time since it moved. ``watch_program``: ``end_reason``
    says when the chamber's program is over (ProgramEnd)."""

    def __init__(self, writer: RunLogWriter, watch_program: bool = False) -> None:
        self.writer = writer
        self.end_reason = ""
        self._program = ProgramEnd() if watch_program else None
        self._chamber = {column: "" for _, column in _CHS_FIELDS}
        self._rig = {"ambient_c": "", "incl_x_deg": "", "incl_y_deg": "", "since_move_s": ""}
        self._moved_at_s: float | None = None
        self._move_pending = False

    @property
    def rows(self) -> int:
        return self.writer.rows

    def set_ambient(self, ambient_c: float | None) -> None:
        self._rig["ambient_c"] = format_number(ambient_c, 3)

    def move_table(
        self, incl_x_deg: float | None, incl_y_deg: float | None, at_s: float | None = None, first_frame: bool = False
    ) -> None:
        """The table's angles (None: unknown) from now on. It moved at
        ``at_s`` on the clock record_imu's ``received_s`` uses, or, with
        ``first_frame``, just before the next IMU frame (a log that begins
        right after the table was set and the IMU's filters restarted). Without
        either, when it moved is unknown and since_move_s stays empty."""
        self._rig["incl_x_deg"] = format_number(incl_x_deg, 2)
        self._rig["incl_y_deg"] = format_number(incl_y_deg, 2)
        self._moved_at_s = at_s
        self._move_pending = first_frame

    def record_chamber(self, frames: list[Frame]) -> None:
        for frame in frames:
            if frame.type != "CHS":
                continue
            for field_name, column in _CHS_FIELDS:
                self._chamber[column] = _raw_field(frame, field_name)
            if self._program is not None:
                self.end_reason = self._program.reason(frame) or self.end_reason

    def record_imu(self, frame: Frame, received_s: float | None = None, truth: Mapping[str, str] | None = None) -> None:
        """A row for an IMU frame that reached the host at ``received_s``
        (None: the frame's own board time counts); ``truth``: the twin's
        true_* cells."""
        if received_s is None:
            received_s = frame["t_ms"] / 1000.0
        if self._move_pending:
            self._moved_at_s, self._move_pending = received_s, False
        if self._moved_at_s is not None:
            self._rig["since_move_s"] = format_number(received_s - self._moved_at_s, 2)
        row: dict[str, str] = {"time_s": format_number(frame["t_ms"] / 1000.0, 3), "imu_seq": str(frame.seq)}
        for field_name, column in _IMU_FIELDS:
            row[column] = _raw_field(frame, field_name)
        row.update(self._chamber)
        row.update(self._rig)
        if truth is not None:
            row.update(truth)
        self.writer.write_row(row)
