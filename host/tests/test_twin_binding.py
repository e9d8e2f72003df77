"""Both firmware images driven through thermotilt.twin.boards (ctypes over
build/native/libthermotilt_twin.so, built by `make build`).

Expected values come from the parts and the paper, not from the twin: the
thermistor input from the divider and the beta equation, the drive from the
P law pwm = min(255, 350 * |setpoint - inner|) (paper eq. 2), the duty
reaching the Peltier from Timer2's phase-correct PWM (high for OCR2B/255 of
the period), the IMU temperature from 8 LSB/degC + 21 degC, the line time
from 10 bits a byte at 115200 baud.
"""

import math

import numpy as np
import pytest
import serial
from firmware_helpers import chamber, divider_millivolts, of_type, start_program

from thermotilt.build_tree import build_dir
from thermotilt.surfaces import PAPER_DEFAULTS, table_from_values
from thermotilt.twin.boards import Board, Drive, TwinError, firmware_elf
from thermotilt.wire.coefficients import encode_block
from thermotilt.wire.protocol import FrameReader, build_frame

pytestmark = pytest.mark.twin

KP = 350.0
BYTE_SECONDS = 10 / 115200
# -1700 / -400 / 16000 LSB, raw temperature 32 -> 32 / 8 + 21 = 25.000 degC.
SENSOR = (-1700, -400, 16000, 32)


def measured_celsius(millivolts: float) -> float:
    """What the firmware can know: the ATmega's ADC code (the datasheet's
    ideal ADC: Vin * 1024 / Vref, rounded: its first transition is at half
    an LSB), then the divider and the beta equation backwards."""
    code = math.floor(millivolts * 1024 / 5000 + 0.5)
    ntc = 100e3 * code / (1024 - code)
    return 1.0 / (math.log(ntc / 100e3) / 3950.0 + 1.0 / 298.15) - 273.15


def imu_with_sensor() -> Board:
    board = Board.imu_reader()
    board.attach_lsm9ds0()
    board.set_lsm9ds0(*SENSOR)
    return board


# ---- thermal chamber and the L298N --------------------------------------


def test_chamber_cools_through_timer2_pwm_by_the_p_law():
    reader = FrameReader()
    with chamber(inner_c=20.3) as board:
        board.run_until(1.0)
        start_program(board, 20.0)
        # Control ticks every 250 ms; the one at 1.25 s applies the drive.
        board.run_until(1.5)
        board.read_l298n()
        board.run_until(2.2)
        drive = board.read_l298n()
        frames = reader.feed(board.read_uart())
    assert reader.malformed == 0
    status = of_type(frames, "CHS")[-1]
    assert (status["phase"], status["setpoint_c"], status["dir"]) == ("W", 20.0, "C")
    inner = measured_celsius(divider_millivolts(20.3))
    assert status["inner_c"] == pytest.approx(inner, abs=0.006)
    # 350 * (20.31 - 20) = 108.5: cooling, well short of saturation.
    expected_pwm = KP * (inner - 20.0)
    assert status["pwm"] == pytest.approx(expected_pwm, abs=1)
    assert drive.direction == -1
    assert drive.pwm == status["pwm"]
    # Phase-correct PWM is high for OCR2B/255 of the period; ENA is also low
    # for microseconds at each tick while applyDrive sets the pins.
    assert drive.duty == pytest.approx(expected_pwm / 255, abs=1 / 255)
    assert drive.duty == pytest.approx(drive.pwm / 255, abs=1e-3)


