"""The real firmware images in simavr with nothing attached to them.

No LSM9DS0 answers on the bus and both thermistor inputs read 0 V, so each
board must say what is missing, keep running, and leave the Peltier off.
The images come from the offline build (`make build`); THERMOTILT_BUILD_DIR
points elsewhere when needed.
"""

import math
import os
import subprocess
from pathlib import Path

import pytest

from thermotilt.protocol import PROTOCOL_VERSION, FrameReader

REPO = Path(__file__).resolve().parents[2]
BUILD = Path(os.environ.get("THERMOTILT_BUILD_DIR", REPO / "build"))
AVR_RUN = BUILD / "native" / "avr_run"
STILL_RUNNING = 4  # avr_run's status when the image runs until the time limit


def run_board(mcu: str, image: str, seconds: float):
    elf = BUILD / mcu / f"{image}.elf"
    for path in (AVR_RUN, elf):
        if not path.exists():
            pytest.fail(f"{path} is missing: run `make build` first")
    result = subprocess.run(
        [str(AVR_RUN), "-m", mcu, "-f", "16000000", "-t", str(seconds), str(elf)],
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


def of_type(frames, frame_type):
    return [frame for frame in frames if frame.type == frame_type]


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
