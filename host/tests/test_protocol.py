import importlib.util
import math
import re
from pathlib import Path

import pytest

from thermotilt.wire import protocol, protocol_spec
from thermotilt.wire.protocol import (
    FRAMES,
    FrameReader,
    MalformedFrame,
    SequenceCounter,
    build_frame,
    checksum,
    parse_line,
)

HOST_DIR = Path(__file__).resolve().parents[1]
REPO_DIR = HOST_DIR.parent
DEFINITION = REPO_DIR / "lib" / "Protocol" / "src" / "ProtocolFrames.def"

# The same vectors as test/test_protocol and test/test_frame_writer. Checksums were
# computed independently ("%04X" % binascii.crc_hqx(body, 0), CRC-16/XMODEM)
VECTORS = [
    "$START,1*80BD",
    "$VER,0,imu_reader,0.2.0,2,POWER_ON*5BB9",
    "$ACK,0,13,STOP*B192",
    "$ACK,65535,12,SETPRG*7DCE",
    "$ERR,8,-1,BAD_CHECKSUM,CMD*9211",
    # hold_start appended: the C++ test keeps the 6-field line (its parser counts no fields).
    "$SETPRG,9,-10.00,45.00,2.00,60,1200,1,T*B58A",
    "$GETCOE,3,C,Y*C2AC",
    "$IMU,42,123456,-1650,-388,16012,-1649.75,-388.50,16012.25,-1078.25,-34.50,16011.00,23.50,W,E,I*765D",
    "$COE,7,W,X,5.7150e+02,-2.0230e+01,1.5690e-03,-1.0440e-01,-6.9360e-05,6.3270e-09*FCD1",
]
LONGEST = "$LONG,0," + "A" * 107 + "*E008"  # 120 characters


def read_all(data, chunk=None):
    reader = FrameReader()
    if chunk is None:
        frames = reader.feed(data)
    else:
        frames = [f for i in range(0, len(data), chunk) for f in reader.feed(data[i : i + chunk])]
    return reader, frames


@pytest.mark.parametrize("line", VECTORS + [LONGEST])
def test_checksum_vectors(line):
    body, digits = line[1:].split("*")
    assert checksum(body) == int(digits, 16)
    assert parse_line(line + "\r\n").line == line


def test_checksum_by_hand():
    assert checksum("123456789") == 0x31C3  # CRC-16/XMODEM's check value
    assert checksum("START,1") == 0x80BD
    assert checksum("ERR,1,-0.1") == 0x2330
    assert checksum(b"START,1") == 0x80BD