def test_chamber_heats_at_full_drive_once_the_error_saturates():
    reader = FrameReader()
    with chamber(inner_c=18.0) as board:
        board.run_until(1.0)
        idle = board.read_l298n()
        start_program(board, 20.0)
        board.run_until(1.5)
        switching_on = board.read_l298n()
        board.run_until(2.2)
        full = board.read_l298n()
        frames = reader.feed(board.read_uart())
    assert idle == Drive(duty=0.0, direction=0, pwm=0)
    # 350 * 2 degC = 700 -> 255, which analogWrite sends as a plain HIGH. On
    # from the tick at 1.25 s (plus the few ms it spends reading the
    # thermistors), so about half of the 1.0..1.5 s window.
    assert 0.48 < switching_on.duty <= 0.5
    assert full.direction == 1 and full.pwm == 255
    assert full.duty == pytest.approx(1.0, abs=1e-3)
    status = of_type(frames, "CHS")[-1]
    assert (status["phase"], status["pwm"], status["dir"]) == ("W", 255, "H")


def test_an_open_inner_thermistor_stops_the_drive_until_the_host_clears_it():
    reader = FrameReader()
    with chamber(inner_c=18.0) as board:
        board.run_until(1.0)
        start_program(board, 20.0)
        board.run_until(1.6)
        assert board.read_l298n().direction == 1
        board.set_adc_fault(0, "open")
        board.run_until(2.6)
        board.write_uart(build_frame("CLEAR", 3).encode())
        board.read_l298n()
        board.run_until(3.6)
        faulty = board.read_l298n()
        board.set_adc_fault(0, "none")
        board.run_until(4.6)
        board.write_uart((build_frame("START", 4) + build_frame("CLEAR", 5)).encode())
        board.run_until(5.6)
        frames = reader.feed(board.read_uart())
        cleared = board.read_l298n()
    assert faulty == Drive(duty=0.0, direction=0, pwm=0)
    errors = of_type(frames, "ERR")
    assert [(e["cmd_seq"], e["code"], e["detail"]) for e in errors] == [
        (-1, "THERMISTOR", "INNER_OPEN"),
        (3, "FAULT", "INNER_OPEN"),  # CLEAR refused while the thermistor is still open
        (4, "FAULT", "INNER_OPEN"),  # START refused while the fault is latched
    ]
    assert [f["cmd_seq"] for f in of_type(frames, "ACK")] == [1, 2, 5]
    during, fixed, after = (next(f for f in of_type(frames, "CHS") if f["t_ms"] == t_ms) for t_ms in (3000, 4000, 5000))
    assert (during["phase"], during["fault"], during["pwm"], during["dir"]) == ("F", "INNER_OPEN", 0, "O")
    assert math.isnan(during["inner_c"])
    # The reading is back but the fault stays latched until CLEAR.
    assert (fixed["phase"], fixed["fault"], fixed["pwm"]) == ("F", "INNER_OPEN", 0)
    assert fixed["inner_c"] == pytest.approx(measured_celsius(divider_millivolts(18.0)), abs=0.006)
    assert (after["phase"], after["fault"]) == ("I", "OK")
    assert cleared == Drive(duty=0.0, direction=0, pwm=0)


def test_a_shorted_outer_thermistor_is_reported():
    reader = FrameReader()
    with chamber(inner_c=22.0) as board:
        board.set_adc_fault(1, "short")
        board.run_until(1.1)
        frames = reader.feed(board.read_uart())
    assert [(e["code"], e["detail"]) for e in of_type(frames, "ERR")] == [("THERMISTOR", "OUTER_SHORT")]
    status = of_type(frames, "CHS")[-1]
    assert (status["phase"], status["fault"]) == ("F", "OUTER_SHORT")
    assert status["inner_c"] == pytest.approx(measured_celsius(divider_millivolts(22.0)), abs=0.006)


def test_a_cut_peltier_wire_keeps_the_command_but_drives_nothing():
    reader = FrameReader()
    with chamber(inner_c=18.0) as board:
        board.run_until(1.0)
        start_program(board, 20.0)
        board.run_until(1.5)
        board.set_l298n_disconnected(True)
        board.read_l298n()
        board.run_until(2.5)
        cut = board.read_l298n()
        board.set_l298n_disconnected(False)
        board.run_until(3.5)
        restored = board.read_l298n()
        frames = reader.feed(board.read_uart())
    assert cut == Drive(duty=0.0, direction=0, pwm=255)
    assert restored.direction == 1
    assert restored.duty == pytest.approx(1.0, abs=1e-3)
    # The firmware cannot tell: it still reports full heating.
    status = next(f for f in of_type(frames, "CHS") if f["t_ms"] == 2000)
    assert (status["pwm"], status["dir"], status["fault"]) == (255, "H", "OK")


