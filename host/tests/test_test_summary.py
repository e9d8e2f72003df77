"""cmake/test_summary.py: make test's closing counts come from the runners'
JUnit files, and a program that dies without a Unity failure still fails."""

import subprocess
import sys
from pathlib import Path

SUMMARY = Path(__file__).resolve().parents[2] / "cmake" / "test_summary.py"

UNITY_PASSING = """<testsuite tests="2">
<testcase name="native.test_a" status="run"><system-out>t.cpp:10:test_one:PASS
t.cpp:11:test_two:PASS
t.cpp:12:test_three:IGNORE
-----------------------
3 Tests 0 Failures 1 Ignored
OK</system-out></testcase>
<testcase name="native.test_b" status="fail"><system-out>t.cpp:20:test_four:PASS
t.cpp:21:test_five:FAIL: Expected 1 Was 2
-----------------------
2 Tests 1 Failures 0 Ignored
FAIL</system-out></testcase>
</testsuite>"""

UNITY_CRASHED = """<testsuite tests="1">
<testcase name="atmega328p.test_c" status="fail"><system-out>Loaded 7230 .text at address 0x0
t.cpp:30:test_six:PASS
</system-out></testcase>
</testsuite>"""

PYTEST = """<testsuites><testsuite>
<testcase classname="a" name="ok"/>
<testcase classname="a" name="broken"><failure message="x"/></testcase>
<testcase classname="a" name="setup_broken"><error message="x"/></testcase>
<testcase classname="a" name="skipped"><skipped type="pytest.skip" message="x"/></testcase>
<testcase classname="a" name="expected"><skipped type="pytest.xfail" message="x"/></testcase>
</testsuite></testsuites>"""


def summarise(tmp_path, *, unity, pytest_xml=PYTEST, fuzz="fuzz: 3 targets, 900 runs, 0 crashes", fuzz_failed=0):
    arguments = []
    for label, text in unity.items():
        path = tmp_path / f"{label}.xml"
        path.write_text(text)
        arguments += ["--unity", f"{label}={path}"]
    pytest_path = tmp_path / "pytest.xml"
    if pytest_xml is not None:
        pytest_path.write_text(pytest_xml)
    return subprocess.run(
        [
            sys.executable,
            str(SUMMARY),
            *arguments,
            "--pytest",
            str(pytest_path),
            "--fuzz",
            fuzz,
            "--fuzz-failed",
            str(fuzz_failed),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_counts_each_runners_cases(tmp_path):
    result = summarise(tmp_path, unity={"native": UNITY_PASSING})
    lines = result.stdout.splitlines()
    assert lines == [
        "native: 2 test programs, 5 Unity tests, 1 failures, 1 ignored",
        "host: pytest 1 passed, 2 failed, 1 skipped, 1 expected failures",
        "fuzz: 3 targets, 900 runs, 0 crashes",
        "total: 7 passed, 3 failed",  # Unity 3 + pytest 1 + fuzz 3; Unity 1 + pytest 2
    ]
    assert result.returncode == 1


def test_a_program_that_died_outside_unity_counts_as_a_failure(tmp_path):
    result = summarise(
        tmp_path,
        unity={"simavr atmega328p": UNITY_CRASHED},
        pytest_xml=PYTEST.replace('<failure message="x"/>', "").replace('<error message="x"/>', ""),
    )
    assert "1 Unity tests, 0 failures, 0 ignored, 1 programs failed outside Unity" in result.stdout
    assert result.stdout.splitlines()[-1] == "total: 7 passed, 1 failed"
    assert "atmega328p.test_c failed without a Unity failure" in result.stderr
    assert result.returncode == 1


def test_missing_results_and_a_fuzz_run_that_did_not_run_fail(tmp_path):
    result = summarise(
        tmp_path,
        unity={
            "native": UNITY_PASSING.replace('status="fail"', 'status="run"').replace(":FAIL: Expected 1 Was 2", ":PASS")
        },
        pytest_xml=None,
        fuzz="",
        fuzz_failed=0,
    )
    assert "host: pytest no results" in result.stdout
    assert "fuzz: did not run" in result.stdout
    assert result.stdout.splitlines()[-1] == "total: 4 passed, 2 failed"
    assert result.returncode == 1


def test_all_passing_exits_zero(tmp_path):
    passing = PYTEST.replace('<failure message="x"/>', "").replace('<error message="x"/>', "")
    result = summarise(
        tmp_path, unity={"native": UNITY_CRASHED.replace('status="fail"', 'status="run"')}, pytest_xml=passing
    )
    assert result.stdout.splitlines()[-1] == "total: 7 passed, 0 failed"
    assert result.returncode == 0


UNITY_ON_THE_NANO = """<testsuite tests="2">
<testcase name="atmega328p.test_d" status="run"><system-out>t.cpp:40:test_seven:PASS
-----------------------
1 Tests 0 Failures 0 Ignored
OK
avr_run: RAM 2048 B: static 1299 B, stack untouched 329 B
</system-out></testcase>
<testcase name="atmega328p.test_long_name" status="fail"><system-out>t.cpp:50:test_eight:PASS
avr_run: RAM 2048 B: static 1885 B, stack untouched 105 B
avr_run: build/test_long_name.elf restarted during test_nine after 2.007 s simulated
</system-out></testcase>
</testsuite>"""


def test_each_avr_program_shows_its_ram_and_why_avr_run_failed_it(tmp_path):
    result = summarise(tmp_path, unity={"simavr atmega328p": UNITY_ON_THE_NANO})
    lines = result.stdout.splitlines()
    assert lines[:4] == [
        "simavr atmega328p: 2 test programs, 2 Unity tests, 0 failures, 0 ignored, 1 programs failed outside Unity",
        "  RAM of 2048 B   static  stack untouched",
        "  test_d            1299              329",
        "  test_long_name    1885              105",
    ]
    assert (
        "atmega328p.test_long_name failed without a Unity failure: "
        "avr_run: build/test_long_name.elf restarted during test_nine after 2.007 s simulated"
    ) in result.stderr
    assert result.returncode == 1
