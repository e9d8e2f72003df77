"""The IMU reader's defences, in the twin (the real imu_reader.elf in simavr
through thermotilt.twin.boards): coefficient blocks in EEPROM it must not trust,
SETCOE surfaces whose output no IMU frame can carry, a first temperature
sample taken before the sensor refreshed it, commands with a field
appended, and RESET, a reset through the watchdog that is not a fault.

Expected values come from the protocol and the parts: the frame limits of
docs/protocol.md, the paper's default coefficients, the LSM9DS0's
8 LSB/degC temperature output and the model's reported temperature.
"""

import math
import shutil
import struct
import subprocess
from pathlib import Path

import pytest
from firmware_helpers import of_type

from thermotilt.physics import Model, Sensor
from thermotilt.surfaces import COEFFICIENT_NAMES, PAPER_DEFAULTS, table_from_values
from thermotilt.twin.boards import Board, firmware_elf
from thermotilt.twin.simulate import STEP_S
from thermotilt.wire.coefficients import crc16_xmodem, encode_block
from thermotilt.wire.protocol import MAX_LINE, Frame, FrameReader, build_frame, parse_line

pytestmark = pytest.mark.twin

NANO = "atmega328p"
# -1700 / -400 / 16000 LSB, raw temperature 32 -> 32 / 8 + 21 = 25.000 degC.
SENSOR = (-1700, -400, 16000, 32)
# The sensor resolves 1/8 degC (8 LSB/degC).
TEMPERATURE_RESOLUTION_C = 1 / 8
# The block: magic, version, 36 float32 from byte 2, CRC in the last two bytes.
FLOATS_OFFSET = 2
CRC_OFFSET = 186


def start_imu(elf: Path | None = None, sensor=SENSOR) -> Board:
    board = Board(elf, NANO) if elf is not None else Board.imu_reader()
    board.attach_lsm9ds0()
    board.set_lsm9ds0(*sensor)
    return board


def answers(board: Board, reader: FrameReader, commands: list[str], seconds: float) -> list[Frame]:
    """Sends the commands one at a time, each after the previous answer, and
    returns every frame the board sent until `seconds` of simulated time."""
    frames = []
    for command in commands:
        seq = parse_line(command).seq
        board.write_uart(command.encode())
        deadline = board.seconds + 0.1
        while board.seconds < deadline:
            board.run_until(board.seconds + 0.002)
            frames += reader.feed(board.read_uart())
            if any(f.type in ("ACK", "ERR") and f["cmd_seq"] == seq for f in frames):
                break
    board.run_until(max(seconds, board.seconds))
    return frames + reader.feed(board.read_uart())


def surface_values(frame: Frame) -> tuple[float, ...]:
    return tuple(frame[term] for term in COEFFICIENT_NAMES)


# ---- coefficient block in EEPROM ----------------------------------------


def image_with_eeprom(tmp_path: Path, block: bytes) -> Path:
    """A copy of imu_reader.elf whose EEPROM starts with `block`: simavr's ELF
    loader fills the EEPROM from the section named .eeprom, the one avr-gcc
    emits for EEMEM data."""
    objcopy = shutil.which("avr-objcopy")
    if objcopy is None:
        pytest.fail("avr-objcopy (binutils-avr) is missing: run `make deps`")
    contents = tmp_path / "eeprom.bin"
    contents.write_bytes(block)
    elf = tmp_path / "imu_reader_eeprom.elf"
    subprocess.run(
        [objcopy, "--add-section", f".eeprom={contents}", str(firmware_elf("imu_reader")), str(elf)],
        check=True,
        capture_output=True,
    )
    return elf


def resealed(block: bytes) -> bytes:
    """The block with its CRC computed again, as a sound block of that content."""
    return block[:CRC_OFFSET] + struct.pack("<H", crc16_xmodem(block[:CRC_OFFSET]))