# ---- IMU reader and the LSM9DS0 -----------------------------------------


def test_imu_streams_the_sensor_values_at_10_hz():
    reader = FrameReader()
    with imu_with_sensor() as board:
        board.run_until(2.05)
        first = of_type(reader.feed(board.read_uart()), "IMU")
        # As a physics model written with numpy would give them.
        board.set_lsm9ds0(*np.array([100, -200, 16500, -8], dtype=np.int16))
        board.run_until(3.05)
        later = of_type(reader.feed(board.read_uart()), "IMU")
    assert reader.malformed == 0 and reader.gaps == 0
    # 100 Hz sampling, decimation 10: one frame per 100 ms from start-up on.
    assert len(first) == 20
    assert all(b["t_ms"] - a["t_ms"] in (99, 100, 101) for a, b in zip(first, first[1:]))
    assert {(f["ax_raw"], f["ay_raw"], f["az_raw"]) for f in first} == {SENSOR[:3]}
    assert first[-1]["temp_c"] == 25.0
    assert len(later) == 10
    assert (later[-1]["ax_raw"], later[-1]["ay_raw"], later[-1]["az_raw"]) == (100, -200, 16500)
    # -8 / 8 + 21 = 20 degC, approached through the temperature's Kalman filter.
    assert 20.0 <= later[-1]["temp_c"] < 25.0


def test_imu_reports_an_absent_sensor_every_second():
    reader = FrameReader()
    with imu_with_sensor() as board:
        board.set_lsm9ds0_fault("absent")
        board.run_until(2.5)
        frames = reader.feed(board.read_uart())
    assert not of_type(frames, "IMU")
    errors = of_type(frames, "ERR")
    assert [(e["code"], e["detail"]) for e in errors] == [("SENSOR_MISSING", "NO_ANSWER")] * 3


def test_imu_reports_a_stuck_sensor_as_no_data_and_recovers():
    reader = FrameReader()
    with imu_with_sensor() as board:
        board.run_until(1.0)
        before = of_type(reader.feed(board.read_uart()), "IMU")
        board.set_lsm9ds0_fault("stuck")
        board.run_until(3.0)
        stuck = reader.feed(board.read_uart())
        board.set_lsm9ds0_fault("none")
        board.run_until(4.5)
        recovered = reader.feed(board.read_uart())
    # Frames from 93 ms on, every 100 ms; the one at ~993 ms is still on the wire.
    assert len(before) == 9
    # It still answers WHO_AM_I, so every reconnection succeeds and then
    # waits in vain for data-ready: NO_DATA, never NO_ANSWER.
    errors = of_type(stuck, "ERR")
    assert len(errors) >= 2
    assert {(e["code"], e["detail"]) for e in errors} == {("SENSOR_MISSING", "NO_DATA")}
    assert all(frame["t_ms"] < 1100 for frame in of_type(stuck, "IMU"))
    assert len(of_type(recovered, "IMU")) >= 3
    assert not of_type(recovered, "ERR")


# ---- serial line ----------------------------------------------------------


def imu_output(seconds: float, corruption: tuple[float, int] | None = None) -> tuple[bytes, int]:
    with imu_with_sensor() as board:
        if corruption is not None:
            board.set_uart_corruption(*corruption)
        board.run_until(seconds)
        return board.read_uart(), board.uart_corrupted_bytes


