"""test/unity_main.cpp's exit code: under PlatformIO (PIO_UNIT_TESTING) a
failed assertion must reach the user as a plain Unity failure, which
PlatformIO reads from the output, not as the signal it makes of a non-zero
exit; CTest, which runs the offline build, judges by the exit code. On the
AVR, a program that restarts fails the test it was in, both under
sim/avr_run and under stock simavr; avr_run fails a program that left too
little stack untouched."""

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from platformio.test.runners.unity import UnityTestRunner

from thermotilt.twin.boards import Board, TwinError

REPO = Path(__file__).resolve().parents[2]
FALLBACK_UNITY = REPO / "cmake" / "unity"

FAILING_TEST = """
#include <unity.h>

void setUp(void) {}
void tearDown(void) {}

static void test_one_is_two(void)
{
    TEST_ASSERT_EQUAL_INT(1, 2);
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_one_is_two);
    return UNITY_END();
}
"""


def run_failing_test_program(tmp_path: Path, *defines: str) -> subprocess.CompletedProcess:
    """Builds unity_main.cpp with one failing test, as the native envs do, and runs it."""
    if shutil.which("cc") is None or shutil.which("c++") is None:
        pytest.skip("no native C/C++ compiler")
    test_source = tmp_path / "test_failing.cpp"
    test_source.write_text(FAILING_TEST)
    unity_object = tmp_path / "unity.o"
    program = tmp_path / "program"
    includes = [f"-I{FALLBACK_UNITY}", f"-I{REPO / 'cmake' / 'unity_config'}", "-DUNITY_INCLUDE_CONFIG_H"]
    subprocess.run(["cc", "-c", *includes, str(FALLBACK_UNITY / "unity.c"), "-o", str(unity_object)], check=True)
    subprocess.run(
        [
            "c++",
            *includes,
            *defines,
            str(REPO / "test" / "unity_main.cpp"),
            str(test_source),
            str(unity_object),
            "-o",
            str(program),
        ],
        check=True,
    )
    return subprocess.run([str(program)], capture_output=True, text=True, timeout=30, check=False)


def platformio_cases(output: str) -> list:
    """The test cases PlatformIO's Unity runner reads from a program's output."""
    return [match.groupdict() for match in map(UnityTestRunner.TESTCASE_PARSE_RE.search, output.splitlines()) if match]


def test_under_platformio_a_failure_is_read_from_unity_and_the_program_exits_0(tmp_path):
    result = run_failing_test_program(tmp_path, "-DPIO_UNIT_TESTING")
    assert result.returncode == 0, result.stdout + result.stderr
    cases = platformio_cases(result.stdout)
    assert [(case["name"], case["status"]) for case in cases] == [("test_one_is_two", "FAIL")], result.stdout


def test_under_ctest_a_failure_exits_non_zero(tmp_path):
    result = run_failing_test_program(tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert [case["status"] for case in platformio_cases(result.stdout)] == ["FAIL"]


# The second test jumps to the reset vector once the first test's line is
# out (a restart after a crash comes with the UART idle as often as not).
RESTARTING_TEST = """
#include <Arduino.h>
#include <unity.h>

void setUp(void) {}
void tearDown(void) {}

static void test_first(void)
{
    TEST_ASSERT_TRUE(1);
}

static void test_jumps_to_the_reset_vector(void)
{
    Serial.flush();
    asm volatile("jmp 0");
}

static void test_never_reached(void)
{
    TEST_ASSERT_TRUE(1);
}

int runUnityTests(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_first);
    RUN_TEST(test_jumps_to_the_reset_vector);
    RUN_TEST(test_never_reached);
    return UNITY_END();
}
"""
ARDUINO_AVR = Path("/usr/share/arduino/hardware/arduino/avr")
BUILD = Path(os.environ.get("THERMOTILT_BUILD_DIR", REPO / "build"))
AVR_RUN = BUILD / "native" / "avr_run"
RESTARTED = 6  # avr_run's status for a program that started again
STACK_SHORT = 5  # and for one that left too little stack untouched


def build_restarting_program(tmp_path: Path) -> Path:
    """The restarting test with unity_main.cpp, linked as the offline build
    links a Nano's test program (its Unity and Arduino core archives)."""
    tree = BUILD / "atmega328p"
    archives = [tree / "libunity.a", tree / "libarduino_core.a"]
    for path in (AVR_RUN, *archives):
        if not path.exists():
            pytest.fail(f"{path} is missing: run `make build` first")
    source = tmp_path / "test_restarting.cpp"
    source.write_text(RESTARTING_TEST)
    program = tmp_path / "test_restarting.elf"
    flags = ["-mmcu=atmega328p", "-Os", "-flto", "-DF_CPU=16000000L", "-DARDUINO=10807", "-DARDUINO_ARCH_AVR"]
    includes = [
        f"-I{ARDUINO_AVR / 'cores' / 'arduino'}",
        f"-I{ARDUINO_AVR / 'variants' / 'eightanaloginputs'}",
        f"-I{FALLBACK_UNITY}",
        f"-I{REPO / 'cmake' / 'unity_config'}",
        "-DUNITY_INCLUDE_CONFIG_H",
    ]
    subprocess.run(
        ["avr-g++", *flags, *includes, str(REPO / "test" / "unity_main.cpp"), str(source), *map(str, archives)]
        + ["-o", str(program)],
        check=True,
    )
    return program


@pytest.mark.twin
def test_a_nano_test_program_that_restarts_fails_the_test_it_was_in(tmp_path):
    program = build_restarting_program(tmp_path)
    # avr_run, which runs make test's AVR programs, stops at the second start.
    result = subprocess.run(
        [str(AVR_RUN), "-m", "atmega328p", "-f", "16000000", "-t", "60", "--unity", str(program)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == RESTARTED, result.stdout + result.stderr
    assert "restarted during test_jumps_to_the_reset_vector" in result.stderr
    # Under stock simavr (pio test) the program reports its own restart.
    with Board(program, "atmega328p") as board:
        with pytest.raises(TwinError, match="slept with interrupts off"):
            board.run_until(30.0)
        output = board.read_uart().decode()
    cases = [(case["name"], case["status"]) for case in platformio_cases(output)]
    assert cases == [("test_first", "PASS"), ("test_jumps_to_the_reset_vector", "FAIL")], output
    assert "the program restarted during this test" in output
    assert "1 Tests 1 Failures 0 Ignored" in output


@pytest.mark.twin
def test_avr_run_fails_a_program_whose_stack_kept_too_little_untouched():
    program = BUILD / "atmega328p" / "test_thermistor.elf"
    command = [str(AVR_RUN), "-m", "atmega328p", "-f", "16000000", "-t", "60", "--unity", str(program)]
    passing = subprocess.run([*command[:-1], "--min-stack", "256", str(program)], capture_output=True, text=True)
    assert passing.returncode == 0, passing.stderr
    ram = re.search(r"^avr_run: RAM 2048 B: static (\d+) B, stack untouched (\d+) B$", passing.stdout, re.M)
    assert ram and int(ram[1]) + int(ram[2]) <= 2048 and int(ram[2]) >= 256, passing.stdout
    # Asked for more than the whole SRAM above the static data, it fails though its tests passed.
    short = subprocess.run([*command[:-1], "--min-stack", "2000", str(program)], capture_output=True, text=True)
    assert short.returncode == STACK_SHORT, short.stderr
    assert "OK" in short.stdout.splitlines()
    assert f"left {ram[2]} B of stack untouched, fewer than the 2000 B required" in short.stderr