def test_frame_table_has_the_fields_and_directions_of_docs_protocol():
    # Field lists typed from docs/protocol.md, independently of the .def file.
    assert FRAMES["IMU"].field_names == (
        "t_ms",
        "ax_raw",
        "ay_raw",
        "az_raw",
        "ax_filt",
        "ay_filt",
        "az_filt",
        "ax_comp",
        "ay_comp",
        "az_comp",
        "temp_c",
        "comp_set",
        "coef_source",
        "temp_domain",
    )
    assert FRAMES["ICF"].field_names == ("decimation", "streaming", "coef_source", "hysteresis_c", "sensor_id")
    assert FRAMES["CHS"].field_names == (
        "t_ms",
        "phase",
        "step",
        "setpoint_c",
        "inner_c",
        "outer_c",
        "pwm",
        "dir",
        "fault",
    )
    assert FRAMES["PRG"].field_names == (
        "start_c",
        "max_c",
        "step_c",
        "hold_s",
        "rest_s",
        "cycles",
        "mode",
        "kp",
        "ki",
        "accepted",
        "hold_start",
    )
    assert FRAMES["SETPRG"].field_names == FRAMES["PRG"].field_names[:6] + ("hold_start",)
    assert FRAMES["VER"].field_names == ("device", "firmware_version", "protocol_version", "reset_cause")
    assert FRAMES["SETGRD"].field_names == FRAMES["GRD"].field_names[:-1]
    assert FRAMES["GRD"].field_names[-1] == "heartbeat_s"
    assert FRAMES["SETHB"].field_names == ("timeout_s",)
    assert FRAMES["SETCOE"].field_names == FRAMES["COE"].field_names
    assert (
        FRAMES["SETDOM"].field_names
        == FRAMES["DOM"].field_names
        == (
            "set",
            "t_min_c",
            "t_max_c",
            "ax_min",
            "ax_max",
            "ay_min",
            "ay_max",
            "az_min",
            "az_max",
        )
    )
    assert FRAMES["GETDOM"].field_names == ("set",)
    assert FRAMES["SETID"].field_names == ("sensor_id",)
    assert FRAMES["ERR"].field_names == ("cmd_seq", "code", "detail")
    board = {tag for tag, spec in FRAMES.items() if spec.direction == "board"}
    assert board == {"IMU", "CHS", "VER", "ICF", "PRG", "GRD", "COE", "DOM", "ACK", "ERR"}
    host = {tag for tag, spec in FRAMES.items() if spec.direction == "host"}
    assert host == {
        "START",
        "STOP",
        "VERSION",
        "STATUS",
        "SETPRG",
        "SETCTL",
        "SETDEC",
        "GETCOE",
        "SETCOE",
        "SAVECOE",
        "DEFCOE",
        "GETDOM",
        "SETDOM",
        "SETID",
        "SETGRD",
        "SETHB",
        "CLEAR",
        "RESEED",
        "RESET",
    }


def docs_frame_titles(text):
    """Tag -> the title of its section in docs/protocol.md ("### IMU — ...")."""
    return dict(re.findall(r"^### ([A-Z]{2,7}) — (.*)$", text, re.MULTILINE))


def docs_query_data(text):
    """The frames docs/protocol.md's command table lists in an answer besides
    ACK and ERR (e.g. "ICF (imu) or PRG and GRD (chamber), ACK")."""
    section = text[text.index("## Host → board commands") :]
    section = section[: section.index("\n## ", 1)]
    frames = set()
    for line in section.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) == 4 and cells[0].startswith("`$"):
            frames.update(word for word in re.findall(r"\b[A-Z]{2,7}\b", cells[3]) if word in FRAMES)
    return frames - {"ACK", "ERR"}


def test_frame_roles_are_the_ones_the_docs_describe():
    docs = REPO_DIR / "docs" / "protocol.md"
    if not docs.exists():
        pytest.skip("not in the ThermoTilt repository: no docs/protocol.md")
    text = docs.read_text()
    roles = {
        role: {tag for tag, spec in FRAMES.items() if spec.role == role}
        for role in (protocol.STREAM, protocol.ANSWER, protocol.OUTCOME, protocol.COMMAND)
    }
    assert sum(len(tags) for tags in roles.values()) == len(FRAMES)
    titles = docs_frame_titles(text)
    assert {tag for tag, title in titles.items() if "answer to" in title} == roles[protocol.ANSWER]
    assert docs_query_data(text) == roles[protocol.ANSWER] == {"VER", "ICF", "PRG", "GRD", "COE", "DOM"}
    assert roles[protocol.STREAM] == {"IMU", "CHS"}
    assert roles[protocol.OUTCOME] == {"ACK", "ERR"}
    assert all(FRAMES[tag].direction == protocol.HOST for tag in roles[protocol.COMMAND])
    assert all(spec.direction == protocol.BOARD for spec in FRAMES.values() if spec.role != protocol.COMMAND)


def load_generator():
    spec = importlib.util.spec_from_file_location("generator", HOST_DIR / "tools" / "generate_protocol_spec.py")
    generator = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(generator)
    return generator


def test_generated_spec_is_fresh():
    if not DEFINITION.exists():
        pytest.skip("not in the ThermoTilt repository: no ProtocolFrames.def")
    expected = load_generator().render(DEFINITION.read_text())
    assert Path(protocol_spec.__file__).read_text() == expected, (
        "thermotilt/protocol_spec.py is stale: run host/tools/generate_protocol_spec.py"
    )