def test_uart_corruption_flips_one_bit_in_about_one_byte_in_a_hundred():
    clean, none_corrupted = imu_output(3.0)
    noisy, corrupted = imu_output(3.0, (0.01, 1234))
    again, _ = imu_output(3.0, (0.01, 1234))
    other_seed, _ = imu_output(3.0, (0.01, 4321))
    assert none_corrupted == 0
    assert noisy == again
    assert other_seed != noisy
    # Corrupting what the firmware sends does not change what it does, so the
    # streams differ exactly in the corrupted bytes, by one bit each.
    assert len(noisy) == len(clean)
    flips = [a ^ b for a, b in zip(clean, noisy) if a != b]
    assert len(flips) == corrupted
    assert all(bin(flip).count("1") == 1 for flip in flips)
    # Binomial(n ~ 2700 bytes, p = 0.01): 27 expected; 11..54 is beyond 3 sigma.
    assert 0.004 < corrupted / len(clean) < 0.02
    reader = FrameReader()
    reader.feed(noisy)
    assert reader.malformed > 0
    assert reader.frames > 0


def test_uart_corruption_reaches_bytes_sent_to_the_firmware():
    reader = FrameReader()
    command = build_frame("VERSION", 3).encode()
    with imu_with_sensor() as board:
        board.run_until(0.5)
        board.read_uart()
        board.set_uart_corruption(1.0, 7)
        board.write_uart(command)
        board.run_until(0.52)
        garbled = board.read_uart()
        corrupted = board.uart_corrupted_bytes
        board.set_uart_corruption(0.0, 7)
        board.run_until(1.5)
        frames = reader.feed(board.read_uart())
    # Every byte both ways had a bit flipped, so the command never arrived.
    assert corrupted == len(garbled) + len(command)
    assert not of_type(frames, "ACK")
    assert of_type(frames, "IMU")


def test_a_command_longer_than_the_receive_fifo_arrives_at_line_rate():
    reader = FrameReader()
    coefficients = [571.5, -20.23, 0.001569, -0.1044, -6.936e-05, 6.327e-09]
    command = build_frame("SETCOE", 9, ["W", "X", *coefficients]).encode()
    # More than simavr's 64-byte receive FIFO: it must wait for XON, not overflow.
    assert len(command) > 64
    with imu_with_sensor() as board:
        board.run_until(0.5)
        board.read_uart()
        board.write_uart(command + build_frame("GETCOE", 10, ["W", "X"]).encode())
        answered_after_ms = None
        # In 0.1 ms steps: the answer is timed to that, not rounded up to a whole ms.
        for tenth in range(1, 400):
            ms = tenth / 10
            board.run_until(0.5 + ms / 1000)
            frames = reader.feed(board.read_uart())
            if any(f.type == "ACK" and f["cmd_seq"] == 9 for f in frames):
                answered_after_ms = ms
                break
        board.run_until(0.6)
        frames = reader.feed(board.read_uart())
    wire_ms = len(command) * BYTE_SECONDS * 1000
    assert answered_after_ms is not None
    assert wire_ms <= answered_after_ms < wire_ms + 5
    (coe,) = of_type(frames, "COE")
    assert [coe[name] for name in ("p00", "p10", "p01", "p20", "p11", "p02")] == pytest.approx(coefficients, rel=1e-4)


def test_a_serial_program_talks_to_the_board_through_the_pty():
    reader = FrameReader()
    frames = []
    received = bytearray()
    with imu_with_sensor() as board:
        path = board.open_pty()
        assert path.startswith("/dev/pts/")
        assert board.open_pty() == path
        with serial.Serial(path, 115200, timeout=0) as port:
            for step in range(1, 151):
                board.run_until(step / 100)
                if step == 100:
                    port.write(build_frame("VERSION", 5).encode())
                chunk = port.read(4096)
                received += chunk
                frames += reader.feed(chunk)
            direct = board.read_uart()
            port.timeout = 0.2
            while len(received) < len(direct) and (chunk := port.read(len(direct) - len(received))):
                received += chunk
                frames += reader.feed(chunk)
        dropped = board.pty_dropped_bytes
    assert dropped == 0
    # The pty carries the same bytes read_uart gives.
    assert bytes(received) == direct
    imu = of_type(frames, "IMU")
    assert len(imu) >= 14
    assert (imu[-1]["ax_raw"], imu[-1]["ay_raw"], imu[-1]["az_raw"]) == SENSOR[:3]
    assert [f["device"] for f in of_type(frames, "VER")] == ["imu_reader", "imu_reader"]
    assert [(f["cmd_seq"], f["cmd_type"]) for f in of_type(frames, "ACK")] == [(5, "VERSION")]


