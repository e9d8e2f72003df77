"""test/unity_main.cpp's exit code: under PlatformIO (PIO_UNIT_TESTING) a
failed assertion must reach the user as a plain Unity failure, which
PlatformIO reads from the output, not as the signal it makes of a non-zero
exit; CTest, which runs the offline build, judges by the exit code."""

import shutil
import subprocess
from pathlib import Path

import pytest
from platformio.test.runners.unity import UnityTestRunner

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
