"""A coefficient table (``thermotilt.surfaces``) on the wire: the IMU's EEPROM
block and the SETCOE/SETDOM/COE frames.

EEPROM block, little-endian (the firmware's Compensation library uses the
same layout; ``host/tests/test_firmware_differential.py`` holds the two to
the same bytes). Version 2, 188 bytes:

======= =====================================================================
bytes   content
======= =====================================================================
0       magic 0x54 ('T')
1       format version 2
2-145   36 float32: set (W, C) x axis (X, Y, Z) x (p00, p10, p01, p20, p11, p02)
146-153 the sensor ID the surfaces were fitted for, ASCII, NUL-padded;
        all NUL: fitted for no particular sensor
154-185 the calibrated domain, int16: per set (W, C) the temperature min and
        max in 1/100 degC, then per axis (X, Y, Z) the acceleration min and
        max in LSB; a range whose min is above its max is none
186-187 CRC-16/XMODEM of bytes 0-185, low byte first
======= =====================================================================

Version 1, 148 bytes, is the same up to byte 145 and ends with its CRC at
146-147: no sensor ID (any sensor) and no domain (unknown). Both decode.
"""

from __future__ import annotations

import binascii
import math
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from ..surfaces import (
    AXES,
    COEFFICIENT_NAMES,
    SENSOR_ID_LENGTH,
    SETS,
    CoefficientTable,
    Surface,
    sensor_id_problem,
    table_from_values,
)
from .protocol import Frame, SequenceCounter, build_frame

MAGIC = 0x54
FORMAT_VERSION = 2
BLOCK_SIZE = 188
V1_BLOCK_SIZE = 148
BLOCK_SIZES = {1: V1_BLOCK_SIZE, FORMAT_VERSION: BLOCK_SIZE}
_COEFFICIENTS = struct.Struct("<36f")
_SENSOR_ID_FIELD = struct.Struct(f"<{SENSOR_ID_LENGTH}s")
_DOMAIN = struct.Struct("<16h")
_CRC = struct.Struct("<H")
_FLOATS_OFFSET = 2
_SENSOR_ID_OFFSET = _FLOATS_OFFSET + _COEFFICIENTS.size
_DOMAIN_OFFSET = _SENSOR_ID_OFFSET + _SENSOR_ID_FIELD.size
_CRC_OFFSET = _DOMAIN_OFFSET + _DOMAIN.size
INT16_MIN, INT16_MAX = -32768, 32767
CENTI = 100
# What the block writes for no range: min above max.
NO_RANGE = (INT16_MAX, INT16_MIN)


class CoefficientBlockError(ValueError):
    """An EEPROM coefficient block that cannot be used."""


def crc16_xmodem(data: bytes) -> int:
    """CRC-16/XMODEM (poly 0x1021, init 0); b"123456789" -> 0x31C3."""
    return binascii.crc_hqx(data, 0)


# The imu_reader's ID record (lib/Compensation/SensorId.h) and where its
# EEPROM keeps it (firmware/imu_reader/main.cpp); test_sensor_identity
# compares both with what the firmware's SETID writes.
SENSOR_ID_RECORD_ADDRESS = 512
_SENSOR_ID_RECORD_MAGIC = b"I"


def encode_sensor_id_record(sensor_id: str) -> bytes:
    """The 11-byte EEPROM record of a board whose ID is sensor_id."""
    problem = sensor_id_problem(sensor_id)
    if problem:
        raise ValueError(problem)
    body = _SENSOR_ID_RECORD_MAGIC + _SENSOR_ID_FIELD.pack(sensor_id.encode("ascii"))
    return body + _CRC.pack(crc16_xmodem(body))


Range = tuple[int, int]


def _int16(value: int) -> int:
    return min(max(value, INT16_MIN), INT16_MAX)


def _range_or_none(low: int, high: int) -> Range | None:
    return (low, high) if low <= high else None