def docs_err_table(text):
    """docs/protocol.md's ERR table as [(code, {token in its detail cell})]; a
    token is a back-quoted upper-case word of two characters or more."""
    section = text[text.index("### ERR") :]
    section = section[: section.index("\n## ")]
    rows = []
    for line in section.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        code = re.fullmatch(r"`([A-Z][A-Z0-9_]+)`", cells[0])
        if len(cells) == 3 and code:
            rows.append((code.group(1), set(re.findall(r"`([A-Z][A-Z0-9_]+)`", cells[2]))))
    return rows


def test_docs_err_table_has_every_code_and_detail_token_of_the_definition():
    docs = REPO_DIR / "docs" / "protocol.md"
    if not docs.exists():
        pytest.skip("not in the ThermoTilt repository: no docs/protocol.md")
    rows = docs_err_table(docs.read_text())
    assert [code for code, _ in rows] == list(protocol_spec.ERRORS), (
        "docs/protocol.md's ERR rows differ from the .def's codes"
    )
    for code, documented in rows:
        assert documented == set(protocol_spec.ERRORS[code][1]), f"ERR {code}: detail tokens differ"


def test_the_chamber_codes_the_docs_once_lacked_are_defined():
    assert protocol_spec.ERRORS["THERMISTOR"][1] == ("INNER_OPEN", "INNER_SHORT", "OUTER_OPEN", "OUTER_SHORT")
    assert protocol_spec.ERRORS["BUSY"][1] == ("STOP_FIRST",)
    assert "HOLD_LOST" in protocol_spec.ERRORS["FAULT"][1]
    assert protocol_spec.ERRORS["UNKNOWN_CMD"][1] == ()


@pytest.mark.parametrize(
    "lines, complaint",
    [
        (['THERMOTILT_ERROR(BUSY, "one")', 'THERMOTILT_ERROR(BUSY, "two")'], "defined twice"),
        (['THERMOTILT_ERROR(BUSY, "one")', 'THERMOTILT_ERROR_DETAIL(STOP_FIRST, "BUSY IDLE")'], "no ERR code IDLE"),
        (
            [
                'THERMOTILT_ERROR(BUSY, "one")',
                'THERMOTILT_ERROR_DETAIL(STOP_FIRST, "BUSY")',
                'THERMOTILT_ERROR_DETAIL(STOP_FIRST, "BUSY")',
            ],
            "defined twice",
        ),
        (["THERMOTILT_ERROR(busy, one)"], "expected form"),
    ],
)
def test_generator_refuses_a_broken_error_table(lines, complaint):
    generator = load_generator()
    with pytest.raises(generator.DefinitionError, match=complaint):
        generator.parse_errors("\n".join(lines) + "\n")


def test_docs_show_every_frame():
    docs = REPO_DIR / "docs" / "protocol.md"
    if not docs.exists():
        pytest.skip("not in the ThermoTilt repository: no docs/protocol.md")
    text = docs.read_text()
    for tag, spec in FRAMES.items():
        signature = ",".join(("$" + tag, "seq") + spec.field_names) + "*HHHH"
        assert f"`{signature}`" in text, f"docs/protocol.md lacks {signature}"
    examples = re.findall(r"`(\$[A-Z]+,[0-9][^`]*\*[0-9A-F]{4})`", text)
    assert len(examples) >= len(FRAMES)
    for example in examples:
        parse_line(example)  # raises on a wrong checksum or field count


