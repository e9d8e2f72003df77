#!/usr/bin/env bash
# Runs every test tree of the offline build, the host's pytest suite and a
# short run of each fuzz target, then prints how many tests ran.
# Usage: BUILD=build VENV=.venv cmake/run-tests.sh MCU...
set -uo pipefail

build=${BUILD:-build}
venv=${VENV:-.venv}
failed_steps=0
total_passed=0
total_failed=0
summary=()

# Unity prints "N Tests N Failures N Ignored" per test program; CTest keeps
# every program's output in LastTest.log.
count_unity_cases() {
    local log=$1/Testing/Temporary/LastTest.log
    grep -E '^[0-9]+ Tests [0-9]+ Failures [0-9]+ Ignored' "$log" 2>/dev/null |
        awk '{tests += $1; failures += $3; ignored += $5} END {printf "%d %d %d\n", tests, failures, ignored}'
}

run_ctest_tree() {
    local name=$1 dir=$2
    echo "== ${name}: Unity tests (${dir})"
    (cd "$dir" && ctest --output-on-failure) || failed_steps=$((failed_steps + 1))
    read -r tests failures ignored < <(count_unity_cases "$dir")
    local programs
    programs=$(cd "$dir" && ctest -N | awk '/^Total Tests:/ {print $3}')
    summary+=("${name}: ${programs} test programs, ${tests} Unity tests, ${failures} failures, ${ignored} ignored")
    total_passed=$((total_passed + tests - failures - ignored))
    total_failed=$((total_failed + failures))
}

# Which Unity the tests were built with (cmake/unity.cmake), on one line that
# names the trees only when they differ.
report_unity() {
    local tree unity i trees=() unities=()
    for tree in native "$@"; do
        trees+=("$tree")
        unity=$(sed -n 's/^THERMOTILT_UNITY:INTERNAL=//p' "$build/$tree/CMakeCache.txt" 2>/dev/null)
        unities+=("${unity:-unknown}")
    done
    if [ "$(printf '%s\n' "${unities[@]}" | sort -u | wc -l)" -eq 1 ]; then
        echo "== Unity: ${unities[0]}"
        return
    fi
    local line="== Unity:"
    for i in "${!trees[@]}"; do
        line+=" ${trees[$i]}: ${unities[$i]};"
    done
    echo "${line%;}"
}

report_unity "$@"
run_ctest_tree native "$build/native"
for mcu in "$@"; do
    run_ctest_tree "simavr ${mcu}" "$build/$mcu"
done

echo "== host: pytest"
pytest_log=$(mktemp)
"$venv/bin/python" -m pytest host/tests 2>&1 | tee "$pytest_log"
pytest_status=${PIPESTATUS[0]}
[ "$pytest_status" -eq 0 ] || failed_steps=$((failed_steps + 1))
pytest_passed=$(grep -Eo '[0-9]+ passed' "$pytest_log" | tail -1 | awk '{print $1}')
pytest_failed=$(grep -Eo '[0-9]+ (failed|error)' "$pytest_log" | awk '{n += $1} END {print n + 0}')
rm -f "$pytest_log"
summary+=("host: pytest ${pytest_passed:-0} passed, ${pytest_failed} failed")
total_passed=$((total_passed + ${pytest_passed:-0}))
total_failed=$((total_failed + pytest_failed))

# Each libFuzzer target for a bounded time; a crash or sanitizer report fails
# the step, and each target counts as one test.
fuzz_seconds=20
echo "== fuzz: libFuzzer targets, ${fuzz_seconds} s each"
fuzz_log=$(mktemp)
bash fuzz/run.sh "$build/fuzz" "$fuzz_seconds" 2>&1 | tee "$fuzz_log"
fuzz_failed=${PIPESTATUS[0]}
fuzz_summary=$(grep -E '^fuzz: [0-9]+ targets' "$fuzz_log" | tail -1)
rm -f "$fuzz_log"
# fuzz/run.sh exits with the number of targets that failed.
if [ -n "$fuzz_summary" ]; then
    fuzz_targets=$(echo "$fuzz_summary" | awk '{print $2}')
    total_passed=$((total_passed + fuzz_targets - fuzz_failed))
else
    fuzz_summary="fuzz: did not run"
    fuzz_failed=1
fi
[ "$fuzz_failed" -eq 0 ] || failed_steps=$((failed_steps + 1))
summary+=("$fuzz_summary")
total_failed=$((total_failed + fuzz_failed))

echo
echo "== summary"
printf '%s\n' "${summary[@]}"
if [ "$failed_steps" -ne 0 ] && [ "$total_failed" -eq 0 ]; then
    # A crash, time-out or build error fails a step without a counted failure.
    total_failed=$failed_steps
fi
echo "total: ${total_passed} passed, ${total_failed} failed"
[ "$failed_steps" -eq 0 ]
