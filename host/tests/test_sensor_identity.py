"""The sensor ID and the calibrated domain on the real imu_reader image in
the twin: SETID, SETDOM/GETDOM, ICF's sensor_id, the IMU frame's
temp_domain, and which coefficient block the board loads for which ID.

Expected values come from docs/protocol.md (commands, answers, ERR codes),
the block layout of docs/protocol.md and lib/Compensation's ID record
(test/test_sensor_id holds the same record bytes).
"""

import struct

import pytest
from firmware_helpers import of_type

from thermotilt.calibration.upload import FitToUpload, upload_table
from thermotilt.physics import Model
from thermotilt.run.folder import RunFolder
from thermotilt.surfaces import PAPER_DEFAULTS
from thermotilt.twin import simulate
from thermotilt.twin.boards import Board
from thermotilt.twin.scenarios import ScenarioOptions, build
from thermotilt.wire.client import CommandClient
from thermotilt.wire.coefficients import (
    BLOCK_SIZE,
    SENSOR_ID_RECORD_ADDRESS,
    SetDomain,
    crc16_xmodem,
    decode_block,
    encode_block,
    encode_sensor_id_record,
)
from thermotilt.wire.protocol import FrameReader, checksum

pytestmark = pytest.mark.twin

# -1700 / -400 / 16000 LSB, raw temperature 32 -> 25.000 degC.
SENSOR = (-1700, -400, 16000, 32)
# raw (T - 21 degC) * 8: 50 degC, above the domain's 45.
HOT_RAW = (50 - 21) * 8
ID_RECORD_ADDRESS = 512  # firmware/imu_reader/main.cpp
# Python: b"INODE-07\0" and binascii.crc_hqx of it, 0xAB20, low byte first.
NODE_07_RECORD = b"INODE-07\x00\x20\xab"
DOMAIN = {
    "W": SetDomain((-1000, 4500), {"X": (-16000, 16000), "Y": (-16000, 16000), "Z": None}),
    "C": SetDomain((-995, 4510), {"X": (-15990, 16010), "Y": (-16005, 15995), "Z": None}),
}
BLANK_BLOCK = b"\xff" * BLOCK_SIZE


@pytest.fixture
def imu():
    with Board.imu_reader() as board:
        board.attach_lsm9ds0()
        board.set_lsm9ds0(*SENSOR)
        board.run_until(0.3)
        yield board


class Host:
    """A CommandClient that keeps every frame no command took (IMU, the ERR
    a board reports on its own account, the VER of a restart)."""

    def __init__(self, board: Board):
        self.frames = []
        self.client = CommandClient(board, timeout_s=2.0, on_frame=self.frames.append)

    def command(self, frame_type, values=()):
        return self.client.command(frame_type, values)

    def status(self):
        (config,) = of_type(self.command("STATUS").data, "ICF")
        return config

    def reported(self, since: int = 0) -> list[tuple[str, str]]:
        return [(e["code"], e["detail"]) for e in of_type(self.frames[since:], "ERR") if e["cmd_seq"] == -1]

    def imu_frames(self, seconds: float = 1.0) -> list:
        mark = len(self.frames)
        self.client.wait_for(lambda frame: False, seconds)
        return of_type(self.frames[mark:], "IMU")

    def restart(self) -> None:
        """RESET, then wait for the first IMU frame: setup() has reported what it found."""
        mark = len(self.frames)
        self.command("RESET")
        self.client.wait_for(lambda frame: frame.type == "IMU", 3.0)
        assert of_type(self.frames[mark:], "VER") and of_type(self.frames[mark:], "IMU")


def test_setid_writes_the_id_record_alone(imu):
    host = Host(imu)
    assert host.status()["sensor_id"] == ""
    host.command("SETID", ["NODE-07"])
    assert imu.read_eeprom(ID_RECORD_ADDRESS, len(NODE_07_RECORD)) == NODE_07_RECORD
    assert (SENSOR_ID_RECORD_ADDRESS, encode_sensor_id_record("NODE-07")) == (ID_RECORD_ADDRESS, NODE_07_RECORD)
    assert imu.read_eeprom(0, BLOCK_SIZE) == BLANK_BLOCK
    config = host.status()
    assert (config["sensor_id"], config["coef_source"]) == ("NODE-07", "D")
    # Kept across a reset, as an EEPROM keeps it; a blank block is no error.
    host.restart()
    assert host.status()["sensor_id"] == "NODE-07" and host.reported() == []
    assert {frame["temp_domain"] for frame in host.imu_frames()} == {"U"}