@dataclass(frozen=True)
class SetDomain:
    """Where one set's surfaces were fitted, in the block's units: the
    temperature range in 1/100 degC and per axis the acceleration range in
    LSB, bounds included; None where there is none (an unknown temperature
    range, an axis not fitted)."""

    temperature_centi_c: Range | None = None
    acceleration_lsb: Mapping[str, Range | None] = field(default_factory=lambda: dict.fromkeys(AXES))

    @classmethod
    def covering(
        cls, temperature_c: tuple[float, float], acceleration_lsb: Mapping[str, tuple[float, float]]
    ) -> SetDomain:
        """The smallest domain in the block's units that holds these ranges
        (bounds rounded outwards), clamped to int16."""

        def outwards(low: float, high: float, scale: float) -> Range:
            if not (math.isfinite(low) and math.isfinite(high)) or low > high:
                raise ValueError(f"not a range: {low} .. {high}")
            return _int16(math.floor(low * scale)), _int16(math.ceil(high * scale))

        return cls(
            outwards(*temperature_c, CENTI),
            {axis: outwards(*acceleration_lsb[axis], 1) if axis in acceleration_lsb else None for axis in AXES},
        )

    @property
    def temperature_c(self) -> tuple[float, float] | None:
        if self.temperature_centi_c is None:
            return None
        low, high = self.temperature_centi_c
        return low / CENTI, high / CENTI

    def values(self) -> list[int]:
        """The eight int16 of the block: temperature min, max, then X, Y, Z min, max."""
        ranges = [self.temperature_centi_c, *(self.acceleration_lsb.get(axis) for axis in AXES)]
        return [bound for item in ranges for bound in (item if item is not None else NO_RANGE)]

    @classmethod
    def from_values(cls, values: Iterable[int]) -> SetDomain:
        bounds = list(values)
        ranges = [_range_or_none(bounds[i], bounds[i + 1]) for i in range(0, 8, 2)]
        return cls(ranges[0], dict(zip(AXES, ranges[1:], strict=True)))

    def setdom_values(self, set_name: str) -> list[str | int]:
        """The fields of SETDOM (and of the DOM answer) for this set; needs a
        temperature range."""
        if self.temperature_centi_c is None:
            raise ValueError(f"set {set_name} has no calibrated temperature range")
        low, high = self.temperature_centi_c
        return [set_name, f"{low / CENTI:.2f}", f"{high / CENTI:.2f}", *self.values()[2:]]


NO_DOMAIN: Mapping[str, SetDomain] = {set_name: SetDomain() for set_name in SETS}


@dataclass(frozen=True)
class CoefficientBlock:
    """What a block holds: the surfaces, the sensor ID they were fitted for
    ("" for none) and their calibrated domain per set."""

    table: CoefficientTable
    sensor_id: str = ""
    domain: Mapping[str, SetDomain] = field(default_factory=lambda: dict(NO_DOMAIN))
    version: int = FORMAT_VERSION


def encode_block(table: CoefficientTable, sensor_id: str = "", domain: Mapping[str, SetDomain] | None = None) -> bytes:
    """A version 2 block; ValueError for an ID that is not one."""
    problem = sensor_id_problem(sensor_id)
    if problem is not None:
        raise ValueError(problem)
    domain = NO_DOMAIN if domain is None else domain
    body = (
        bytes((MAGIC, FORMAT_VERSION))
        + _COEFFICIENTS.pack(*table.values())
        + _SENSOR_ID_FIELD.pack(sensor_id.encode("ascii"))
        + _DOMAIN.pack(*(value for set_name in SETS for value in domain[set_name].values()))
    )
    return body + _CRC.pack(crc16_xmodem(body))