def with_float(block: bytes, index: int, value: float) -> bytes:
    offset = FLOATS_OFFSET + 4 * index
    return block[:offset] + struct.pack("<f", value) + block[offset + 4 :]


def boot_with_eeprom(tmp_path: Path, block: bytes) -> list[Frame]:
    reader = FrameReader()
    with start_imu(image_with_eeprom(tmp_path, block)) as board:
        board.run_until(0.3)
        frames = answers(board, reader, [build_frame("GETCOE", 1, ["W", "X"])], 0.6)
    assert reader.malformed == 0
    return frames


PAPER_BLOCK = encode_block(PAPER_DEFAULTS)
# One surface the firmware could never write out: p00 = 2e7 LSB, a finite
# value the host encodes without complaint.
ABSURD_VALUES = [2e7, *PAPER_DEFAULTS.values()[1:]]

DAMAGED_BLOCKS = {
    "another magic": (b"X" + PAPER_BLOCK[1:], "EEPROM_MAGIC"),
    # An erased magic byte in front of written bytes is damage, not a blank EEPROM.
    "erased magic": (b"\xff" + PAPER_BLOCK[1:], "EEPROM_MAGIC"),
    "one flipped bit": (PAPER_BLOCK[:77] + bytes([PAPER_BLOCK[77] ^ 0x04]) + PAPER_BLOCK[78:], "EEPROM_CRC"),
    # Power lost while saving onto a blank EEPROM: the first 100 bytes written.
    "half written": (PAPER_BLOCK[:100] + b"\xff" * (len(PAPER_BLOCK) - 100), "EEPROM_CRC"),
    "version 3": (resealed(PAPER_BLOCK[:1] + b"\x03" + PAPER_BLOCK[2:]), "EEPROM_VERSION"),
    "NaN with a good CRC": (resealed(with_float(PAPER_BLOCK, 15, math.nan)), "EEPROM_VALUES"),
    "output beyond a frame": (encode_block(table_from_values(ABSURD_VALUES)), "EEPROM_VALUES"),
    # A sound block fitted for a sensor ID, on a board that has none.
    "another sensor's": (encode_block(PAPER_DEFAULTS, "NODE-07"), "EEPROM_SENSOR"),
}


@pytest.mark.parametrize("damage", DAMAGED_BLOCKS)
def test_a_damaged_block_is_reported_and_the_defaults_are_used(tmp_path, damage):
    block, code = DAMAGED_BLOCKS[damage]
    frames = boot_with_eeprom(tmp_path, block)
    assert [(e["cmd_seq"], e["code"], e["detail"]) for e in of_type(frames, "ERR")] == [(-1, code, "DEFAULTS")]
    imu = of_type(frames, "IMU")
    assert imu and {f["coef_source"] for f in imu} == {"D"}
    (coe,) = of_type(frames, "COE")
    assert surface_values(coe) == pytest.approx(tuple(PAPER_DEFAULTS.surface("W", "X")), rel=1e-4)


def test_a_blank_eeprom_gives_the_defaults_silently(tmp_path):
    frames = boot_with_eeprom(tmp_path, b"\xff" * len(PAPER_BLOCK))
    assert not of_type(frames, "ERR")
    assert {f["coef_source"] for f in of_type(frames, "IMU")} == {"D"}


def test_a_sound_block_is_used(tmp_path):
    values = PAPER_DEFAULTS.values()
    values[0] = 500.0
    frames = boot_with_eeprom(tmp_path, encode_block(table_from_values(values)))
    assert not of_type(frames, "ERR")
    assert {f["coef_source"] for f in of_type(frames, "IMU")} == {"E"}
    (coe,) = of_type(frames, "COE")
    assert surface_values(coe) == pytest.approx(tuple(values[:6]), rel=1e-4)


# ---- SETCOE and the IMU frame ---------------------------------------------

# The firmware's limit on |raw - f|: 1e6 (nine characters at one decimal in the
# longest IMU line) less 0.1 % (lib/Compensation/src/Compensation.h).
OUTPUT_LIMIT_LSB = 9.99e5
INT16_MIN = -32768