def test_imu_round_trip():
    values = [
        123456,
        -1650,
        -388,
        16012,
        -1649.75,
        -388.5,
        16012.25,
        -1078.25,
        -34.5,
        16011.0,
        23.5,
        "W",
        "E",
        "O",
    ]
    line = build_frame("IMU", 42, values)
    assert line.endswith("\r\n")
    assert len(line) - 2 <= protocol.MAX_LINE
    frame = parse_line(line)
    assert frame.type == "IMU" and frame.seq == 42
    assert frame["t_ms"] == 123456 and frame["ax_raw"] == -1650
    assert frame["az_filt"] == 16012.25
    assert frame["comp_set"] == "W" and frame["coef_source"] == "E" and frame["temp_domain"] == "O"
    assert list(frame.fields.values()) == values


def test_parse_board_imu_line():
    frame = parse_line(VECTORS[7])
    assert frame.seq == 42
    assert frame["ay_filt"] == -388.5
    assert frame["temp_c"] == 23.5


def test_tiny_coefficients_scientific_and_fixed():
    frame = parse_line(VECTORS[8])
    assert frame["p02"] == pytest.approx(6.327e-9, rel=1e-12)
    assert frame["p10"] == pytest.approx(-20.23)
    line = build_frame(
        "SETCOE",
        65535,
        ["C", "Y", -1.23456789e-38, -12.82, 4.439e-3, -3.299e-2, -1.579e-4, -1.455e-8],
    )
    assert len(line) - 2 <= protocol.MAX_LINE
    assert parse_line(line)["p00"] == -1.23456789e-38


def test_build_from_mapping_and_errors():
    line = build_frame("SETCTL", 3, {"mode": "PI", "kp": 350, "ki": 0.5})
    assert parse_line(line).fields == {"mode": "PI", "kp": 350.0, "ki": 0.5}
    with pytest.raises(ValueError, match="takes 3 fields"):
        build_frame("SETCTL", 3, ["P", 350])
    with pytest.raises(ValueError, match="missing"):
        build_frame("SETCTL", 3, {"mode": "P"})
    with pytest.raises(ValueError, match="not allowed"):
        build_frame("ERR", 1, [-1, "A,B", "x"])
    with pytest.raises(ValueError, match="upper-case"):
        build_frame("imu", 1)
    with pytest.raises(ValueError, match="0..65535"):
        build_frame("START", 65536)
    with pytest.raises(ValueError, match="characters"):
        build_frame("LONG", 0, ["A" * 108])
    assert build_frame("LONG", 0, ["A" * 107]) == LONGEST + "\r\n"


def test_non_finite_values():
    frame = parse_line(build_frame("ICF", 1, [10, 1, "E", math.nan, "NODE-07"]))
    assert math.isnan(frame["hysteresis_c"])


@pytest.mark.parametrize(
    "text, reason",
    [
        ("$ACK,0,13,STOP*B193", protocol.BAD_CHECKSUM),
        ("$ACK,0,13,STOP*G000", protocol.BAD_CHECKSUM),
        ("$ACK,0,13,STOP", protocol.NO_CHECKSUM),
        ("$ACK,0,13,STOP*4", protocol.NO_CHECKSUM),
        ("$LONG,0," + "A" * 108 + "*ADCB", protocol.TOO_LONG),
        ("$ACK,65536,1,X*35E4", protocol.BAD_SEQ),
        ("$ACK,x,1*" + "{:04X}".format(checksum("ACK,x,1")), protocol.BAD_SEQ),
        ("$A,1*" + "{:04X}".format(checksum("A,1")), protocol.BAD_TYPE),
        ("$ACKNOWLE,1*" + "{:04X}".format(checksum("ACKNOWLE,1")), protocol.BAD_TYPE),
        ("$X1,1*" + "{:04X}".format(checksum("X1,1")), protocol.BAD_TYPE),
        ("$ACK,1,\x01*" + "{:04X}".format(checksum("ACK,1,\x01")), protocol.BAD_CHAR),
        (
            "$ACK,1," + ",".join("1" * 17) + "*" + "{:04X}".format(checksum("ACK,1," + ",".join("1" * 17))),
            protocol.TOO_MANY_FIELDS,
        ),
        ("$ACK,1,5*" + "{:04X}".format(checksum("ACK,1,5")), protocol.FIELD_COUNT),
        ("$ACK,1,five,X*" + "{:04X}".format(checksum("ACK,1,five,X")), protocol.BAD_FIELD),
    ],
)
def test_malformed_lines(text, reason):
    with pytest.raises(MalformedFrame) as error:
        parse_line(text)
    assert error.value.reason == reason
    reader, frames = read_all(text + "\r\n$START,1*80BD\r\n")
    assert [f.type for f in frames] == ["START"]
    assert reader.malformed == 1
    assert reader.malformed_by_reason == {reason: 1}


