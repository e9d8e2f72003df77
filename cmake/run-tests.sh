#!/usr/bin/env bash
# Runs every test tree of the offline build, the host's pytest suite and a
# short run of each fuzz target, then prints how many tests ran from the
# runners' own result files (cmake/test_summary.py).
# Usage: BUILD=build VENV=.venv cmake/run-tests.sh MCU...
set -uo pipefail

build=${BUILD:-build}
venv=${VENV:-.venv}
results=$(mkdir -p "$build" && cd "$build" && pwd)/test-results
rm -rf "$results" && mkdir -p "$results"
failed_steps=0
unity_results=()

# CTest keeps each Unity program's whole output in its JUnit file; passed
# tests' output is cut at 1 KiB unless told otherwise.
run_ctest_tree() {
    local name=$1 dir=$2 file=$3
    echo "== ${name}: Unity tests (${dir})"
    (cd "$dir" && ctest --output-on-failure --output-junit "$results/$file" \
        --test-output-size-passed 1048576 --test-output-size-failed 1048576) ||
        failed_steps=$((failed_steps + 1))
    unity_results+=(--unity "${name}=$results/$file")
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
run_ctest_tree native "$build/native" unity-native.xml
for mcu in "$@"; do
    run_ctest_tree "simavr ${mcu}" "$build/$mcu" "unity-${mcu}.xml"
done

# On every core (pytest-xdist); a worker that finishes early takes tests
# from a busy one's queue, so the discovery tests' long twin runs spread.
# PYTEST_WORKERS=0 runs them in this process, one after another. The tests
# marked long (whole twin campaigns, every discovery candidate) are
# make test-long's.
pytest_workers=${PYTEST_WORKERS:-auto}
echo "== host: pytest (workers: ${pytest_workers}; not the long tests)"
"$venv/bin/python" -m pytest host/tests -m "not long" -n "$pytest_workers" --dist worksteal \
    --junitxml="$results/pytest.xml" ||
    failed_steps=$((failed_steps + 1))

# Each libFuzzer target for a bounded time; a crash or sanitizer report fails
# the step, and each target counts as one test.
fuzz_seconds=20
echo "== fuzz: libFuzzer targets, ${fuzz_seconds} s each"
fuzz_log="$results/fuzz.log"
bash fuzz/run.sh "$build/fuzz" "$fuzz_seconds" 2>&1 | tee "$fuzz_log"
# fuzz/run.sh exits with the number of targets that failed.
fuzz_failed=${PIPESTATUS[0]}
[ "$fuzz_failed" -eq 0 ] || failed_steps=$((failed_steps + 1))

echo
echo "== summary"
"$venv/bin/python" cmake/test_summary.py "${unity_results[@]}" --pytest "$results/pytest.xml" \
    --fuzz "$(grep -E '^fuzz: [0-9]+ targets' "$fuzz_log" | tail -1)" --fuzz-failed "$fuzz_failed"
summary_status=$?
# A build error or a runner that died fails its step even where no result
# file counts a failure.
[ "$failed_steps" -eq 0 ] && [ "$summary_status" -eq 0 ]