def test_setcoe_refuses_surfaces_whose_output_cannot_be_framed():
    reader = FrameReader()
    paper = tuple(PAPER_DEFAULTS.surface("W", "X"))
    commands = [
        build_frame("SETCOE", 1, ["W", "X", 2e7, *paper[1:]]),
        # 0.01 * 32768^2 = 1.07e7 LSB at full scale, although every term is small.
        build_frame("SETCOE", 2, ["W", "X", *paper[:5], 0.01]),
        build_frame("SETCOE", 3, ["W", "X", math.nan, *paper[1:]]),
        build_frame("GETCOE", 4, ["W", "X"]),
        build_frame("STATUS", 5),
    ]
    with start_imu() as board:
        board.run_until(0.3)
        frames = answers(board, reader, commands, 0.6)
    errors = [(e["cmd_seq"], e["code"], e["detail"]) for e in of_type(frames, "ERR")]
    assert errors == [
        (1, "BAD_ARG", "OUTPUT_TOO_LARGE"),
        (2, "BAD_ARG", "OUTPUT_TOO_LARGE"),
        (3, "BAD_ARG", "COEFFICIENTS"),
    ]
    (coe,) = of_type(frames, "COE")
    assert surface_values(coe) == pytest.approx(paper, rel=1e-4)
    (config,) = of_type(frames, "ICF")
    assert config["coef_source"] == "D"


def test_the_longest_accepted_output_still_fits_an_imu_frame():
    # raw = -32768 and p00 = limit - 32768 - 1000: raw - f = -998000 LSB, the
    # longest value with one decimal that the firmware accepts; the
    # temperature at its most negative (raw -2048 -> -235 degC) is longest too.
    # Both sets alike: whatever the device's blend of them, the same value.
    p00 = OUTPUT_LIMIT_LSB + INT16_MIN - 1000
    targets = [(set_name, axis) for set_name in "WC" for axis in "XYZ"]
    commands = [build_frame("SETCOE", seq, [*target, p00, 0, 0, 0, 0, 0]) for seq, target in enumerate(targets, 1)]
    reader = FrameReader()
    with start_imu(sensor=(INT16_MIN, INT16_MIN, INT16_MIN, -2048)) as board:
        board.run_until(0.3)
        frames = answers(board, reader, commands, 0.8)
    assert reader.malformed == 0
    assert [(f["cmd_seq"], f.type) for f in frames if f.type in ("ACK", "ERR")] == [(seq, "ACK") for seq in range(1, 7)]
    last = of_type(frames, "IMU")[-1]
    assert (last["ax_comp"], last["ay_comp"], last["az_comp"]) == (INT16_MIN - p00,) * 3
    assert last["temp_c"] == -235.0
    # This frame's seq and t_ms are short; at 65535 and 4294967295 ms it would be longer by:
    growth = (5 - len(str(last.seq))) + (10 - len(str(last["t_ms"])))
    assert len(last.line) + growth <= MAX_LINE


# ---- the first temperature sample -----------------------------------------

BOOTS = 40
# Far from 21.00 degC, the value OUT_TEMP_XM holds before its first refresh
# (raw 0): the first frame is the mean of 10 samples (decimation 10; the
# Kalman gain starts at 1/n), so one stale sample would move it by at least
# 8 degC / 10, well beyond the 1/8 degC resolution.
AMBIENTS_C = (-10.0, 0.0, 10.0, 30.0, 40.0)


def first_frame_and_truth(seed: int, ambient_c: float, sensor_phase_s: float) -> tuple[Frame, float, list[Frame]]:
    model = Model.load()
    sensor = Sensor(model, seed, ambient_c)
    reader = FrameReader()
    frames: list[Frame] = []
    with Board.imu_reader() as board:
        board.run_until(sensor_phase_s)
        board.attach_lsm9ds0()
        step = 0
        while not of_type(frames, "IMU"):
            sample = sensor.step(STEP_S, ambient_c, 0.0, 0.0)
            board.set_lsm9ds0(sample.ax, sample.ay, sample.az, sample.temperature_raw)
            step += 1
            board.run_until(step * STEP_S)
            frames += reader.feed(board.read_uart())
            assert step < 100, "no IMU frame within a second"
    return of_type(frames, "IMU")[0], sample.reported_c, frames


