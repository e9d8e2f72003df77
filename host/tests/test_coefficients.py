import math
import struct

import pytest

from thermotilt.surfaces import AXES, PAPER_DEFAULTS, SETS, Surface, table_from_values
from thermotilt.wire.coefficients import (
    BLOCK_SIZE,
    CoefficientBlockError,
    crc16_xmodem,
    decode_block,
    encode_block,
    setcoe_frames,
    table_from_coe_frames,
)
from thermotilt.wire.protocol import MAX_LINE, FrameReader, build_frame, parse_line


def bitwise_crc16_xmodem(data):
    """Independent CRC-16/XMODEM: poly 0x1021, init 0, no reflection."""
    crc = 0
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc


def with_crc(body):
    return body + struct.pack("<H", bitwise_crc16_xmodem(body))


def test_crc_check_value():
    # The catalogued check value of CRC-16/XMODEM.
    assert crc16_xmodem(b"123456789") == 0x31C3
    assert bitwise_crc16_xmodem(b"123456789") == 0x31C3


def test_paper_defaults():
    # Sensors 2018, 18, 2536, Table 2 (X) and Table 3 (Y).
    assert PAPER_DEFAULTS.surface("W", "X") == (
        571.5,
        -20.23,
        1.569e-3,
        -0.1044,
        -6.936e-5,
        6.327e-9,
    )
    assert PAPER_DEFAULTS.surface("C", "X").p02 == -7.354e-8
    assert PAPER_DEFAULTS.surface("W", "Y").p00 == 354
    assert PAPER_DEFAULTS.surface("C", "Y") == (
        338.1,
        -12.82,
        4.439e-3,
        -3.299e-2,
        -1.579e-4,
        -1.455e-8,
    )
    assert PAPER_DEFAULTS.surface("W", "Z") == (0,) * 6 == PAPER_DEFAULTS.surface("C", "Z")


def test_surface_evaluate():
    # 1 + 2*2 + 3*3 + 4*4 + 5*2*3 + 6*9 = 114, by hand.
    assert Surface(1, 2, 3, 4, 5, 6).evaluate(2, 3) == 114


def test_block_layout():
    block = encode_block(PAPER_DEFAULTS)
    assert len(block) == BLOCK_SIZE == 148
    assert block[0] == 0x54 and block[1] == 1
    # Cooling (set 1), Y (axis 1), p10 (term 1): 2 + 4 * (18 + 6 + 1) = 102.
    assert struct.unpack_from("<f", block, 102)[0] == pytest.approx(-12.82, rel=1e-7)
    # Warming X p00 is the first float.
    assert struct.unpack_from("<f", block, 2)[0] == 571.5
    assert block[146:] == struct.pack("<H", bitwise_crc16_xmodem(block[:146]))
    # The same value is quoted in test/test_compensation for the firmware side.
    assert bitwise_crc16_xmodem(block[:146]) == 0xD9E0


def test_zero_block_vector():
    zeros = table_from_values([0.0] * 36)
    block = encode_block(zeros)
    assert block == with_crc(bytes([0x54, 0x01]) + bytes(144))


def test_round_trip_is_float32():
    decoded = decode_block(encode_block(PAPER_DEFAULTS))
    assert decoded == PAPER_DEFAULTS.to_float32()
    for s in SETS:
        for a in AXES:
            assert decoded.surface(s, a) == pytest.approx(PAPER_DEFAULTS.surface(s, a), rel=1e-6)


@pytest.mark.parametrize("position", [0, 1, 2, 77, 145, 146, 147])
def test_any_flipped_byte_is_rejected(position):
    block = bytearray(encode_block(PAPER_DEFAULTS))
    block[position] ^= 0x01
    with pytest.raises(CoefficientBlockError):
        decode_block(bytes(block))


def test_error_messages():
    good = encode_block(PAPER_DEFAULTS)
    with pytest.raises(CoefficientBlockError, match="147 bytes, expected 148"):
        decode_block(good[:-1])
    with pytest.raises(CoefficientBlockError, match="magic is 0xFF"):
        decode_block(b"\xff" * 148)
    with pytest.raises(CoefficientBlockError, match="version 2 is not supported"):
        decode_block(with_crc(b"\x54\x02" + good[2:146]))
    with pytest.raises(CoefficientBlockError, match="CRC"):
        decode_block(good[:146] + b"\x00\x00")
    nan_body = b"\x54\x01" + struct.pack("<f", math.nan) + good[6:146]
    with pytest.raises(CoefficientBlockError, match="non-finite"):
        decode_block(with_crc(nan_body))


def test_table_rejects_bad_content():
    with pytest.raises(ValueError, match="36"):
        table_from_values([0.0] * 35)
    with pytest.raises(ValueError, match="non-finite"):
        table_from_values([math.inf] + [0.0] * 35)


def test_setcoe_frames_round_trip():
    lines = setcoe_frames(PAPER_DEFAULTS)
    assert len(lines) == 6
    frames = [parse_line(line) for line in lines]
    assert [f.seq for f in frames] == list(range(6))
    assert [(f["set"], f["axis"]) for f in frames] == [(s, a) for s in SETS for a in AXES]
    assert frames[0]["p02"] == 6.327e-9
    # The board answers GETCOE with COE frames carrying the same fields.
    coe = "".join(build_frame("COE", 100 + i, f.raw_fields) for i, f in enumerate(frames))
    assert table_from_coe_frames(FrameReader().feed(coe)) == PAPER_DEFAULTS


def test_setcoe_longest_values_fit_and_keep_float32():
    # The longest 9-digit text: negative, 9 digits, two-digit negative exponent.
    extreme = table_from_values([-1.17549435e-38, -3.40282347e38, -1.23456789e-12] * 12).to_float32()
    lines = setcoe_frames(extreme)
    for line in lines:
        assert len(line.rstrip("\r\n")) <= MAX_LINE
    frames = [parse_line(line) for line in lines]
    coe = "".join(build_frame("COE", f.seq, f.raw_fields) for f in frames)
    assert table_from_coe_frames(FrameReader().feed(coe)).to_float32() == extreme


def test_missing_surface_reported():
    frames = [parse_line(line) for line in setcoe_frames(PAPER_DEFAULTS)]
    coe = FrameReader().feed("".join(build_frame("COE", f.seq, f.raw_fields) for f in frames[:5]))
    with pytest.raises(ValueError, match=r"\('C', 'Z'\)"):
        table_from_coe_frames(coe)
