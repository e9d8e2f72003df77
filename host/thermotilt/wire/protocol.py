"""ThermoTilt serial frames: ``$TYPE,SEQ,field,...*HHHH\\r\\n`` (docs/protocol.md).

The frame table comes from lib/Protocol/src/ProtocolFrames.def through the
generated module :mod:`thermotilt.protocol_spec`; the rules here mirror the
firmware's FrameParser so both sides accept and reject the same lines.
"""

from __future__ import annotations

import binascii
import math
import numbers
import re
from collections import Counter
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from . import protocol_spec

PROTOCOL_VERSION: int = protocol_spec.PROTOCOL_VERSION
MAX_LINE: int = protocol_spec.MAX_LINE
MAX_FIELDS: int = protocol_spec.MAX_FIELDS
SEQ_MODULUS = 65536

BOARD = "board"
HOST = "host"
# Frame roles (ProtocolFrames.def): what a frame type is for.
STREAM = "stream"  # board -> host on the board's own schedule (IMU, CHS)
ANSWER = "answer"  # board -> host: the data a query returns just before its ACK
OUTCOME = "outcome"  # board -> host: how a command ended (ACK, ERR)
COMMAND = "command"  # host -> board

# Malformed-frame reasons. The first nine match Protocol::MalformedReason in
# the firmware; FIELD_COUNT and BAD_FIELD come from checking the frame table,
# which the firmware leaves to each command handler.
TRUNCATED = "TRUNCATED"
TOO_LONG = "TOO_LONG"
BAD_CHAR = "BAD_CHAR"
NO_CHECKSUM = "NO_CHECKSUM"
BAD_CHECKSUM = "BAD_CHECKSUM"
BAD_TYPE = "BAD_TYPE"
BAD_SEQ = "BAD_SEQ"
TOO_MANY_FIELDS = "TOO_MANY_FIELDS"
FIELD_COUNT = "FIELD_COUNT"
BAD_FIELD = "BAD_FIELD"

_TYPE = re.compile(r"[A-Z]{2,7}")
_SEQ = re.compile(r"[0-9]{1,5}")
# The line check after '*': CRC-16/XMODEM as four hex digits (Protocol.h).
CHECKSUM_DIGITS = 4
_CHECKSUM_HEX = re.compile(rf"[0-9A-Fa-f]{{{CHECKSUM_DIGITS}}}")
_INTEGER = re.compile(r"[+-]?[0-9]+")
_FLOAT = re.compile(
    r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?(?:nan|inf|infinity)",
    re.IGNORECASE,
)
_NOT_PRINTABLE = re.compile(r"[^\x20-\x7e]")
_FORBIDDEN_IN_FIELD = re.compile(r"[^\x20-\x7e]|[,*$]")
_LINE_EVENT = re.compile(r"[$\r\n]")


@dataclass(frozen=True)
class FieldSpec:
    name: str
    kind: str  # "i" integer, "f" float, "t" text token


@dataclass(frozen=True)
class FrameSpec:
    tag: str
    direction: str  # BOARD (board -> host) or HOST (host -> board command)
    role: str  # STREAM, ANSWER, OUTCOME or COMMAND
    fields: tuple[FieldSpec, ...]

    @property
    def field_names(self) -> tuple[str, ...]:
        return tuple(spec.name for spec in self.fields)


FRAMES: dict[str, FrameSpec] = {
    tag: FrameSpec(tag, direction, role, tuple(FieldSpec(name, kind) for name, kind in fields))
    for tag, (direction, role, fields) in protocol_spec.FRAMES.items()
}


class MalformedFrame(ValueError):
    """A line that is not a valid frame; ``reason`` is one of the reason tokens."""

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


@dataclass(frozen=True)
class Frame:
    type: str
    seq: int
    # Field name -> int, float or str, per the frame table; empty for a type
    # the table does not know (a newer firmware), whose text is in raw_fields.
    fields: dict[str, Any]
    raw_fields: tuple[str, ...]

    def __getitem__(self, name: str) -> Any:
        return self.fields[name]

    @property
    def line(self) -> str:
        """The frame as sent, without CR LF."""
        body = ",".join((self.type, str(self.seq)) + self.raw_fields)
        return _with_checksum(body)


def checksum(body: str | bytes) -> int:
    """CRC-16/XMODEM of the bytes between '$' and '*', as the firmware's
    Protocol::checksum (avr-libc's _crc_xmodem_update)."""
    data = body.encode("latin-1") if isinstance(body, str) else bytes(body)
    return binascii.crc_hqx(data, 0)


def _with_checksum(body: str) -> str:
    return f"${body}*{checksum(body):0{CHECKSUM_DIGITS}X}"


def next_seq(seq: int) -> int:
    return (seq + 1) % SEQ_MODULUS


class SequenceCounter:
    """The host's own frame counter: 0, 1, ..., 65535, 0, ..."""

    def __init__(self, start: int = 0):
        self._next = start % SEQ_MODULUS

    def next(self) -> int:
        seq = self._next
        self._next = next_seq(seq)
        return seq


