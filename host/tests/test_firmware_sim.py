"""The real firmware images in simavr, run by sim/avr_run.

With nothing attached, no LSM9DS0 answers on the bus and both thermistor
inputs read 0 V: each board must say what is missing, keep running, and leave
the Peltier off. With the simulated LSM9DS0 (constant acceleration and
temperature), fixed thermistor voltages and command frames on the serial
line, the boards must measure, compensate, control and answer as
docs/protocol.md says. The images come from the offline build (`make build`);
THERMOTILT_BUILD_DIR points elsewhere when needed.
"""

import math
import os
import subprocess
from pathlib import Path

import pytest
from firmware_helpers import divider_millivolts, of_type

from thermotilt.set_blend import FIRMWARE_POWER_UP_SHARE, blend
from thermotilt.surfaces import PAPER_DEFAULTS
from thermotilt.wire.protocol import PROTOCOL_VERSION, FrameReader, build_frame

pytestmark = pytest.mark.twin

REPO = Path(__file__).resolve().parents[2]
BUILD = Path(os.environ.get("THERMOTILT_BUILD_DIR", REPO / "build"))
AVR_RUN = BUILD / "native" / "avr_run"
STILL_RUNNING = 4  # avr_run's status when the image runs until the time limit


def run_board(mcu: str, image: str, seconds: float, *options: str, commands=(), tmp_path=None):
    elf = BUILD / mcu / f"{image}.elf"
    for path in (AVR_RUN, elf):
        if not path.exists():
            pytest.fail(f"{path} is missing: run `make build` first")
    arguments = list(options)
    if commands:
        command_file = tmp_path / "commands.txt"
        command_file.write_text("".join(commands))
        arguments += ["--input", str(command_file)]
    result = subprocess.run(
        [str(AVR_RUN), "-m", mcu, "-f", "16000000", "-t", str(seconds), *arguments, str(elf)],
        capture_output=True,
        timeout=120,
        check=False,
    )
    # Firmware never stops by itself: reaching the time limit is the normal end.
    assert result.returncode == STILL_RUNNING, result.stderr.decode(errors="replace")
    reader = FrameReader()
    frames = reader.feed(result.stdout)
    assert reader.malformed == 0 and reader.gaps == 0
    return frames


@pytest.fixture(scope="module")
def imu_frames():
    return run_board("atmega328p", "imu_reader", 3.5)


@pytest.fixture(scope="module")
def chamber_frames():
    return run_board("atmega2560", "thermal_chamber", 3.5)


def test_imu_reader_announces_itself(imu_frames):
    (version,) = of_type(imu_frames, "VER")
    assert version["device"] == "imu_reader"
    assert version["protocol_version"] == PROTOCOL_VERSION


def test_imu_reader_reports_missing_sensor_every_second_and_sends_no_data(imu_frames):
    errors = of_type(imu_frames, "ERR")
    # At start and then once per second of the 3.5 s run.
    assert len(errors) == 4
    assert all(e["code"] == "SENSOR_MISSING" and e["cmd_seq"] == -1 for e in errors)
    assert {e["detail"] for e in errors} == {"NO_ANSWER"}
    assert not of_type(imu_frames, "IMU")


def test_chamber_reports_thermistor_fault_with_the_peltier_off(chamber_frames):
    (version,) = of_type(chamber_frames, "VER")
    assert version["device"] == "thermal_chamber"
    (error,) = of_type(chamber_frames, "ERR")
    assert (error["code"], error["detail"]) == ("THERMISTOR", "INNER_SHORT")
    status = of_type(chamber_frames, "CHS")
    assert len(status) == 3  # one per second
    for frame in status:
        assert frame["phase"] == "F"
        assert frame["fault"] == "INNER_SHORT"
        assert (frame["pwm"], frame["dir"]) == (0, "O")
        assert math.isnan(frame["inner_c"])


# -1700 / -400 / 16000 LSB, raw temperature 32 -> 32/8 + 21 = 25.000 degC.
SENSOR = ("--lsm9ds0", "-1700,-400,16000,32")


def test_imu_reader_streams_filtered_and_compensated_frames_at_10_hz():
    frames = of_type(run_board("atmega328p", "imu_reader", 2.05, *SENSOR), "IMU")
    # 100 Hz sampling, decimation 10: one frame per 100 ms after start-up.
    assert len(frames) == 20
    assert all(b["t_ms"] - a["t_ms"] in (99, 100, 101) for a, b in zip(frames, frames[1:]))
    last = frames[-1]
    assert (last["ax_raw"], last["ay_raw"], last["az_raw"]) == (-1700, -400, 16000)
    assert (last["ax_filt"], last["ay_filt"], last["az_filt"]) == (-1700.0, -400.0, 16000.0)
    assert last["temp_c"] == 25.0
    assert (last["comp_set"], last["coef_source"]) == ("W", "D")
    # compensated = filtered - f(T, filtered), f from Tables 2 and 3 blended
    # halfway: a still temperature leaves the power-up share (set_blend).
    for axis, name in (("X", "ax"), ("Y", "ay")):
        surfaces = [PAPER_DEFAULTS.surfaces[(s, axis)].evaluate(25.0, last[f"{name}_filt"]) for s in ("W", "C")]
        expected = last[f"{name}_filt"] - blend(FIRMWARE_POWER_UP_SHARE, *surfaces)
        assert last[f"{name}_comp"] == pytest.approx(expected, abs=0.06)
    assert last["az_comp"] == 16000.0