# ---- the binding itself ---------------------------------------------------


def test_identical_inputs_give_identical_runs():
    def run() -> tuple[bytes, list[Drive]]:
        with chamber(inner_c=20.3) as board:
            drives = []
            for step in range(1, 31):
                board.run_until(step * 0.1)
                if step == 10:
                    start_program(board, 20.0)
                board.set_adc_millivolts(0, divider_millivolts(20.3 + step * 0.01))
                drives.append(board.read_l298n())
            return board.read_uart(), drives

    assert run() == run()


def test_run_until_stops_at_the_requested_time():
    with Board.thermal_chamber() as board:
        assert board.cycles == 0
        board.run_until(0.25)
        # A sleeping CPU stops at the requested cycle, one cycle of wake-up past it.
        assert 4_000_000 <= board.cycles <= 4_000_001
        board.run_until(0.1)
        assert board.seconds == pytest.approx(0.25, abs=1e-6)


def test_run_until_reaches_a_deadline_between_two_cycles():
    # A client waits "while now < deadline": a run that stopped at the cycle
    # before a deadline 0.3 cycles past it would never end (rounding to the
    # nearest cycle did, once in these 39 on a sleeping chamber).
    with Board.thermal_chamber() as board:
        for k in range(1, 40):
            deadline = 0.25 + 0.01 * k + 0.3 / board.frequency_hz
            board.run_until(deadline)
            assert board.seconds >= deadline


def test_invalid_arguments_are_refused():
    with Board.thermal_chamber() as board:
        for call in (
            lambda: board.set_adc_millivolts(8, 100),  # simavr models A0..A7
            lambda: board.set_adc_millivolts(0, 5001),
            lambda: board.set_adc_millivolts(0, -1),
            lambda: board.set_adc_millivolts(0, math.nan),
            lambda: board.set_adc_fault(0, "melted"),
            lambda: board.set_uart_corruption(1.5, 1),
            lambda: board.set_uart_corruption(0.1, -1),
            lambda: board.run_until(-1.0),
            lambda: board.run_until(math.inf),
        ):
            with pytest.raises(ValueError):
                call()
        with pytest.raises(TypeError):
            board.write_uart(build_frame("VERSION", 1))
    with Board.imu_reader() as board:
        with pytest.raises(ValueError, match="ADC channel"):
            board.set_adc_millivolts(8, 100)
        with pytest.raises(TwinError, match="attach_lsm9ds0"):
            board.set_lsm9ds0(*SENSOR)
        with pytest.raises(TwinError, match="ATmega2560"):
            board.attach_l298n()
        board.attach_lsm9ds0()
        for call in (
            lambda: board.set_lsm9ds0(40000, 0, 0, 0),
            lambda: board.set_lsm9ds0(0, 0, 0, 2048),  # OUT_TEMP_XM is 12-bit
            lambda: board.set_lsm9ds0(0, 0, 0.5, 0),
            lambda: board.set_lsm9ds0_fault("broken"),
        ):
            with pytest.raises(ValueError):
                call()


def test_a_closed_board_refuses_calls():
    board = Board.imu_reader()
    board.close()
    board.close()
    with pytest.raises(TwinError, match="closed"):
        board.run_until(1.0)