def test_the_first_imu_frame_carries_a_refreshed_temperature():
    misses = []
    for boot in range(BOOTS):
        # The model's sample clock polls CTRL_REG1_XM every 1 ms while powered
        # down and takes its first sample at the first poll after begin()
        # selects 100 Hz. The real sensor's clock runs free of the MCU's, so
        # the boots spread that poll over the whole millisecond.
        phase_s = boot * 0.001 / BOOTS
        ambient_c = AMBIENTS_C[boot % len(AMBIENTS_C)]
        first, reported_c, frames = first_frame_and_truth(boot, ambient_c, phase_s)
        # The sensor was there before the firmware first looked for it.
        assert not of_type(frames, "ERR")
        if abs(first["temp_c"] - reported_c) > TEMPERATURE_RESOLUTION_C:
            misses.append((boot, ambient_c, first["temp_c"], round(reported_c, 3)))
    assert misses == []


# ---- fields appended to a command -----------------------------------------


def with_appended_field(frame_type: str, seq: int, values=()) -> str:
    """A command with one field more than the frame table lists, which
    docs/protocol.md says boards accept; build_frame refuses to write it, so
    its fields are extended and its check digits computed by Frame.line."""
    frame = parse_line(build_frame(frame_type, seq, values))
    return Frame(frame.type, frame.seq, {}, (*frame.raw_fields, "NEXT")).line + "\r\n"


def test_commands_with_an_appended_field_are_carried_out():
    uploaded = (1.5, -2.5, 3.5e-3, -4.5e-4, 5.5e-6, -6.5e-9)
    commands = [
        with_appended_field("SETDEC", 1, [20]),
        with_appended_field("SETCOE", 2, ["C", "Y", *uploaded]),
        with_appended_field("GETCOE", 3, ["C", "Y"]),
        with_appended_field("STATUS", 4),
        with_appended_field("VERSION", 5),
    ]
    reader = FrameReader()
    with start_imu() as board:
        board.run_until(0.3)
        frames = answers(board, reader, commands, 0.6)
    replies = [(f.type, f["cmd_seq"], f["cmd_type"]) for f in frames if f.type == "ACK"]
    assert replies == [
        ("ACK", 1, "SETDEC"),
        ("ACK", 2, "SETCOE"),
        ("ACK", 3, "GETCOE"),
        ("ACK", 4, "STATUS"),
        ("ACK", 5, "VERSION"),
    ]
    assert not of_type(frames, "ERR")
    (coe,) = of_type(frames, "COE")
    assert (coe["set"], coe["axis"]) == ("C", "Y")
    assert surface_values(coe) == pytest.approx(uploaded, rel=1e-6)
    (config,) = of_type(frames, "ICF")
    assert (config["decimation"], config["coef_source"]) == (20, "U")


# ---- RESET: a commanded reset through the watchdog ------------------------

# Firmware/common/Watchdog.h: WDTO_15MS, 2048 cycles of the 128 kHz watchdog
# oscillator, which simavr counts exactly.
COMMANDED_RESET_S = 2048 / 128_000
SAMPLE_PERIOD_S = 0.01


def frames_after(frames: list[Frame], first: Frame) -> list[Frame]:
    """The frames from `first` on: sequence numbers start again at each boot."""
    return frames[next(i for i, f in enumerate(frames) if f is first) :]