def test_a_block_loads_only_while_the_board_has_the_id_it_was_fitted_for(imu):
    host = Host(imu)
    host.command("SETID", ["NODE-07"])
    upload_table(imu, FitToUpload(PAPER_DEFAULTS.to_float32(), "NODE-07", DOMAIN))
    block = imu.read_eeprom(0, BLOCK_SIZE)
    stored = decode_block(block)
    assert (stored.sensor_id, stored.domain) == ("NODE-07", DOMAIN)
    assert {(f["coef_source"], f["temp_domain"]) for f in host.imu_frames()} == {("E", "I")}

    # Another ID: the block stays, but is another sensor's: the defaults, said so.
    mark = len(host.frames)
    host.command("SETID", ["NODE-08"])
    assert host.reported(mark) == [("EEPROM_SENSOR", "DEFAULTS")]
    assert imu.read_eeprom(0, BLOCK_SIZE) == block
    assert (host.status()["coef_source"], host.status()["sensor_id"]) == ("D", "NODE-08")
    assert {(f["coef_source"], f["temp_domain"]) for f in host.imu_frames()} == {("D", "U")}
    (dom,) = of_type(host.command("GETDOM", ["W"]).data, "DOM")
    assert dom.raw_fields[1:3] == ("nan", "nan")
    mark = len(host.frames)
    host.restart()
    assert host.reported(mark) == [("EEPROM_SENSOR", "DEFAULTS")] and host.status()["coef_source"] == "D"

    # Back to the ID it was fitted for: it loads again, domain and all.
    mark = len(host.frames)
    host.command("SETID", ["NODE-07"])
    assert host.reported(mark) == [] and host.status()["coef_source"] == "E"
    (dom,) = of_type(host.command("GETDOM", ["C"]).data, "DOM")
    assert dom.raw_fields == ("C", "-9.95", "45.10", "-15990", "16010", "-16005", "15995", "32767", "-32768")


def test_a_block_fitted_for_no_sensor_loads_on_any_board(imu):
    host = Host(imu)
    upload_table(imu, FitToUpload(PAPER_DEFAULTS.to_float32(), "", DOMAIN))
    assert decode_block(imu.read_eeprom(0, BLOCK_SIZE)).sensor_id == ""
    mark = len(host.frames)
    host.command("SETID", ["NODE-07"])
    assert host.reported(mark) == [] and host.status()["coef_source"] == "E"


def test_a_version_1_block_loads_on_a_board_with_an_id_without_a_domain(imu):
    host = Host(imu)
    host.command("SETID", ["NODE-07"])
    body = bytes((0x54, 1)) + struct.pack("<36f", *PAPER_DEFAULTS.to_float32().values())
    imu.write_eeprom(body + crc16_xmodem(body).to_bytes(2, "little"))
    host.restart()
    assert host.reported() == [] and host.status()["coef_source"] == "E"
    assert {frame["temp_domain"] for frame in host.imu_frames()} == {"U"}
    (coe,) = of_type(host.command("GETCOE", ["C", "Y"]).data, "COE")
    assert coe["p00"] == pytest.approx(338.1, rel=1e-4)


def test_a_damaged_id_record_is_reported_and_the_board_has_no_id(imu):
    host = Host(imu)
    host.command("SETID", ["NODE-07"])
    record = bytearray(NODE_07_RECORD)
    record[7] = ord("8")
    imu.write_eeprom(bytes(record), offset=ID_RECORD_ADDRESS)
    mark = len(host.frames)
    host.restart()
    assert host.reported(mark) == [("EEPROM_ID", "NO_ID")]
    assert host.status()["sensor_id"] == ""


