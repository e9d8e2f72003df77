"""The closing lines of `make test`, read from the runners' own results:
CTest's JUnit file for each Unity tree (one CTest test per Unity program,
Unity's per-case result lines in its output), pytest's JUnit file, and
fuzz/run.sh's closing line.

Usage: test_summary.py --unity LABEL=FILE... --pytest FILE --fuzz LINE --fuzz-failed N

Prints one line per runner and `total: N passed, N failed`; exits 1 when
anything failed, a results file is missing, or a program failed without a
Unity failure to show for it (a crash, a restart, a time-out, a stack short
of its headroom), which counts as one. Under a simulated MCU's line, each
program's static RAM and the bytes its stack never reached (sim/avr_run.c).
"""

import argparse
import re
import sys
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass

# Unity's per-case line: FILE:LINE:TEST:PASS, or :FAIL/:IGNORE with an
# optional ": message".
UNITY_CASE = re.compile(r"^.+:\d+:\w+:(PASS|FAIL|IGNORE)(?::.*)?$", re.MULTILINE)
# sim/avr_run's closing line of a Unity run, and its verdict on a run that
# did not end in Unity's own.
RAM_LINE = re.compile(r"^avr_run: RAM (\d+) B: static (\d+) B, stack untouched (\d+) B$", re.MULTILINE)
AVR_RUN_VERDICT = re.compile(r"^avr_run: (?!RAM ).*$", re.MULTILINE)


@dataclass
class Counts:
    passed: int = 0
    failed: int = 0


def read_junit(path: str) -> ElementTree.Element | None:
    try:
        return ElementTree.parse(path).getroot()
    except (OSError, ElementTree.ParseError) as error:
        print(f"cannot read {path}: {error}", file=sys.stderr)
        return None


def ram_table(ram: list[tuple[str, int, int, int]]) -> list[str]:
    """Each program's static RAM and untouched stack, in bytes."""
    if not ram:
        return []
    width = max(len(name) for name, *_ in ram)
    lines = [f"  {f'RAM of {ram[0][1]} B':<{width}}  static  stack untouched"]
    lines += [f"  {name:<{width}}  {static:>6}  {untouched:>15}" for name, _, static, untouched in ram]
    return lines


def unity_tree(label: str, path: str, counts: Counts) -> list[str]:
    root = read_junit(path)
    if root is None:
        counts.failed += 1
        return [f"{label}: no results ({path})"]
    programs = tests = failures = ignored = silent_failures = 0
    ram = []
    for case in root.iter("testcase"):
        programs += 1
        output = case.findtext("system-out") or ""
        results = UNITY_CASE.findall(output)
        tests += len(results)
        failures += results.count("FAIL")
        ignored += results.count("IGNORE")
        name = case.get("name", "").partition(".")[2]
        ram += [(name, *map(int, line)) for line in RAM_LINE.findall(output)]
        if case.get("status") == "fail" and "FAIL" not in results:
            silent_failures += 1
            verdicts = "; ".join(AVR_RUN_VERDICT.findall(output))
            print(f"{label}: {case.get('name')} failed without a Unity failure{': ' if verdicts else ''}{verdicts}",
                  file=sys.stderr)
    counts.passed += tests - failures - ignored
    counts.failed += failures + silent_failures
    crashed = f", {silent_failures} programs failed outside Unity" if silent_failures else ""
    line = f"{label}: {programs} test programs, {tests} Unity tests, {failures} failures, {ignored} ignored{crashed}"
    return [line, *ram_table(ram)]


def pytest_suite(path: str, counts: Counts) -> str:
    root = read_junit(path)
    if root is None:
        counts.failed += 1
        return f"host: pytest no results ({path})"
    passed = failed = skipped = expected_failures = 0
    for case in root.iter("testcase"):
        skip = case.find("skipped")
        if case.find("failure") is not None or case.find("error") is not None:
            failed += 1
        elif skip is not None and skip.get("type") == "pytest.xfail":
            expected_failures += 1
        elif skip is not None:
            skipped += 1
        else:
            passed += 1
    counts.passed += passed
    counts.failed += failed
    return (f"host: pytest {passed} passed, {failed} failed, {skipped} skipped, "
            f"{expected_failures} expected failures")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--unity", action="append", default=[], metavar="LABEL=FILE")
    parser.add_argument("--pytest", required=True, metavar="FILE")
    parser.add_argument("--fuzz", required=True, metavar="LINE", help="fuzz/run.sh's closing line")
    parser.add_argument("--fuzz-failed", type=int, required=True, metavar="N",
                        help="fuzz/run.sh's exit status: the targets that failed")
    args = parser.parse_args()

    counts = Counts()
    lines = []
    for tree in args.unity:
        label, _, path = tree.partition("=")
        lines += unity_tree(label, path, counts)
    lines.append(pytest_suite(args.pytest, counts))
    fuzz_targets = re.match(r"fuzz: (\d+) targets", args.fuzz)
    if fuzz_targets:
        counts.passed += int(fuzz_targets.group(1)) - args.fuzz_failed
        counts.failed += args.fuzz_failed
        lines.append(args.fuzz)
    else:
        counts.failed += max(args.fuzz_failed, 1)
        lines.append("fuzz: did not run")

    print("\n".join(lines))
    print(f"total: {counts.passed} passed, {counts.failed} failed")
    return 1 if counts.failed else 0


if __name__ == "__main__":
    sys.exit(main())