def test_reset_acknowledges_then_restarts_as_commanded_not_as_a_fault():
    reader = FrameReader()
    frames: list[Frame] = []
    with start_imu() as board:
        board.run_until(0.5)
        board.write_uart(build_frame("RESET", 1).encode())
        acknowledged_s = booted_s = None
        while booted_s is None and board.seconds < 1.0:
            board.run_until(board.seconds + 0.0005)
            new = reader.feed(board.read_uart())
            frames += new
            if acknowledged_s is None and of_type(new, "ACK"):
                acknowledged_s = board.seconds
            if acknowledged_s is not None and of_type(new, "VER"):
                booted_s = board.seconds
        board.run_until(booted_s + 1.0)
        frames += reader.feed(board.read_uart())
    first, second = of_type(frames, "VER")
    assert (first["reset_cause"], second["reset_cause"]) == ("POWER_ON", "COMMANDED")
    (ack,) = of_type(frames, "ACK")
    assert (ack["cmd_seq"], ack["cmd_type"]) == (1, "RESET")
    # Nothing between the ACK and the board's restart, which the watchdog
    # brings within its 15 ms (and the VER's 45 bytes at the line rate).
    assert frames.index(second) == frames.index(ack) + 1
    assert COMMANDED_RESET_S <= booted_s - acknowledged_s < COMMANDED_RESET_S + 0.01
    # No ERR RESET: a commanded reset is no fault. It streams again at 10 Hz.
    after = frames_after(frames, second)
    assert not of_type(after, "ERR")
    restarted = of_type(after, "IMU")
    assert len(restarted) >= 8 and restarted[0].seq < 5
    assert all(b["t_ms"] - a["t_ms"] in (99, 100, 101) for a, b in zip(restarted, restarted[1:]))


def test_a_hang_after_a_commanded_reset_is_a_watchdog_reset_again():
    reader = FrameReader()
    with start_imu() as board:
        board.run_until(0.3)
        frames = answers(board, reader, [build_frame("RESET", 1)], 0.6)
        board.hang()
        board.run_until(1.5)
        frames += reader.feed(board.read_uart())
    assert [v["reset_cause"] for v in of_type(frames, "VER")] == ["POWER_ON", "COMMANDED", "WATCHDOG"]
    assert [(e["code"], e["detail"]) for e in of_type(frames, "ERR")] == [("RESET", "WATCHDOG")]


def test_a_reset_keeps_saved_coefficients_and_drops_unsaved_ones():
    saved = (500.5, -19.0625, 1.5e-3, -0.1, -7.0e-5, 6.0e-9)
    unsaved = (1.5, -2.5, 3.5e-3, -4.5e-4, 5.5e-6, -6.5e-9)
    reader = FrameReader()
    with start_imu() as board:
        board.run_until(0.3)
        frames = answers(
            board,
            reader,
            [
                build_frame("SETCOE", 1, ["W", "X", *saved]),
                build_frame("SAVECOE", 2),
                build_frame("SETCOE", 3, ["C", "Y", *unsaved]),
                build_frame("RESET", 4),
            ],
            0.5,
        )
        frames += answers(
            board,
            reader,
            [build_frame("GETCOE", 5, ["W", "X"]), build_frame("GETCOE", 6, ["C", "Y"]), build_frame("STATUS", 7)],
            1.0,
        )
        stored = board.read_eeprom(0, len(PAPER_BLOCK))
    rebooted = frames_after(frames, of_type(frames, "VER")[1])
    coe_wx, coe_cy = of_type(rebooted, "COE")
    assert surface_values(coe_wx) == pytest.approx(saved, rel=1e-4)
    assert surface_values(coe_cy) == pytest.approx(tuple(PAPER_DEFAULTS.surface("C", "Y")), rel=1e-4)
    (config,) = of_type(rebooted, "ICF")
    assert config["coef_source"] == "E"
    assert {f["coef_source"] for f in of_type(rebooted, "IMU")} == {"E"}
    # SAVECOE stored what SETCOE was sent, as float32, bit for bit.
    values = PAPER_DEFAULTS.values()
    values[:6] = saved
    assert stored == encode_block(table_from_values(values).to_float32())