def test_reader_garbage_crlf_lf_lowercase():
    data = b"\x00\xffnoise*12,\r\n$START,1*80BD\r\n$GETCOE,3,C,Y*c2ac\n\n$STOP,4*" + b"%04X\r\n" % checksum("STOP,4")
    reader, frames = read_all(data)
    assert [f.type for f in frames] == ["START", "GETCOE", "STOP"]
    assert frames[1]["axis"] == "Y"
    assert reader.malformed == 0
    assert (reader.gaps, reader.lost_frames) == (1, 1)  # host seq 1, 3, 4


def test_reader_over_long_line_then_good_frame():
    data = b"$" + b"A" * 300 + b"\r\n$START,1*80BD\r\n" + b"$ACK,0,1$START,2*B0DE\r\n"
    reader, frames = read_all(data)
    assert [f.seq for f in frames] == [1, 2]
    assert reader.malformed_by_reason == {protocol.TOO_LONG: 1, protocol.TRUNCATED: 1}


def test_reader_same_result_in_any_chunking():
    data = ("\r\n".join(VECTORS + [LONGEST, "$ACK,0,13,STOP*B193", "$" + "B" * 200]) + "\r\n").encode()
    whole, whole_frames = read_all(data)
    for chunk in (1, 7, 64):
        reader, frames = read_all(data, chunk)
        assert frames == whole_frames
        assert reader.malformed_by_reason == whole.malformed_by_reason
    assert whole.frames == len(VECTORS) + 1
    assert whole.malformed_by_reason == {protocol.BAD_CHECKSUM: 1, protocol.TOO_LONG: 1}


def lines(*frames):
    return "".join(build_frame(tag, seq, values) for tag, seq, values in frames)


def test_gap_detection_and_wrap():
    ack = ["7", "STOP"]
    data = lines(
        ("ACK", 65534, ack),
        ("ACK", 65535, ack),
        ("ACK", 0, ack),
        ("ACK", 1, ack),
        ("ACK", 4, ack),
        ("ACK", 5, ack),
    )
    reader, frames = read_all(data)
    assert len(frames) == 6
    assert reader.gaps == 1
    assert reader.lost_frames == 2


