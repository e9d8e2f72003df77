import math
import struct

import pytest

from thermotilt.surfaces import AXES, PAPER_DEFAULTS, SETS, Surface, table_from_values
from thermotilt.wire.coefficients import (
    BLOCK_SIZE,
    V1_BLOCK_SIZE,
    CoefficientBlockError,
    SetDomain,
    crc16_xmodem,
    decode_block,
    domain_from_dom_frame,
    encode_block,
    sensor_id_problem,
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


NO_RANGE = struct.pack("<hh", 32767, -32768)


def v1_block(table):
    body = bytes([0x54, 0x01]) + struct.pack("<36f", *table.values())
    return with_crc(body)


def test_block_layout():
    block = encode_block(PAPER_DEFAULTS)
    assert len(block) == BLOCK_SIZE == 188
    assert block[0] == 0x54 and block[1] == 2
    # Cooling (set 1), Y (axis 1), p10 (term 1): 2 + 4 * (18 + 6 + 1) = 102.
    assert struct.unpack_from("<f", block, 102)[0] == pytest.approx(-12.82, rel=1e-7)
    # Warming X p00 is the first float.
    assert struct.unpack_from("<f", block, 2)[0] == 571.5
    # No sensor ID, no domain.
    assert block[146:154] == bytes(8) and block[154:186] == NO_RANGE * 8
    assert block[186:] == struct.pack("<H", bitwise_crc16_xmodem(block[:186]))
    # The same value is quoted in test/test_coefficient_block for the firmware side.
    assert bitwise_crc16_xmodem(block[:186]) == 0x5093


def test_block_with_an_id_and_a_domain():
    domain = {
        "W": SetDomain((-1012, 4498), {"X": (-16500, 16400), "Y": (-16450, 16420), "Z": None}),
        "C": SetDomain((-1005, 4501), {"X": (-16510, 16390), "Y": (-16440, 16410), "Z": None}),
    }
    block = encode_block(PAPER_DEFAULTS, "NODE-07", domain)
    assert block[146:154] == b"NODE-07\0"
    assert block[154:170] == struct.pack("<8h", -1012, 4498, -16500, 16400, -16450, 16420, 32767, -32768)
    assert block[170:186] == struct.pack("<8h", -1005, 4501, -16510, 16390, -16440, 16410, 32767, -32768)
    # Quoted in test/test_coefficient_block (test_block_id_and_domain_bytes).
    assert bitwise_crc16_xmodem(block[:186]) == 0x9062
    decoded = decode_block(block)
    assert (decoded.sensor_id, decoded.domain, decoded.version) == ("NODE-07", domain, 2)
    assert decoded.domain["W"].temperature_c == (-10.12, 44.98)


def test_zero_block_vector():
    zeros = table_from_values([0.0] * 36)
    block = encode_block(zeros)
    assert block == with_crc(bytes([0x54, 0x02]) + bytes(144) + bytes(8) + NO_RANGE * 8)


def test_round_trip_is_float32():
    decoded = decode_block(encode_block(PAPER_DEFAULTS)).table
    assert decoded == PAPER_DEFAULTS.to_float32()
    for s in SETS:
        for a in AXES:
            assert decoded.surface(s, a) == pytest.approx(PAPER_DEFAULTS.surface(s, a), rel=1e-6)


def test_version_1_blocks_decode_without_id_or_domain():
    block = v1_block(PAPER_DEFAULTS)
    assert len(block) == V1_BLOCK_SIZE
    # The firmware's test quotes the same CRC.
    assert bitwise_crc16_xmodem(block[:146]) == 0xD9E0
    decoded = decode_block(block)
    assert decoded.table == PAPER_DEFAULTS.to_float32()
    assert (decoded.sensor_id, decoded.version) == ("", 1)
    assert all(decoded.domain[s] == SetDomain() for s in SETS)


def test_domain_covering_rounds_outwards():
    domain = SetDomain.covering((-10.123, 44.981), {"X": (-16500.4, 16400.2), "Y": (-3.0, 4.0)})
    assert domain.temperature_centi_c == (-1013, 4499)
    assert domain.acceleration_lsb == {"X": (-16501, 16401), "Y": (-3, 4), "Z": None}
    clamped = SetDomain.covering((-400.0, 400.0), {"X": (-40000.0, 40000.0)})
    assert clamped.temperature_centi_c == (-32768, 32767) and clamped.acceleration_lsb["X"] == (-32768, 32767)
    with pytest.raises(ValueError, match="not a range"):
        SetDomain.covering((5.0, 4.0), {})


def test_dom_frame_round_trip():
    domain = SetDomain((-1013, 4499), {"X": (-16501, 16401), "Y": None, "Z": None})
    frame = parse_line(build_frame("DOM", 3, domain.setdom_values("C")))
    assert frame.raw_fields[:3] == ("C", "-10.13", "44.99")
    assert domain_from_dom_frame(frame) == domain
    unknown = parse_line(build_frame("DOM", 4, ["W", "nan", "nan", 32767, -32768, 0, -1, 32767, -32768]))
    assert domain_from_dom_frame(unknown) == SetDomain()
    with pytest.raises(ValueError, match="no calibrated temperature range"):
        SetDomain().setdom_values("W")


@pytest.mark.parametrize(
    "text, problem",
    [
        ("", None),
        ("NODE-07", None),
        ("a_b-C9", None),
        ("NODE-0007", "9 characters, at most 8"),
        ("NODE 7", "only letters, digits"),
        ("NODE.7", "only letters, digits"),
    ],
)
def test_sensor_id_rules(text, problem):
    if problem is None:
        assert sensor_id_problem(text) is None
    else:
        assert problem in sensor_id_problem(text)


@pytest.mark.parametrize("position", [0, 1, 2, 77, 145, 146, 150, 160, 185, 186, 187])
def test_any_flipped_byte_is_rejected(position):
    block = bytearray(encode_block(PAPER_DEFAULTS, "NODE-07"))
    block[position] ^= 0x01
    with pytest.raises(CoefficientBlockError):
        decode_block(bytes(block))


def test_error_messages():
    good = encode_block(PAPER_DEFAULTS)
    with pytest.raises(CoefficientBlockError, match=r"187 bytes, expected 188 \(148 in version 1\)"):
        decode_block(good[:-1])
    with pytest.raises(CoefficientBlockError, match="188 bytes, expected 148 for version 1"):
        decode_block(b"\x54\x01" + good[2:])
    with pytest.raises(CoefficientBlockError, match="magic is 0xFF"):
        decode_block(b"\xff" * 188)
    with pytest.raises(CoefficientBlockError, match="version 3 is not supported"):
        decode_block(with_crc(b"\x54\x03" + good[2:186]))
    with pytest.raises(CoefficientBlockError, match="CRC"):
        decode_block(good[:186] + b"\x00\x00")
    nan_body = b"\x54\x02" + struct.pack("<f", math.nan) + good[6:186]
    with pytest.raises(CoefficientBlockError, match="non-finite"):
        decode_block(with_crc(nan_body))
    spaced = good[:146] + b"NODE 7\0\0" + good[154:186]
    with pytest.raises(CoefficientBlockError, match="sensor ID field"):
        decode_block(with_crc(spaced))
    after_padding = good[:146] + b"AB\0C\0\0\0\0" + good[154:186]
    with pytest.raises(CoefficientBlockError, match="sensor ID field"):
        decode_block(with_crc(after_padding))
    with pytest.raises(ValueError, match="only letters"):
        encode_block(PAPER_DEFAULTS, "NODE 7")


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
