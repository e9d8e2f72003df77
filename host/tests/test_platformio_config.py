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


def test_the_new_bootloader_nano_env_builds_the_same_sketch_at_115200_baud():
    sections = {name: dict(options) for name, options in json.loads(pio_project_config("--json-output"))}
    old, new = sections["env:imu_reader"], sections["env:imu_reader_new"]
    assert new["board"] == "nanoatmega328new"
    assert new["upload_speed"] == 115200
    assert new["build_src_filter"] == old["build_src_filter"]
    assert new["build_flags"] == old["build_flags"]


def plain_pio_test_suites(monkeypatch, *environments: str) -> dict:
    """env -> the test suites `pio test [-e ENV ...]` runs there (not skipped)."""
    from platformio.project.config import ProjectConfig
    from platformio.test.helpers import list_test_suites

    monkeypatch.chdir(REPO)
    config = ProjectConfig(str(REPO / "platformio.ini"))
    suites = list_test_suites(config, environments=environments, filters=(), ignores=())
    run = {}
    for suite in suites:
        if not suite.is_finished():
            run.setdefault(suite.env_name, []).append(suite.test_name)
    return run


def test_a_plain_pio_test_runs_every_suite_in_simavr_and_never_on_a_board(monkeypatch):
    test_programs = sorted(path.name for path in (REPO / "test").glob("test_*") if path.is_dir())
    run = plain_pio_test_suites(monkeypatch)
    assert sorted(run) == ["simavr_mega", "simavr_nano"]
    assert all(sorted(names) == test_programs for names in run.values())
    assert plain_pio_test_suites(monkeypatch, "imu_reader", "imu_reader_new", "thermal_chamber") == {}
    assert sorted(plain_pio_test_suites(monkeypatch, "native")["native"]) == test_programs


def test_simavr_envs_upload_nothing_and_build_the_sketches_for_a_plain_pio_run():
    sections = {name: dict(options) for name, options in json.loads(pio_project_config("--json-output"))}
    defaults = sections["platformio"]["default_envs"]
    assert defaults == ["simavr_nano", "simavr_mega"]
    for env, board_env in (("simavr_nano", "imu_reader"), ("simavr_mega", "thermal_chamber")):
        simulated = sections[f"env:{env}"]
        assert simulated["upload_protocol"] == "custom"
        assert simulated["upload_command"].startswith("echo ")
        assert simulated["build_src_filter"] == sections[f"env:{board_env}"]["build_src_filter"]
        assert simulated["board"] == sections[f"env:{board_env}"]["board"]
