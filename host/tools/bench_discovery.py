"""`make bench-discovery`: how often `thermotilt discover` is right, over
hundreds of runs with a known effect (or none) hidden in them, on a Dask
cluster (docs/discovery.md, "Benchmark"; thermotilt/discovery/benchmark.py).

Runs what the record (docs/benchmarks/discovery-runs.csv) does not hold yet
— on a LocalCluster of this machine's cores, or on the cluster of
--scheduler — then writes the rates into docs/discovery.md and the figure
docs/benchmarks/discovery-rates.png from the record (how long one
discovery takes, `make bench` measures). Ctrl-C keeps every finished run; the next
start runs only the others. --report-only rewrites the tables and the
figure from the record as it is.
"""

from __future__ import annotations

import argparse
import os
import sys
from contextlib import ExitStack
from pathlib import Path

import generated_page

ROOT = Path(__file__).resolve().parents[2]
ROWS_FOR_SPEED = 100_000


def _discovery_problem() -> str | None:
    """Why this machine cannot run discovery (the firmware's processing,
    compiled for the host, missing), or None; asked of every Dask worker."""
    from thermotilt.native import NativeLibraryError, library

    try:
        library()
    except NativeLibraryError as error:
        return str(error)
    return None


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scheduler", help="run on the Dask cluster of this scheduler (tcp://HOST:8786)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="LocalCluster worker processes")
    parser.add_argument("--record", type=Path, default=ROOT / "docs" / "benchmarks" / "discovery-runs.csv")
    parser.add_argument("--document", type=Path, default=ROOT / "docs" / "discovery.md")
    parser.add_argument("--figure", type=Path, default=ROOT / "docs" / "benchmarks" / "discovery-rates.png")
    parser.add_argument(
        "--bases", type=Path, default=ROOT / "build" / "bench-discovery", help="where base runs are kept"
    )
    parser.add_argument(
        "--base-record",
        type=Path,
        default=ROOT / "docs" / "benchmarks" / "discovery-bases.csv",
        help="what making each base took here",
    )
    parser.add_argument("--null-runs", type=int, help="per noise family and base (default: the design's)")
    parser.add_argument("--effect-runs", type=int, help="per candidate and SNR (default: the design's)")
    parser.add_argument("--collinear-runs", type=int, help="per designed pair (default: the design's)")
    parser.add_argument("--world-runs", type=int, help="per cell of changed worlds (default: the design's)")
    parser.add_argument(
        "--kind", action="append", choices=("null", "effect", "collinear", "world"), help="only these runs"
    )
    parser.add_argument(
        "--base", action="append", help="only the runs on these bases (staircase, cycle, wave, ramp, fig8, chamber)"
    )
    parser.add_argument("--report-only", action="store_true", help="only write the tables and figure from the record")
    args = parser.parse_args()

    from tqdm import tqdm

    from thermotilt.cluster import ClusterError, connect_cluster
    from thermotilt.discovery import rates
    from thermotilt.discovery.bases import read_base_seconds
    from thermotilt.discovery.benchmark import cell_summary, default_cells, read_record, run_benchmark

    sizes = {
        "null_runs": args.null_runs,
        "effect_runs": args.effect_runs,
        "collinear_runs": args.collinear_runs,
        "world_runs": args.world_runs,
    }
    cells = [
        cell
        for cell in default_cells(**{name: runs for name, runs in sizes.items() if runs is not None})
        if (not args.kind or cell.kind in args.kind) and (not args.base or cell.base in args.base)
    ]
    if not args.report_only:
        import dask
        from distributed import Client, LocalCluster

        print(f"bench-discovery: {cell_summary(cells)} runs -> {args.record}", flush=True)
        with ExitStack() as resources:
            if args.scheduler:
                try:
                    client = resources.enter_context(
                        connect_cluster(args.scheduler, _discovery_problem, "run discovery")
                    )
                except ClusterError as error:
                    print(f"bench-discovery: error: {error}", file=sys.stderr)
                    return 1
            else:
                # Dask's default MALLOC_TRIM_THRESHOLD_ also fixes glibc's mmap
                # threshold, so every large array of a replay is mapped afresh
                # and its pages faulted in: null runs took 1.4 times as long.
                resources.enter_context(
                    dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None})
                )
                cluster = resources.enter_context(
                    LocalCluster(n_workers=args.workers, threads_per_worker=1, dashboard_address="127.0.0.1:0")
                )
                client = resources.enter_context(Client(cluster))
            bar = resources.enter_context(tqdm(unit="run", file=sys.stderr, disable=None))

            def advance(done: int, total: int) -> None:
                if bar.total != total:
                    bar.reset(total)
                    bar.update(done)
                else:
                    bar.n = done
                    bar.refresh()

            try:
                progress = run_benchmark(
                    cells, args.record, args.bases, client, say=bar.write, bar=advance, base_record=args.base_record
                )
            except KeyboardInterrupt:
                print("\nbench-discovery: stopped; the finished runs are in the record", file=sys.stderr)
                return 130
        for failure in progress.failed:
            print(f"bench-discovery: run failed: {failure}", file=sys.stderr)
    rows = read_record(args.record)
    text = (
        rates.report(rows, read_base_seconds(args.base_record))
        + "\nSpeed: `make bench` times `discover` end to end on 100 000 rows (docs/performance.md).\n"
    )
    try:
        generated_page.write_block(args.document, rates.BEGIN, rates.END, text)
    except ValueError as error:
        print(f"bench-discovery: error: {error}", file=sys.stderr)
        return 1
    rates.figure(rows, args.figure)
    print(text)
    print(f"bench-discovery: wrote {args.document} and {args.figure}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
