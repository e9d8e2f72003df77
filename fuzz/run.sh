#!/usr/bin/env bash
# Runs every libFuzzer target of the fuzz tree for SECONDS each, seeded from
# fuzz/corpus/<target> and replaying fuzz/regressions/<target>; new inputs go
# to BUILD_DIR/corpus/<target>, crash inputs to BUILD_DIR/artifacts/<target>.
# Prints one line per target and a closing "fuzz: N targets, N runs, N crashes";
# exits with the number of targets that crashed or failed to run.
# Usage: fuzz/run.sh BUILD_DIR SECONDS
set -uo pipefail

build=$1
seconds=$2
fuzz_dir=$(cd "$(dirname "$0")" && pwd)
targets=(fuzz_frame_parser fuzz_chamber_commands fuzz_imu_commands)
failed=0
total_runs=0
total_crashes=0

# Each target on its own core, as many at once as there are cores: the
# same fuzzing per target as one after another, in less wall time.
fuzz_one() {
    local target=$1
    local work="$build/corpus/$target" artifacts="$build/artifacts/$target"
    local corpora=("$work" "$fuzz_dir/corpus/$target")
    [ -d "$fuzz_dir/regressions/$target" ] && corpora+=("$fuzz_dir/regressions/$target")
    "$build/$target" -max_total_time="$seconds" -timeout=10 -print_final_stats=1 \
        -artifact_prefix="$artifacts/" "${corpora[@]}" >"$build/logs/$target.log" 2>&1
    echo $? >"$build/logs/$target.status"
}

cores=$(nproc 2>/dev/null || echo 1)
for target in "${targets[@]}"; do
    mkdir -p "$build/corpus/$target" "$build/artifacts/$target" "$build/logs"
    rm -f "$build/logs/$target.status"
    while [ "$(jobs -rp | wc -l)" -ge "$cores" ]; do
        wait -n
    done
    fuzz_one "$target" &
done
wait

for target in "${targets[@]}"; do
    log="$build/logs/$target.log"
    status=$(cat "$build/logs/$target.status" 2>/dev/null || echo 1)
    runs=$(awk '/^stat::number_of_executed_units:/ {print $2}' "$log")
    rate=$(awk '/^stat::average_exec_per_sec:/ {print $2}' "$log")
    coverage=$(grep -Eo 'cov: [0-9]+' "$log" | tail -1 | awk '{print $2}')
    crashes=$(grep -c 'Test unit written to' "$log")
    total_runs=$((total_runs + ${runs:-0}))
    total_crashes=$((total_crashes + crashes))
    echo "$target: ${runs:-0} runs (${rate:-0}/s), cov: ${coverage:-0}, crashes: $crashes"
    if [ "$status" -ne 0 ] || [ "$crashes" -ne 0 ]; then
        failed=$((failed + 1))
        echo "  FAILED (exit $status); log: $log"
        sed -E -n '/invariant violated|ERROR: (AddressSanitizer|libFuzzer|LeakSanitizer)|runtime error|No such file/,/Test unit written to/p' \
            "$log" | head -80 | sed 's/^/  | /'
    fi
done

echo "fuzz: ${#targets[@]} targets, $total_runs runs, $total_crashes crashes"
exit "$failed"
