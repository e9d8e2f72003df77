"""Commands to a board, one at a time, each waiting for its answer.

A board answers every command with ACK or ERR whose ``cmd_seq`` is the
command's SEQ; a query sends its data frames (the ANSWER frames of
ProtocolFrames.def: VER, ICF, PRG, GRD, COE, DOM) just before the ACK
(docs/protocol.md). It reads commands through a 64-byte receive
ring (firmware/common/Uart0) and answers at the 115200-baud line rate, so a
host that sends the next command before the answer came overruns that
ring: in the twin (with Arduino's Serial, whose ring was the same size),
50 GETCOE (about 20 bytes each, each answered by about 110) sent back to back
got 10 answers, sent 9 ms apart 43, and only from 11 ms apart all 50.
:class:`CommandClient` therefore keeps one command in flight.

Retries: a command that gets no answer within the timeout is sent again with
a new SEQ, and only the answer to the latest attempt counts, so a late
answer to an earlier one is never mistaken for it. Every command but START
is safe to carry out twice: queries change nothing, SETDEC, SETCOE, SETDOM,
SETID, SETPRG, SETCTL, DEFCOE and STOP set a state that a second time leaves
as it is, and
SAVECOE writes bytes equal to those already stored (EEPROM.update skips
them), and a second RESET resets a board that has just reset, losing
nothing the first did not. START is sent once: on the chamber it restarts the staircase from
step 0, so a START that ran but whose ACK was lost would, sent again, throw
away the elapsed part of a calibration. After its timeout the board's state
is unknown; STATUS or the CHS phase tell. A refusal (ERR) is an answer and is
never retried.

The client talks to a pyserial port (a board, or the twin's ``--pty``), with
timeouts in wall-clock seconds, or to a :class:`thermotilt.twin.Board`
directly, which it runs while it waits, with timeouts in simulated seconds:
the same test gives the same bytes every time.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Protocol

from .protocol import ANSWER, FRAMES, Frame, FrameReader, SequenceCounter, build_frame

# The data frames that answer a query, sent right before its ACK.
ANSWER_DATA_TYPES = frozenset(tag for tag, spec in FRAMES.items() if spec.role == ANSWER)
NOT_RETRIED = frozenset({"START"})
# The longest answer, COE and ACK, is ~110 bytes: 9.5 ms at 115200 baud,
# behind at most one IMU or CHS frame already on the wire. 0.5 s leaves
# room for USB latency and a loaded host.
DEFAULT_TIMEOUT_S = 0.5
# A command or answer the line corrupted (the receiver drops the line) costs
# one attempt; two retries get through two such losses in a row.
DEFAULT_RETRIES = 2
# How long to sleep between looks at an idle serial port (12 byte times).
SERIAL_POLL_S = 0.001
# How far the twin runs per look at its line: one IMU sample period.
TWIN_STEP_S = 0.01


class CommandError(RuntimeError):
    """A command that was not carried out, or whose outcome is unknown."""

    def __init__(self, message: str, command: str):
        super().__init__(message)
        self.command = command


class CommandRefused(CommandError):
    """The board answered ERR: ``code`` and ``detail`` as docs/protocol.md lists them."""

    def __init__(self, command: str, error: Frame):
        self.code = error["code"]
        self.detail = error["detail"]
        super().__init__(f"{command} refused by the board: {self.code} {self.detail}", command)


class CommandTimeout(CommandError):
    """No answer within the timeout, after every attempt."""

    def __init__(self, command: str, attempts: int, timeout_s: float):
        self.attempts = attempts
        self.timeout_s = timeout_s
        unknown = " (not retried: the board's state is unknown, ask STATUS)" if command in NOT_RETRIED else ""
        super().__init__(f"{command}: no answer within {timeout_s:g} s, {attempts} attempt(s){unknown}", command)


@dataclass(frozen=True)
class Answer:
    """An ACK and the data frames that came before it."""

    ack: Frame
    data: tuple[Frame, ...]


class _Line(Protocol):
    def now(self) -> float: ...

    def write(self, data: bytes) -> None: ...

    def read(self, deadline: float) -> bytes: ...

    def read_waiting(self) -> bytes: ...


class _SerialLine:
    """A pyserial port: wall-clock time, polled without touching its settings."""

    def __init__(self, port: Any):
        self._port = port

    def now(self) -> float:
        return time.monotonic()

    def write(self, data: bytes) -> None:
        self._port.write(data)
        self._port.flush()

    def read(self, deadline: float) -> bytes:
        while True:
            waiting = self._port.in_waiting
            if waiting:
                return self._port.read(waiting)
            if time.monotonic() >= deadline:
                return b""
            time.sleep(SERIAL_POLL_S)

    def read_waiting(self) -> bytes:
        waiting = self._port.in_waiting
        return self._port.read(waiting) if waiting else b""


class _TwinLine:
    """A twin Board: simulated time, which passes only while the client waits."""

    def __init__(self, board: Any):
        self._board = board

    def now(self) -> float:
        return self._board.seconds

    def write(self, data: bytes) -> None:
        self._board.write_uart(data)

    def read(self, deadline: float) -> bytes:
        self._board.run_until(min(deadline, self._board.seconds + TWIN_STEP_S))
        return self._board.read_uart()

    def read_waiting(self) -> bytes:
        return self._board.read_uart()


class CommandClient:
    """Sends commands to one board and returns their answers.

    ``port`` is a pyserial ``Serial`` (anything with ``write``, ``flush``,
    ``in_waiting`` and ``read``) or a :class:`thermotilt.twin.Board`.
    Frames that answer no command (IMU, CHS, unsolicited ERR, late answers
    to earlier attempts) go to ``on_frame`` as they arrive, or are dropped
    without one. A Nano resets when its port is opened: wait for its VER
    before the first command.
    """

    def __init__(
        self,
        port: Any,
        *,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        retries: int = DEFAULT_RETRIES,
        on_frame: Callable[[Frame], None] | None = None,
        seq: SequenceCounter | None = None,
    ):
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be > 0, not {timeout_s!r}")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, not {retries!r}")
        self._line: _Line = _TwinLine(port) if hasattr(port, "write_uart") else _SerialLine(port)
        self.timeout_s = timeout_s
        self.retries = retries
        self._on_frame = on_frame
        self._seq = seq if seq is not None else SequenceCounter()
        self.reader = FrameReader()

    def command(self, frame_type: str, values: Iterable[Any] = ()) -> Answer:
        """Sends one command and waits for its ACK. Raises CommandRefused on
        ERR and CommandTimeout when no attempt was answered."""
        values = tuple(values)
        attempts = 1 if frame_type in NOT_RETRIED else 1 + self.retries
        for _ in range(attempts):
            # What arrived before the command cannot answer it (the VER a
            # board sends at start-up, a late answer to an earlier command).
            for frame in self.reader.feed(self._line.read_waiting()):
                self._pass_on(frame)
            seq = self._seq.next()
            self._line.write(build_frame(frame_type, seq, values).encode("ascii"))
            answer = self._await_answer(frame_type, seq, self._line.now() + self.timeout_s)
            if answer is not None:
                return answer
        raise CommandTimeout(frame_type, attempts, self.timeout_s)

    def wait_for(self, wanted: Callable[[Frame], bool], timeout_s: float) -> Frame | None:
        """Reads frames, sending nothing, until one is wanted or timeout_s
        has passed; every frame read goes to on_frame, the wanted one too.
        Returns the first wanted frame, or None. For what a board sends on
        its own: the VER after a reset, the next IMU frame."""
        deadline = self._line.now() + timeout_s
        found: Frame | None = None
        while found is None and self._line.now() < deadline:
            for frame in self.reader.feed(self._line.read(deadline)):
                self._pass_on(frame)
                if found is None and wanted(frame):
                    found = frame
        return found

    def _await_answer(self, frame_type: str, seq: int, deadline: float) -> Answer | None:
        data: list[Frame] = []
        while self._line.now() < deadline:
            outcome: Frame | None = None
            for frame in self.reader.feed(self._line.read(deadline)):
                if outcome is not None:
                    self._pass_on(frame)
                elif frame.type in ("ACK", "ERR") and frame["cmd_seq"] == seq:
                    outcome = frame
                elif frame.type in ANSWER_DATA_TYPES:
                    data.append(frame)
                elif frame.type in ("ACK", "ERR") and frame["cmd_seq"] >= 0:
                    # A late answer to an earlier attempt, with the data before it.
                    for late in (*data, frame):
                        self._pass_on(late)
                    data.clear()
                else:
                    self._pass_on(frame)
            if outcome is not None and outcome.type == "ERR":
                raise CommandRefused(frame_type, outcome)
            if outcome is not None:
                return Answer(outcome, tuple(data))
        return None

    def _pass_on(self, frame: Frame) -> None:
        if self._on_frame is not None:
            self._on_frame(frame)