def test_imu_reader_answers_commands(tmp_path):
    commands = [
        build_frame("SETDEC", 1, [50]),
        build_frame("GETCOE", 2, ["W", "X"]),
        "$GETCOE,3,W,X*0000\r\n",
        build_frame("BOGUS", 4),
        build_frame("SETCOE", 5, ["C", "Y", 1, 2, 3e-3, 4e-4, 5e-5, 6e-9]),
        build_frame("GETCOE", 6, ["C", "Y"]),
        build_frame("STATUS", 7),
        build_frame("SETDEC", 8, [0]),
    ]
    frames = run_board("atmega328p", "imu_reader", 1.5, *SENSOR, commands=commands, tmp_path=tmp_path)
    replies = [(f.type, f["cmd_seq"]) for f in frames if f.type in ("ACK", "ERR")]
    assert replies == [("ACK", 1), ("ACK", 2), ("ERR", -1), ("ERR", 4), ("ACK", 5), ("ACK", 6), ("ACK", 7), ("ERR", 8)]
    errors = of_type(frames, "ERR")
    assert [(e["code"], e["detail"]) for e in errors] == [
        ("BAD_FRAME", "BAD_CHECKSUM"),
        ("UNKNOWN_CMD", "BOGUS"),
        ("BAD_ARG", "FACTOR_1_255"),
    ]
    paper, uploaded = of_type(frames, "COE")
    assert tuple(paper.fields[t] for t in ("p00", "p10", "p01", "p20", "p11", "p02")) == pytest.approx(
        tuple(PAPER_DEFAULTS.surfaces[("W", "X")]), rel=1e-4
    )
    assert (uploaded["set"], uploaded["axis"], uploaded["p02"]) == ("C", "Y", pytest.approx(6e-9))
    (config,) = of_type(frames, "ICF")
    assert (config["decimation"], config["streaming"], config["coef_source"]) == (50, 1, "U")


def test_chamber_reads_both_thermistors_and_idles_without_a_program():
    frames = run_board(
        "atmega2560",
        "thermal_chamber",
        2.5,
        "--adc",
        f"0={round(divider_millivolts(20.0))}",
        "--adc",
        f"1={round(divider_millivolts(25.0))}",
    )
    assert not of_type(frames, "ERR")
    for status in of_type(frames, "CHS"):
        # One ADC count is ~0.09 degC here.
        assert status["inner_c"] == pytest.approx(20.0, abs=0.2)
        assert status["outer_c"] == pytest.approx(25.0, abs=0.2)
        assert (status["phase"], status["pwm"], status["dir"], status["fault"]) == ("I", 0, "O", "OK")
        assert math.isnan(status["setpoint_c"])


def test_chamber_runs_a_program_and_drives_the_peltier_by_the_p_law(tmp_path):
    commands = [
        build_frame("SETPRG", 1, [-20, 22, 2, 60, 1200, 1, "T"]),
        build_frame("SETPRG", 2, [18, 22, 2, 60, 1200, 1, "T"]),
        build_frame("START", 3),
        build_frame("SETPRG", 4, [16, 22, 2, 60, 1200, 1, "T"]),
        build_frame("STATUS", 5),
    ]
    # avr_run holds an input at whole millivolts.
    inner = round(divider_millivolts(18.3))
    frames = run_board(
        "atmega2560",
        "thermal_chamber",
        2.5,
        "--adc",
        f"0={inner}",
        "--adc",
        "1=2500",
        commands=commands,
        tmp_path=tmp_path,
    )
    errors = of_type(frames, "ERR")
    assert [(e["cmd_seq"], e["code"], e["detail"]) for e in errors] == [
        (1, "BAD_ARG", "START_RANGE"),
        (4, "BUSY", "STOP_FIRST"),
    ]
    (program,) = of_type(frames, "PRG")
    assert (program["start_c"], program["max_c"], program["mode"], program["kp"]) == (18.0, 22.0, "P", 350.0)
    status = of_type(frames, "CHS")[-1]
    assert (status["phase"], status["step"], status["setpoint_c"]) == ("W", 0, 18.0)
    # Error = 18 - inner, a few tenths of a degree -> cool at 350 * |error|,
    # well short of saturation; inner_c is reported to 0.01 degC, worth 1.75 PWM.
    expected_pwm = 350.0 * (status["inner_c"] - 18.0)
    assert status["dir"] == "C"
    assert status["pwm"] == pytest.approx(expected_pwm, abs=1.75)
    assert 50 < status["pwm"] < 200