def format_value(value: Any) -> str:
    """Text of one field: integers in decimal, floats with 9 significant digits
    (enough to carry a float32 exactly), strings as they are."""
    if isinstance(value, str):
        text = value
    elif isinstance(value, numbers.Integral):
        text = str(int(value))
    elif isinstance(value, numbers.Real):
        number = float(value)
        if math.isnan(number):
            text = "nan"
        elif math.isinf(number):
            text = "inf" if number > 0 else "-inf"
        else:
            text = format(number, ".9g")
    else:
        raise TypeError(f"cannot put {type(value).__name__} in a frame field")
    if _FORBIDDEN_IN_FIELD.search(text):
        raise ValueError(f"field {text!r} contains a character not allowed in a field")
    return text


def build_frame(frame_type: str, seq: int, values: Iterable[Any] | Mapping[str, Any] = ()) -> str:
    """One frame line including CR LF. ``values`` are in table order, or a
    mapping by field name for a type in the frame table."""
    if not _TYPE.fullmatch(frame_type):
        raise ValueError(f"frame type {frame_type!r} is not 2 to 7 upper-case letters")
    if not isinstance(seq, numbers.Integral) or not 0 <= seq < SEQ_MODULUS:
        raise ValueError(f"seq {seq!r} is not in 0..65535")
    spec = FRAMES.get(frame_type)
    if isinstance(values, Mapping):
        if spec is None:
            raise ValueError(f"{frame_type} is not in the frame table; pass values in order")
        unknown = set(values) - set(spec.field_names)
        missing = [name for name in spec.field_names if name not in values]
        if unknown or missing:
            raise ValueError(f"{frame_type}: missing fields {missing}, unknown fields {sorted(unknown)}")
        values = [values[name] for name in spec.field_names]
    texts = [format_value(value) for value in values]
    if spec is not None:
        if len(texts) != len(spec.fields):
            raise ValueError(f"{frame_type} takes {len(spec.fields)} fields, got {len(texts)}")
        # What the reader would refuse is never sent.
        for field_spec, text in zip(spec.fields, texts, strict=True):
            try:
                _convert(field_spec, text)
            except MalformedFrame as error:
                raise ValueError(f"{frame_type}: {error.detail}") from None
    if len(texts) > MAX_FIELDS:
        raise ValueError(f"{len(texts)} fields, at most {MAX_FIELDS} allowed")
    body = ",".join([frame_type, str(int(seq))] + texts)
    line = _with_checksum(body)
    if len(line) > MAX_LINE:
        raise ValueError(f"{frame_type} frame is {len(line)} characters, at most {MAX_LINE}")
    return line + "\r\n"


def _split_body(body: str) -> tuple[str, int, tuple[str, ...]]:
    """Check the text after '$' (no CR LF) the way the firmware does."""
    if len(body) > MAX_LINE - 1:
        raise MalformedFrame(TOO_LONG, f"{len(body) + 1} characters, at most {MAX_LINE}")
    if _NOT_PRINTABLE.search(body):
        raise MalformedFrame(BAD_CHAR, "control or non-ASCII byte in the line")
    if "$" in body:
        raise MalformedFrame(TRUNCATED, "a '$' inside the line")
    star = body.find("*")
    if star < 0 or len(body) - star != 1 + CHECKSUM_DIGITS:
        raise MalformedFrame(NO_CHECKSUM, f"no '*' followed by {CHECKSUM_DIGITS} checksum digits")
    digits = body[star + 1 :]
    if not _CHECKSUM_HEX.fullmatch(digits):
        raise MalformedFrame(BAD_CHECKSUM, f"checksum {digits!r} is not hexadecimal")
    content = body[:star]
    expected = checksum(content)
    if int(digits, 16) != expected:
        raise MalformedFrame(BAD_CHECKSUM, f"checksum {digits}, computed {expected:0{CHECKSUM_DIGITS}X}")
    tokens = content.split(",")
    if not _TYPE.fullmatch(tokens[0]):
        raise MalformedFrame(BAD_TYPE, f"type {tokens[0]!r} is not 2 to 7 upper-case letters")
    if len(tokens) < 2 or not _SEQ.fullmatch(tokens[1]) or int(tokens[1]) >= SEQ_MODULUS:
        raise MalformedFrame(BAD_SEQ, "seq missing or not in 0..65535")
    raw_fields = tuple(tokens[2:])
    if len(raw_fields) > MAX_FIELDS:
        raise MalformedFrame(TOO_MANY_FIELDS, f"{len(raw_fields)} fields, at most {MAX_FIELDS}")
    return tokens[0], int(tokens[1]), raw_fields


def _convert(spec: FieldSpec, text: str) -> Any:
    if spec.kind == "i":
        if not _INTEGER.fullmatch(text):
            raise MalformedFrame(BAD_FIELD, f"{spec.name}={text!r} is not an integer")
        return int(text)
    if spec.kind == "f":
        if not _FLOAT.fullmatch(text):
            raise MalformedFrame(BAD_FIELD, f"{spec.name}={text!r} is not a number")
        return float(text)
    return text