@pytest.mark.parametrize(
    "command, values, detail",
    [
        ("SETID", ["NODE 7"], "SENSOR_ID"),
        ("SETID", ["NODE-0007"], "SENSOR_ID"),
        ("SETID", ["NODE.7"], "SENSOR_ID"),
        ("SETID", [], "SENSOR_ID"),
        ("SETDOM", ["W", 45, -10, 0, 0, 0, 0, 0, 0], "DOMAIN"),
        ("SETDOM", ["W", "nan", 45, 0, 0, 0, 0, 0, 0], "DOMAIN"),
        ("SETDOM", ["W", -10, 400, 0, 0, 0, 0, 0, 0], "DOMAIN"),
        ("SETDOM", ["W", -10, 45, 0, 0, 0, 0, 0, 40000], "DOMAIN"),
        ("SETDOM", ["X", -10, 45, 0, 0, 0, 0, 0, 0], "DOMAIN"),
        ("SETDOM", ["W", -10, 45], "DOMAIN"),
        ("GETDOM", ["Y"], "DOMAIN"),
    ],
)
def test_bad_arguments_are_refused_and_change_nothing(imu, command, values, detail):
    host = Host(imu)
    host.command("SETID", ["NODE-07"])
    eeprom = imu.read_eeprom()
    # Written by hand: build_frame would refuse a short one.
    body = ",".join([command, "900", *map(str, values)])
    imu.write_uart(f"${body}*{checksum(body):04X}\r\n".encode())
    imu.run_until(imu.seconds + 0.2)
    answers = [frame for frame in FrameReader().feed(imu.read_uart()) if frame.type in ("ACK", "ERR")]
    assert [(frame["cmd_seq"], frame.type) for frame in answers] == [(900, "ERR")]
    assert (answers[0]["code"], answers[0]["detail"]) == ("BAD_ARG", detail)
    assert imu.read_eeprom() == eeprom
    assert host.status()["sensor_id"] == "NODE-07"


def test_the_imu_frame_says_when_the_temperature_leaves_the_calibrated_range(imu):
    host = Host(imu)
    host.command("SETDOM", DOMAIN["W"].setdom_values("W"))
    assert {(f["comp_set"], f["temp_domain"]) for f in host.imu_frames()} == {("W", "I")}
    imu.set_lsm9ds0(*SENSOR[:3], HOT_RAW)
    # Seeded again, the filtered temperature starts at the new reading.
    host.command("RESEED")
    frames = host.imu_frames()
    assert frames and all(f["temp_c"] == pytest.approx(50.0) and f["temp_domain"] == "O" for f in frames)
    # New surfaces for the set: where they were fitted is unknown until SETDOM.
    host.command("SETCOE", ["W", "X", *PAPER_DEFAULTS.surface("W", "X")])
    assert {f["temp_domain"] for f in host.imu_frames()} == {"U"}
    host.command("SETDOM", ["W", -10, 50, 0, 0, 0, 0, 32767, -32768])
    assert {f["temp_domain"] for f in host.imu_frames()} == {"I"}
    host.command("DEFCOE")
    assert {f["temp_domain"] for f in host.imu_frames()} == {"U"}


@pytest.mark.parametrize(("board_id", "reported"), [("TT-02", []), ("TT-01", ["EEPROM_SENSOR DEFAULTS"])])
def test_a_twin_run_of_a_batch_sensor_boots_holding_its_id(tmp_path, board_id, reported):
    """simulate --sensor and a batch campaign give the IMU its sensor's ID
    as assign-id would: a block fitted for TT-02 loads on TT-02's board
    alone, another board reports it and keeps the defaults (docs/protocol.md)."""
    block = encode_block(PAPER_DEFAULTS.to_float32(), "TT-02", DOMAIN)
    scenario = build("field-warming", ScenarioOptions(duration_s=2))
    result = simulate.run(scenario, Model.load(), tmp_path, eeprom=block, sensor_id=board_id)
    saved = RunFolder.at(tmp_path).imu_eeprom.read_bytes()
    assert saved[ID_RECORD_ADDRESS : ID_RECORD_ADDRESS + len(NODE_07_RECORD)] == encode_sensor_id_record(board_id)
    errors = result.summary.boards["imu_reader"].reported_errors
    assert [error.split(" at ")[0] for error in errors] == reported