def decode_block(data: bytes) -> CoefficientBlock:
    """A version 1 or 2 block; CoefficientBlockError, in one line, for
    anything the firmware would not load on a board of the block's ID."""
    data = bytes(data)
    if len(data) not in BLOCK_SIZES.values():
        raise CoefficientBlockError(
            f"coefficient block is {len(data)} bytes, expected {BLOCK_SIZE} ({V1_BLOCK_SIZE} in version 1)"
        )
    if data[0] != MAGIC:
        raise CoefficientBlockError(f"coefficient block magic is 0x{data[0]:02X}, expected 0x{MAGIC:02X}")
    version = data[1]
    if version not in BLOCK_SIZES:
        raise CoefficientBlockError(
            f"coefficient block format version {version} is not supported (expected 1 or {FORMAT_VERSION})"
        )
    size = BLOCK_SIZES[version]
    if len(data) != size:
        raise CoefficientBlockError(f"coefficient block is {len(data)} bytes, expected {size} for version {version}")
    (stored_crc,) = _CRC.unpack_from(data, size - _CRC.size)
    computed_crc = crc16_xmodem(data[: size - _CRC.size])
    if stored_crc != computed_crc:
        raise CoefficientBlockError(f"coefficient block CRC is 0x{stored_crc:04X}, computed 0x{computed_crc:04X}")
    values = _COEFFICIENTS.unpack_from(data, _FLOATS_OFFSET)
    if not all(math.isfinite(value) for value in values):
        raise CoefficientBlockError("coefficient block holds a non-finite coefficient")
    table = table_from_values(values)
    if version == 1:
        return CoefficientBlock(table, version=1)
    (id_field,) = _SENSOR_ID_FIELD.unpack_from(data, _SENSOR_ID_OFFSET)
    text, _, padding = id_field.partition(b"\0")
    sensor_id = text.decode("ascii", errors="replace")
    if padding.strip(b"\0") or sensor_id_problem(sensor_id) is not None:
        raise CoefficientBlockError(f"coefficient block's sensor ID field {id_field!r} is not an ID")
    bounds = _DOMAIN.unpack_from(data, _DOMAIN_OFFSET)
    domain = {set_name: SetDomain.from_values(bounds[8 * index : 8 * index + 8]) for index, set_name in enumerate(SETS)}
    return CoefficientBlock(table, sensor_id, domain, version)


def setcoe_frames(table: CoefficientTable, seq: SequenceCounter | None = None) -> list[str]:
    """SETCOE command lines (with CR LF) for all six surfaces, in block order."""
    counter = seq if seq is not None else SequenceCounter()
    return [build_frame("SETCOE", counter.next(), [s, a, *table.surface(s, a)]) for s in SETS for a in AXES]


def table_from_coe_frames(frames: Iterable[Frame]) -> CoefficientTable:
    """A table from the COE frames a board sent in answer to GETCOE; the last
    frame for a surface wins. Raises ValueError if a surface is missing."""
    surfaces = {}
    for frame in frames:
        if frame.type != "COE":
            continue
        key = (frame["set"], frame["axis"])
        if key[0] not in SETS or key[1] not in AXES:
            raise ValueError(f"COE frame {frame.seq} names unknown surface {key}")
        surfaces[key] = Surface(*(frame[term] for term in COEFFICIENT_NAMES))
    missing = [(s, a) for s in SETS for a in AXES if (s, a) not in surfaces]
    if missing:
        raise ValueError(f"no COE frame for surfaces {missing}")
    return CoefficientTable(surfaces)


def domain_from_dom_frame(frame: Frame) -> SetDomain:
    """The set's domain as a DOM frame (the answer to GETDOM) states it:
    temperatures in degC with two decimals (nan: unknown), accelerations in
    LSB."""
    low, high = frame["t_min_c"], frame["t_max_c"]
    temperature = None
    if math.isfinite(low) and math.isfinite(high):
        temperature = _range_or_none(round(low * CENTI), round(high * CENTI))
    acceleration = {axis: _range_or_none(frame[f"a{axis.lower()}_min"], frame[f"a{axis.lower()}_max"]) for axis in AXES}
    return SetDomain(temperature, acceleration)
