"""A coefficient table (``thermotilt.surfaces``) on the wire: the IMU's EEPROM
block and the SETCOE/COE frames.

EEPROM block, 148 bytes, little-endian (the firmware's Compensation library
uses the same layout):

====== =====================================================================
bytes  content
====== =====================================================================
0      magic 0x54 ('T')
1      format version 1
2-145  36 float32: set (W, C) x axis (X, Y, Z) x (p00, p10, p01, p20, p11, p02)
146    CRC-16/XMODEM of bytes 0-145, low byte first
====== =====================================================================
"""

from __future__ import annotations

import binascii
import math
import struct
from collections.abc import Iterable

from ..surfaces import AXES, COEFFICIENT_NAMES, SETS, CoefficientTable, Surface, table_from_values
from .protocol import Frame, SequenceCounter, build_frame

MAGIC = 0x54
FORMAT_VERSION = 1
BLOCK_SIZE = 148
_COEFFICIENTS = struct.Struct("<36f")
_CRC = struct.Struct("<H")
_CRC_OFFSET = 2 + _COEFFICIENTS.size


class CoefficientBlockError(ValueError):
    """An EEPROM coefficient block that cannot be used."""


def crc16_xmodem(data: bytes) -> int:
    """CRC-16/XMODEM (poly 0x1021, init 0); b"123456789" -> 0x31C3."""
    return binascii.crc_hqx(data, 0)


def encode_block(table: CoefficientTable) -> bytes:
    body = bytes((MAGIC, FORMAT_VERSION)) + _COEFFICIENTS.pack(*table.values())
    return body + _CRC.pack(crc16_xmodem(body))


def decode_block(data: bytes) -> CoefficientTable:
    data = bytes(data)
    if len(data) != BLOCK_SIZE:
        raise CoefficientBlockError(f"coefficient block is {len(data)} bytes, expected {BLOCK_SIZE}")
    if data[0] != MAGIC:
        raise CoefficientBlockError(f"coefficient block magic is 0x{data[0]:02X}, expected 0x{MAGIC:02X}")
    if data[1] != FORMAT_VERSION:
        raise CoefficientBlockError(
            f"coefficient block format version {data[1]} is not supported (expected {FORMAT_VERSION})"
        )
    (stored_crc,) = _CRC.unpack_from(data, _CRC_OFFSET)
    computed_crc = crc16_xmodem(data[:_CRC_OFFSET])
    if stored_crc != computed_crc:
        raise CoefficientBlockError(f"coefficient block CRC is 0x{stored_crc:04X}, computed 0x{computed_crc:04X}")
    values = _COEFFICIENTS.unpack_from(data, 2)
    if not all(math.isfinite(value) for value in values):
        raise CoefficientBlockError("coefficient block holds a non-finite coefficient")
    return table_from_values(values)


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