def test_bad_images_and_missing_builds_are_explained(tmp_path, monkeypatch):
    garbage = tmp_path / "garbage.elf"
    garbage.write_bytes(b"not an ELF")
    with pytest.raises(TwinError, match="cannot read firmware"):
        Board(garbage, "atmega328p")
    with pytest.raises(TwinError, match="does not know MCU"):
        Board(firmware_elf("imu_reader"), "atmega9999")
    with pytest.raises(ValueError):
        firmware_elf("toaster")
    monkeypatch.setenv("THERMOTILT_BUILD_DIR", str(tmp_path))
    assert build_dir() == tmp_path
    with pytest.raises(TwinError, match="run `make build` first"):
        firmware_elf("imu_reader")
    with pytest.raises(TwinError, match="run `make build` first"):
        Board(garbage, "atmega328p")
    # A library the loader refuses (here not a shared object at all) is one line too.
    (tmp_path / "native").mkdir()
    (tmp_path / "native" / "libthermotilt_twin.so").write_bytes(b"not a library")
    with pytest.raises(TwinError, match="cannot load .*libthermotilt_twin.so: .*run `make build` again"):
        Board(garbage, "atmega328p")


# ---- EEPROM --------------------------------------------------------------

# The datasheets: 1 KB on the ATmega328P, 4 KB on the ATmega2560; erased cells read 0xFF.
EEPROM_BYTES = {"atmega328p": 1024, "atmega2560": 4096}


def test_the_eeprom_is_blank_and_sized_as_the_datasheets_say():
    for board in (Board.imu_reader(), Board.thermal_chamber()):
        with board:
            assert board.eeprom_size == EEPROM_BYTES[board.mcu]
            assert board.read_eeprom() == b"\xff" * EEPROM_BYTES[board.mcu]


def test_eeprom_bytes_written_before_boot_are_what_the_firmware_loads_and_survive_a_watchdog_reset():
    values = PAPER_DEFAULTS.values()
    values[0] = 500.0
    block = encode_block(table_from_values(values))
    reader = FrameReader()
    with imu_with_sensor() as board:
        board.write_eeprom(block)
        board.write_eeprom(b"\x12\x34", offset=1022)
        assert board.read_eeprom(0, len(block)) == block
        board.run_until(1.0)
        board.hang()
        board.run_until(2.0)
        frames = reader.feed(board.read_uart())
        assert board.read_eeprom(0, len(block)) == block
        assert board.read_eeprom(1020) == b"\xff\xff\x12\x34"
    versions = of_type(frames, "VER")
    assert [v["reset_cause"] for v in versions] == ["POWER_ON", "WATCHDOG"]
    # Loaded at boot, and again after the reset; the sensor's sample clock
    # kept running through it, as a real sensor's does.
    rebooted = frames[frames.index(versions[1]) :]
    assert {f["coef_source"] for f in of_type(frames, "IMU")} == {"E"}
    assert len(of_type(rebooted, "IMU")) >= 4


def test_eeprom_access_beyond_its_end_is_refused():
    with Board.imu_reader() as board:
        for call in (
            lambda: board.read_eeprom(1020, 5),
            lambda: board.read_eeprom(1025),
            lambda: board.read_eeprom(-1, 1),
            lambda: board.write_eeprom(b"\x00" * 5, offset=1020),
            lambda: board.write_eeprom(b"\x00", offset=1024),
        ):
            with pytest.raises(ValueError, match="EEPROM"):
                call()
        with pytest.raises(TypeError):
            board.write_eeprom("text")
        board.write_eeprom(b"", offset=1024)
        assert board.read_eeprom(1024) == b""
        assert board.read_eeprom() == b"\xff" * 1024


def test_the_stack_high_water_mark_is_measured_on_painted_sram():
    with imu_with_sensor() as board:
        board.run_until(0.001)
        untouched_at_start, capacity = board.stack_headroom()
        board.run_until(2.0)
        untouched, same_capacity = board.stack_headroom()
    # The Nano's 2 KB SRAM ends at 0x8FF; above the ~1.2 KB of static data
    # lie some 800 bytes, which the running firmware's stack eats into.
    assert same_capacity == capacity and 300 < capacity < 1000
    assert untouched < untouched_at_start <= capacity
    assert capacity - untouched > 100
