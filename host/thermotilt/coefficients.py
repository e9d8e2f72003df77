"""Thermal-drift compensation coefficients and their EEPROM block.

Each surface is the paper's Equation (3),
``f(x, y) = p00 + p10*x + p01*y + p20*x**2 + p11*x*y + p02*y**2``,
with x the temperature and y the inclination term; there is one surface per
set (W warming, C cooling) and axis (X, Y, Z).

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
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import NamedTuple

from .protocol import Frame, SequenceCounter, build_frame

SETS = ("W", "C")
AXES = ("X", "Y", "Z")
TERMS = ("p00", "p10", "p01", "p20", "p11", "p02")

MAGIC = 0x54
FORMAT_VERSION = 1
BLOCK_SIZE = 148
_COEFFICIENTS = struct.Struct("<36f")
_CRC = struct.Struct("<H")
_CRC_OFFSET = 2 + _COEFFICIENTS.size


class CoefficientBlockError(ValueError):
    """An EEPROM coefficient block that cannot be used."""


class Surface(NamedTuple):
    p00: float
    p10: float
    p01: float
    p20: float
    p11: float
    p02: float

    def evaluate(self, x: float, y: float) -> float:
        return (
            self.p00
            + self.p10 * x
            + self.p01 * y
            + self.p20 * x * x
            + self.p11 * x * y
            + self.p02 * y * y
        )


ZERO_SURFACE = Surface(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class CoefficientTable:
    """Six surfaces keyed by (set, axis), e.g. ("W", "X")."""

    surfaces: Mapping[tuple[str, str], Surface]

    def __post_init__(self) -> None:
        expected = {(s, a) for s in SETS for a in AXES}
        if set(self.surfaces) != expected:
            raise ValueError(f"coefficient table needs exactly the surfaces {sorted(expected)}")
        for key, surface in self.surfaces.items():
            if not all(math.isfinite(value) for value in surface):
                raise ValueError(f"surface {key} has a non-finite coefficient")

    def surface(self, set_: str, axis: str) -> Surface:
        return self.surfaces[(set_, axis)]

    def values(self) -> list[float]:
        """The 36 coefficients in block order."""
        return [value for s in SETS for a in AXES for value in self.surfaces[(s, a)]]

    def to_float32(self) -> CoefficientTable:
        """The table as the firmware holds it (float32)."""
        return table_from_values(_COEFFICIENTS.unpack(_COEFFICIENTS.pack(*self.values())))


def table_from_values(values: Iterable[float]) -> CoefficientTable:
    values = [float(value) for value in values]
    if len(values) != 36:
        raise ValueError(f"need 36 coefficients, got {len(values)}")
    surfaces = {}
    for index, key in enumerate((s, a) for s in SETS for a in AXES):
        surfaces[key] = Surface(*values[6 * index : 6 * index + 6])
    return CoefficientTable(surfaces)


# Sensors 2018, 18, 2536: Table 2 (X axis) and Table 3 (Y axis), point
# estimates as printed. The X cooling p01 (7.23e-4) lies outside its own
# printed confidence bounds (7.535e-4, 7.91e-4); it is kept as printed. The
# paper gives Z against the X and Y inclinations (Tables 4, 5), which do not
# fit one Z surface, so Z defaults to no correction.
PAPER_DEFAULTS = CoefficientTable(
    {
        ("W", "X"): Surface(571.5, -20.23, 1.569e-3, -0.1044, -6.936e-5, 6.327e-9),
        ("C", "X"): Surface(582.9, -21.29, 7.23e-4, -7.898e-2, -6.362e-5, -7.354e-8),
        ("W", "Y"): Surface(354.0, -13.96, 5.747e-3, -2.931e-3, -1.915e-4, -5.363e-8),
        ("C", "Y"): Surface(338.1, -12.82, 4.439e-3, -3.299e-2, -1.579e-4, -1.455e-8),
        ("W", "Z"): ZERO_SURFACE,
        ("C", "Z"): ZERO_SURFACE,
    }
)


def crc16_xmodem(data: bytes) -> int:
    """CRC-16/XMODEM (poly 0x1021, init 0); b"123456789" -> 0x31C3."""
    return binascii.crc_hqx(data, 0)


def encode_block(table: CoefficientTable) -> bytes:
    body = bytes((MAGIC, FORMAT_VERSION)) + _COEFFICIENTS.pack(*table.values())
    return body + _CRC.pack(crc16_xmodem(body))


def decode_block(data: bytes) -> CoefficientTable:
    data = bytes(data)
    if len(data) != BLOCK_SIZE:
        raise CoefficientBlockError(
            f"coefficient block is {len(data)} bytes, expected {BLOCK_SIZE}"
        )
    if data[0] != MAGIC:
        raise CoefficientBlockError(
            f"coefficient block magic is 0x{data[0]:02X}, expected 0x{MAGIC:02X}"
        )
    if data[1] != FORMAT_VERSION:
        raise CoefficientBlockError(
            f"coefficient block format version {data[1]} is not supported"
            f" (expected {FORMAT_VERSION})"
        )
    (stored_crc,) = _CRC.unpack_from(data, _CRC_OFFSET)
    computed_crc = crc16_xmodem(data[:_CRC_OFFSET])
    if stored_crc != computed_crc:
        raise CoefficientBlockError(
            f"coefficient block CRC is 0x{stored_crc:04X}, computed 0x{computed_crc:04X}"
        )
    values = _COEFFICIENTS.unpack_from(data, 2)
    if not all(math.isfinite(value) for value in values):
        raise CoefficientBlockError("coefficient block holds a non-finite coefficient")
    return table_from_values(values)


def setcoe_frames(table: CoefficientTable, seq: SequenceCounter | None = None) -> list[str]:
    """SETCOE command lines (with CR LF) for all six surfaces, in block order."""
    counter = seq if seq is not None else SequenceCounter()
    return [
        build_frame("SETCOE", counter.next(), [s, a, *table.surface(s, a)])
        for s in SETS
        for a in AXES
    ]


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
        surfaces[key] = Surface(*(frame[term] for term in TERMS))
    missing = [(s, a) for s in SETS for a in AXES if (s, a) not in surfaces]
    if missing:
        raise ValueError(f"no COE frame for surfaces {missing}")
    return CoefficientTable(surfaces)