def test_corrupted_frame_shows_as_gap():
    good = build_frame("ACK", 10, [1, "START"]) + build_frame("ACK", 12, [2, "STOP"])
    bad = build_frame("ACK", 11, [1, "STOP"]).replace("STOP", "STOQ")
    reader, frames = read_all(good[: len(good) // 2] + bad + good[len(good) // 2 :])
    assert [f.seq for f in frames] == [10, 12]
    assert reader.malformed_by_reason == {protocol.BAD_CHECKSUM: 1}
    assert (reader.gaps, reader.lost_frames) == (1, 1)


def test_restart_is_a_gap_without_lost_frames():
    ack = [1, "X"]
    reader, _ = read_all(lines(("ACK", 500, ack), ("ACK", 0, ack), ("ACK", 1, ack)))
    assert (reader.gaps, reader.lost_frames) == (1, 0)


def test_directions_tracked_separately():
    data = lines(
        ("SETDEC", 0, [10]),
        ("ACK", 100, [0, "SETDEC"]),
        ("STATUS", 1, []),
        ("ICF", 101, [10, 1, "E", 0.5, ""]),
        ("ACK", 102, [1, "STATUS"]),
    )
    reader, frames = read_all(data)
    assert len(frames) == 5
    assert reader.gaps == 0


def test_unknown_type_is_kept_raw():
    frame = parse_line(build_frame("NEWONE", 5, [1, "x"]))
    assert frame.fields == {} and frame.raw_fields == ("1", "x")


def test_appended_fields_are_tolerated():
    body = "ACK,5,1,STOP,9"
    frame = parse_line(f"${body}*{checksum(body):04X}")
    assert frame.fields == {"cmd_seq": 1, "cmd_type": "STOP"}
    assert frame.raw_fields[-1] == "9"


def test_sequence_counter_wraps():
    counter = SequenceCounter(65535)
    assert [counter.next() for _ in range(3)] == [65535, 0, 1]


def test_read_from_stream(tmp_path):
    path = tmp_path / "capture.bin"
    path.write_bytes(("\r\n".join(VECTORS) + "\r\n").encode())
    reader = FrameReader()
    with open(path, "rb") as stream:
        frames = list(reader.read_from(stream, chunk_size=5))
    assert len(frames) == len(VECTORS)


def test_generator_refuses_a_frame_without_a_known_role():
    constants = "".join(f"#define THERMOTILT_PROTOCOL_{name} 1\n" for name in ("VERSION", "MAX_LINE", "MAX_FIELDS"))
    generator = load_generator()
    with pytest.raises(generator.DefinitionError, match="expected form"):
        generator.parse_definition(constants + 'THERMOTILT_FRAME(ACK, BOARD, "cmd_seq:i,cmd_type:t")\n')
    _, frames = generator.parse_definition(constants + 'THERMOTILT_FRAME(ACK, OUTCOME, "cmd_seq:i,cmd_type:t")\n')
    assert frames == [("ACK", "board", "outcome", [("cmd_seq", "i"), ("cmd_type", "t")])]


ENUM_TABLE = [
    'THERMOTILT_ERROR(BUSY, "one")',
    'THERMOTILT_ERROR(FAULT, "two")',
    'THERMOTILT_ERROR(LIMIT, "three")',
    'THERMOTILT_ERROR_DETAIL(STOP_FIRST, "BUSY")',
    'THERMOTILT_ERROR_DETAIL(INNER_HOT, "LIMIT FAULT")',
]


@pytest.mark.parametrize(
    "line, complaint",
    [
        ("THERMOTILT_CHAMBER_FAULT(INNER_HOT, LIMIT)", None),
        ("THERMOTILT_CHAMBER_FAULT(INNER_HOT, LIMIT)  // a comment (with parentheses)", None),
        ("THERMOTILT_CHAMBER_FAULT(STOP_FIRST, BUSY)", "ERR FAULT does not carry STOP_FIRST"),
        ("THERMOTILT_CHAMBER_FAULT(INNER_HOT, BUSY)", "ERR BUSY does not carry INNER_HOT"),
        ("THERMOTILT_CHAMBER_FAULT(INNER_HOT, IDLE)", "no ERR code IDLE"),
        ("THERMOTILT_CHAMBER_FAULT(INNER_HOT)", "expected"),
        ("THERMOTILT_CHAMBER_FAULTS(INNER_HOT, LIMIT)", "no such line"),
        ("THERMOTILT_CHAMBER_FAULT(INNER_HOT, LIMIT) x", "expected form"),
        ("THERMOTILT_BLOCK_STATUS(BadMagic, LIMIT)\nTHERMOTILT_BLOCK_STATUS(BadMagic, BUSY)", "named twice"),
    ],
)
def test_generator_checks_the_lines_that_name_firmware_enumerators(line, complaint):
    generator = load_generator()
    text = "\n".join(ENUM_TABLE + [line]) + "\n"
    if complaint is None:
        generator.check_enum_lines(text, generator.parse_errors(text))
        return
    with pytest.raises(generator.DefinitionError, match=complaint):
        generator.check_enum_lines(text, generator.parse_errors(text))
