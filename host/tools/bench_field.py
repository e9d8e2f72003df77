"""`make bench-field`: whether a sensor's certificate bounds what a monitoring
user reads in the field, over field runs of sensors drawn from the batch
population, on a Dask cluster (docs/benchmarks/field-accuracy.md;
thermotilt/calibration/field_bench.py).

Makes (or reuses) the base twin campaign in build/bench-field, calibrates
each sensor through it, runs what the record (docs/benchmarks/field-runs.csv)
does not hold yet - on a LocalCluster of this machine's cores, or on the
cluster of --scheduler - then writes the shares into the page and its
figure from the record. Ctrl-C keeps every finished run; the next start
runs only the others. --report-only rewrites the page from the record as it is.
"""

from __future__ import annotations

import argparse
import os
import sys
from contextlib import ExitStack
from pathlib import Path

import generated_page

ROOT = Path(__file__).resolve().parents[2]
COMMAND = "make bench-field"


def _field_problem() -> str | None:
    """Why this machine cannot replay field runs (the firmware's processing,
    compiled for the host, missing), or None; asked of every Dask worker."""
    from thermotilt.native import NativeLibraryError, library

    try:
        library()
    except NativeLibraryError as error:
        return str(error)
    return None


def _arguments() -> argparse.Namespace:
    from thermotilt.calibration.field_bench import DEFAULT_SENSORS, TILTS_DEG
    from thermotilt.calibration.field_calibration import BASE_POSITIONS
    from thermotilt.calibration.field_replay import FIELD_PROFILES

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    option = parser.add_argument
    option("--scheduler", help="run on the Dask cluster of this scheduler (tcp://HOST:8786)")
    option("--workers", type=int, default=os.cpu_count() or 1, help="LocalCluster worker processes")
    option("--record", type=Path, default=ROOT / "docs" / "benchmarks" / "field-runs.csv")
    option("--document", type=Path, default=ROOT / "docs" / "benchmarks" / "field-accuracy.md")
    option("--figure", type=Path, default=ROOT / "docs" / "benchmarks" / "field-accuracy.png")
    option("--folder", type=Path, default=ROOT / "build" / "bench-field", help="where the base campaign is kept")
    option("--sensors", type=int, default=DEFAULT_SENSORS, help=f"sensors drawn (default {DEFAULT_SENSORS})")
    option("--runs", type=int, default=1, help="runs per sensor, profile and tilt, each its own seed (default 1)")
    option("--profile", action="append", choices=FIELD_PROFILES, help="only these profiles")
    option("--tilt", action="append", type=float, help=f"only these tilts about X (default {TILTS_DEG})")
    option("--duration", type=float, help="every profile this long, s (default: its own; for trials)")
    option(
        "--positions",
        default=BASE_POSITIONS,
        help=f"the base campaign's positions, as campaign --positions takes them (default {BASE_POSITIONS}; "
        "all: the paper's 37); give another --folder and --record for another design",
    )
    option("--report-only", action="store_true", help="only write the page and figure from the record")
    return parser.parse_args()


def _cluster(resources: ExitStack, args: argparse.Namespace):
    from thermotilt.cluster import connect_cluster

    if args.scheduler:
        return resources.enter_context(connect_cluster(args.scheduler, _field_problem, "replay field runs"))
    import dask
    from distributed import Client, LocalCluster

    # As bench-discovery: Dask's default MALLOC_TRIM_THRESHOLD_ also fixes
    # glibc's mmap threshold, so every large array is mapped afresh.
    resources.enter_context(dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}))
    cluster = resources.enter_context(
        LocalCluster(n_workers=args.workers, threads_per_worker=1, dashboard_address="127.0.0.1:0")
    )
    return resources.enter_context(Client(cluster))


def _run(args: argparse.Namespace, design) -> int:
    from tqdm import tqdm

    from thermotilt.calibration.field_bench import run_bench
    from thermotilt.calibration.field_calibration import FieldBenchError
    from thermotilt.cluster import ClusterError

    print(f"bench-field: {len(design.tasks())} runs -> {args.record}", flush=True)
    with ExitStack() as resources:
        try:
            client = _cluster(resources, args)
        except ClusterError as error:
            print(f"bench-field: error: {error}", file=sys.stderr)
            return 1
        bar = resources.enter_context(tqdm(unit="run", file=sys.stderr, disable=None))

        def advance(done: int, total: int) -> None:
            if bar.total != total:
                bar.reset(total)
            bar.n = done
            bar.refresh()

        try:
            progress = run_bench(design, args.record, args.folder, client, args.workers, say=bar.write, bar=advance)
        except KeyboardInterrupt:
            print("\nbench-field: stopped; the finished runs are in the record", file=sys.stderr)
            return 130
        except FieldBenchError as error:
            print(f"bench-field: error: {error}", file=sys.stderr)
            return 1
    for failure in progress.failed:
        print(f"bench-field: run failed: {failure}", file=sys.stderr)
    return 0


def main() -> int:
    args = _arguments()
    # The base campaign is the benchmark's, not the lab's: nothing for the registry.
    os.environ["THERMOTILT_REGISTRY"] = "off"
    from thermotilt.calibration import field_accuracy
    from thermotilt.calibration.field_bench import Design, method_digest, read_record
    from thermotilt.calibration.field_calibration import BaseDesign

    started, load = generated_page.now(), generated_page.load_average()
    design = Design(
        sensors=args.sensors,
        runs=args.runs,
        duration_s=args.duration,
        base=BaseDesign(positions=args.positions),
        **({"profiles": tuple(args.profile)} if args.profile else {}),
        **({"tilts_deg": tuple(args.tilt)} if args.tilt else {}),
    )
    if not args.report_only:
        status = _run(args, design)
        if status:
            return status
    rows = read_record(args.record)
    command = COMMAND if not args.report_only else "python host/tools/bench_field.py --report-only"
    text = (
        field_accuracy.report(rows, method_digest())
        + "\n"
        + "\n".join(generated_page.stamp(command, started, load))
        + "\n"
    )
    try:
        generated_page.write_block(args.document, field_accuracy.BEGIN, field_accuracy.END, text)
    except ValueError as error:
        print(f"bench-field: error: {error}", file=sys.stderr)
        return 1
    field_accuracy.figure(rows, args.figure)
    print(text)
    print(f"bench-field: wrote {args.document} and {args.figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