def _typed_fields(frame_type: str, raw_fields: tuple[str, ...]) -> dict[str, Any]:
    spec = FRAMES.get(frame_type)
    if spec is None:
        return {}
    # More fields than the table lists are allowed: a newer firmware of the
    # same protocol version may append fields.
    if len(raw_fields) < len(spec.fields):
        raise MalformedFrame(FIELD_COUNT, f"{frame_type} needs {len(spec.fields)} fields, got {len(raw_fields)}")
    return {
        field_spec.name: _convert(field_spec, text) for field_spec, text in zip(spec.fields, raw_fields, strict=False)
    }


def parse_line(line: str | bytes) -> Frame:
    """Parse one line starting with '$' (a trailing CR LF or LF is allowed).
    Raises MalformedFrame."""
    text = line.decode("latin-1") if isinstance(line, (bytes, bytearray)) else line
    text = text.removesuffix("\n").removesuffix("\r")
    if not text.startswith("$"):
        raise MalformedFrame(TRUNCATED, "line does not start with '$'")
    frame_type, seq, raw_fields = _split_body(text[1:])
    return Frame(frame_type, seq, _typed_fields(frame_type, raw_fields), raw_fields)


@dataclass
class SequenceGaps:
    """Sequence tracking for one sender."""

    last_seq: int | None = None
    gaps: int = 0
    lost_frames: int = 0

    def update(self, seq: int) -> None:
        if self.last_seq is not None:
            missed = (seq - next_seq(self.last_seq)) % SEQ_MODULUS
            if missed:
                self.gaps += 1
                # A jump back (sender restarted, duplicate) is a gap but says
                # nothing about how many frames were lost.
                if missed < SEQ_MODULUS // 2:
                    self.lost_frames += missed
        self.last_seq = seq


_WAITING, _IN_LINE, _DISCARDING = range(3)


@dataclass
class FrameReader:
    """Turns a byte stream into frames, counting malformed lines and sequence
    gaps (tracked per direction, so a log of both directions works)."""

    frames_by_type: Counter = field(default_factory=Counter)
    malformed_by_reason: Counter = field(default_factory=Counter)
    sequences: dict[str, SequenceGaps] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._state = _WAITING
        self._parts: list[str] = []
        self._length = 0
        self._discard_reason = ""

    @property
    def frames(self) -> int:
        return sum(self.frames_by_type.values())

    @property
    def malformed(self) -> int:
        return sum(self.malformed_by_reason.values())

    @property
    def gaps(self) -> int:
        return sum(tracker.gaps for tracker in self.sequences.values())

    @property
    def lost_frames(self) -> int:
        return sum(tracker.lost_frames for tracker in self.sequences.values())

    def feed(self, data: bytes | bytearray | str) -> list[Frame]:
        """Consume a chunk; return the frames it completed."""
        text = bytes(data).decode("latin-1") if not isinstance(data, str) else data
        frames: list[Frame] = []
        position = 0
        while position < len(text):
            event = _LINE_EVENT.search(text, position)
            end = event.start() if event else len(text)
            if end > position and self._state == _IN_LINE:
                self._append(text[position:end])
            if event is None:
                break
            if event.group() == "$":
                self._end_partial_line()
                self._state = _IN_LINE
                self._parts = []
                self._length = 0
            else:
                if self._state == _IN_LINE:
                    frame = self._end_line()
                    if frame is not None:
                        frames.append(frame)
                elif self._state == _DISCARDING:
                    self._reject(self._discard_reason)
                self._state = _WAITING
            position = event.end()
        return frames

    def read_from(self, stream: Any, chunk_size: int = 4096) -> Iterator[Frame]:
        """Frames from a binary file-like object (a file, a serial.Serial)
        until read() returns nothing."""
        while True:
            chunk = stream.read(chunk_size)
            if not chunk:
                return
            yield from self.feed(chunk)

    def _end_partial_line(self) -> None:
        if self._state == _IN_LINE:
            self._reject(TRUNCATED)
        elif self._state == _DISCARDING:
            self._reject(self._discard_reason)

    def _append(self, segment: str) -> None:
        room = MAX_LINE - 1 - self._length
        bad_char = _NOT_PRINTABLE.search(segment)
        if bad_char is not None and bad_char.start() <= room:
            self._discard(BAD_CHAR)
        elif len(segment) > room:
            self._discard(TOO_LONG)
        else:
            self._parts.append(segment)
            self._length += len(segment)

    def _discard(self, reason: str) -> None:
        self._state = _DISCARDING
        self._discard_reason = reason
        self._parts = []

    def _reject(self, reason: str) -> None:
        self.malformed_by_reason[reason] += 1

    def _end_line(self) -> Frame | None:
        try:
            frame_type, seq, raw_fields = _split_body("".join(self._parts))
        except MalformedFrame as error:
            self._reject(error.reason)
            return None
        spec = FRAMES.get(frame_type)
        direction = spec.direction if spec else "unknown"
        self.sequences.setdefault(direction, SequenceGaps()).update(seq)
        try:
            fields = _typed_fields(frame_type, raw_fields)
        except MalformedFrame as error:
            self._reject(error.reason)
            return None
        self.frames_by_type[frame_type] += 1
        return Frame(frame_type, seq, fields, raw_fields)
