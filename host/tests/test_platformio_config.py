"""platformio.ini must stay valid for PlatformIO users, even where its
registry (platforms, toolchains) cannot be reached: reading and linting the
project configuration runs offline."""

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def pio_project_config(*options: str) -> str:
    result = subprocess.run(
        [sys.executable, "-m", "platformio", "project", "config", *options],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return result.stdout


def test_platformio_lints_the_project_configuration_clean():
    assert "free from linting errors" in pio_project_config("--lint")


def test_each_board_builds_its_own_sketch_and_tests_run_in_simavr():
    sections = {name: dict(options) for name, options in json.loads(pio_project_config("--json-output"))}
    assert sections["env:imu_reader"]["board"] == "nanoatmega328"
    assert sections["env:imu_reader"]["build_src_filter"] == ["+<imu_reader/> +<common/>"]
    assert sections["env:thermal_chamber"]["board"] == "megaatmega2560"
    assert sections["env:thermal_chamber"]["build_src_filter"] == ["+<thermal_chamber/> +<common/>"]
    assert sections["env:native"]["platform"] == "native"
    for env, mcu in (("simavr_nano", "atmega328p"), ("simavr_mega", "atmega2560")):
        command = sections[f"env:{env}"]["test_testing_command"]
        assert command[0].endswith("tool-simavr/bin/simavr")
        assert command[1:3] == ["-m", mcu]
        assert command[-1].endswith(f"/{env}/firmware.elf")
