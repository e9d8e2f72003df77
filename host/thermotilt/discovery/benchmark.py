"""Discovery's error rates measured over many runs, each an independent
task on a Dask cluster: hide an effect (or nothing) in a base run with
`hide_effect`, run `Search` on it, and record what it said beside the truth,
one row per run (docs/discovery.md, "Benchmark"; `make bench-discovery`).

The record is resumable: a row is written and flushed as its run finishes,
and a run whose key is in the record is never run again. Every run's seed
comes from its cell and index alone, so any row can be made again by
itself (`Task.seed`).
"""

from __future__ import annotations

import csv
import functools
import hashlib
import tempfile
import time
import tomllib
import uuid
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..run.folder import RunFolder
from .bases import BASES, Base, base_recorder, make_bases
from .candidates import BY_NAME, CANDIDATES
from .replay import CHAMBER_CHANNELS

if TYPE_CHECKING:
    from distributed import Client

NULL, EFFECT, COLLINEAR, WORLD = "null", "effect", "collinear", "world"
KINDS = (NULL, EFFECT, COLLINEAR, WORLD)
FOUND, NONE, AMBIGUOUS, NOT_TESTABLE, UNEXPLAINED = "found", "none", "ambiguous", "not_testable", "unexplained"
COLUMNS = (
    "key",
    "kind",
    "effect",
    "channel",
    "snr",
    "noise",
    "base",
    "index",
    "seed",
    "verdict",
    "named",
    "named_channel",
    "value",
    "low",
    "high",
    "truth",
    "ambiguous",
    "fit",
    "expected_pair",
    "snr_actual",
    "rows",
    "seconds",
    "method",
)
# The Python a run's outcome depends on (not the report, the rates or the
# command line; the model file's parser and the native library by what they
# give, method_digest): a change to any of these makes every row of the
# record stale, as does a change in the default model or in what the native
# library computes.
METHOD_SOURCES = (
    "discovery/bases.py",
    "discovery/benchmark.py",
    "discovery/candidates.py",
    "discovery/chamber_floor.py",
    "discovery/chamber_floor.toml",
    "discovery/chamber_readings.py",
    "discovery/channel.py",
    "discovery/hide.py",
    "discovery/noise_families.py",
    "discovery/nonlinear.py",
    "discovery/reml.py",
    "discovery/replay.py",
    "discovery/search.py",
    "physics/sensor.py",
    "physics/chamber.py",
    "physics/document.py",
    "physics/parameters.py",
    "physics/terms",
    "run/__init__.py",
    "run/folder.py",
    "run/log.py",
    "run/positions.py",
    "surfaces.py",
)


@dataclass(frozen=True)
class Cell:
    """Runs alike but for their seed and base. effect: a candidate, or
    "none"; base: the bases' kind, run i on its base i mod `bases` (or on the
    base of that name when `bases` is 1); channel: the channel it is sized
    on, or None for one drawn per run; pair: for a collinear cell, the
    candidates that run cannot tell apart; since, note: when the design took
    the cell in and why, or what replaced it."""

    kind: str
    effect: str
    snr: float | None
    noise: str
    base: str
    runs: int
    channel: str | None = None
    pair: tuple[str, ...] = ()
    bases: int = 1
    since: str = ""
    note: str = ""

    def tasks(self) -> list[Task]:
        return [Task(self, index) for index in range(self.runs)]


@dataclass(frozen=True)
class Task:
    cell: Cell
    index: int

    @property
    def key(self) -> str:
        c = self.cell
        snr = "" if c.snr is None else f"{c.snr:g}"
        return f"{c.kind}/{c.effect}/{c.channel or ''}/{snr}/{c.noise}/{c.base}/{self.index}"

    @property
    def base(self) -> str:
        c = self.cell
        return c.base if c.bases == 1 else f"{c.base}-{self.index % c.bases:02d}"

    @property
    def seed(self) -> int:
        return zlib.crc32(self.key.encode())


DESIGN = Path(__file__).with_name("benchmark_design.toml")


@functools.cache
def _design() -> dict[str, Any]:
    with open(DESIGN, "rb") as stream:
        return tomllib.load(stream)


SNRS = tuple(float(snr) for snr in _design()["effect"]["snr"])


def default_cells(
    null_runs: int | None = None,
    effect_runs: int | None = None,
    collinear_runs: int | None = None,
    world_runs: int | None = None,
) -> list[Cell]:
    """The benchmark's design as DESIGN states it (the sizes may be asked
    smaller): null runs in every noise family on the sensor's and the
    chamber's bases; every candidate at every SNR with the model's noise, on
    the staircases (sensor) or the twin's cycles (chamber); the collinear
    pairs; worlds the model does not describe, with nothing hidden; each
    cell with the date the design took it in."""
    design = _design()
    runs = design["runs"]
    bases = int(runs["bases"])
    null_runs = int(runs["null"]) if null_runs is None else null_runs
    effect_runs = int(runs["effect"]) if effect_runs is None else effect_runs
    collinear_runs = int(runs["collinear"]) if collinear_runs is None else collinear_runs
    world_runs = int(runs["world"]) if world_runs is None else world_runs
    cells = [
        Cell(NULL, "none", None, noise, kind, null_runs, bases=bases, since=group["since"], note=group["why"])
        for group in design["null"]
        for kind in group["bases"]
        for noise in group["noise"]
    ]
    effect = design["effect"]
    for candidate in CANDIDATES:
        kind = effect["chamber_base"] if set(candidate.channels) <= set(CHAMBER_CHANNELS) else effect["sensor_base"]
        cells += [
            Cell(EFFECT, candidate.name, float(snr), "model", kind, effect_runs, bases=bases, since=effect["since"])
            for snr in effect["snr"]
        ]
    cells += [
        Cell(
            COLLINEAR,
            pair["effect"],
            float(pair["snr"]),
            "model",
            pair["base"],
            collinear_runs,
            channel=pair.get("channel"),
            pair=tuple(pair["pair"]),
            bases=bases,
            since=pair["since"],
            note=pair["why"],
        )
        for pair in design["collinear"]
    ]
    cells += [
        Cell(
            WORLD,
            "none",
            None,
            "model",
            world["base"],
            world_runs,
            bases=bases,
            since=world["since"],
            note=world["why"],
        )
        for world in design["world"]
    ]
    return cells


_BASE_FOLDERS: dict[str, Path] = {}


def _base_folder(data: bytes) -> Path:
    """The base's run.csv in a folder of this process, written once."""
    digest = hashlib.sha256(data).hexdigest()[:16]
    if digest not in _BASE_FOLDERS:
        folder = Path(tempfile.mkdtemp(prefix=f"thermotilt-base-{digest}-"))
        RunFolder.at(folder).log.write_bytes(data)
        _BASE_FOLDERS[digest] = folder
    return _BASE_FOLDERS[digest]


def run_task(task: Task, base_csv: bytes) -> dict[str, Any]:
    """One run: the effect hidden in the base, discovery on it, the row."""
    from ..physics import Model
    from .hide import hide_effect
    from .replay import load_measured
    from .search import Search

    cell = task.cell
    started = time.perf_counter()
    model = Model.load()
    with tempfile.TemporaryDirectory(prefix="thermotilt-bench-") as scratch:
        run = Path(scratch)
        truth = hide_effect(
            _base_folder(base_csv),
            run,
            cell.effect,
            task.seed,
            snr=cell.snr,
            channel=cell.channel,
            noise=cell.noise,
            model=model,
        )
        measured = load_measured(run)
        outcome = Search(measured, model).run()
    verdict = outcome.verdict
    if truth.channel is not None:
        tested = [t for t in outcome.rounds[0] if t.key == (cell.effect, truth.channel)]
        if tested and not tested[0].testable:
            verdict = NOT_TESTABLE
    first = outcome.effects[0] if outcome.effects else None
    return {
        "key": task.key,
        "kind": cell.kind,
        "effect": cell.effect,
        "channel": truth.channel or "",
        "snr": "" if cell.snr is None else cell.snr,
        "noise": cell.noise,
        "base": task.base,
        "index": task.index,
        "seed": task.seed,
        "verdict": verdict,
        "named": first.candidate if first else "",
        "named_channel": first.channel if first else "",
        "value": _number(first.value) if first else "",
        "low": _number(first.interval[0]) if first else "",
        "high": _number(first.interval[1]) if first else "",
        "truth": "" if truth.value is None else _number(truth.value),
        "ambiguous": ";".join("+".join(group.names) for group in outcome.ambiguous),
        "fit": ";".join(f"{fit.channel}:{fit.gap:.4g}/{fit.allowed:.4g}" for fit in outcome.fit.values()),
        "expected_pair": "+".join(cell.pair),
        "snr_actual": "" if truth.snr is None else f"{truth.snr:.3f}",
        "rows": len(measured.time_s),
        "seconds": f"{time.perf_counter() - started:.1f}",
        "method": method_digest(),
    }


@functools.cache
def method_digest() -> str:
    """A digest of what a run's outcome depends on: the Python sources
    (METHOD_SOURCES) as this process first read them, the default model as
    loaded, and the native library's outputs on a fixed input, so that a
    change to the firmware's processing counts and a change that computes
    the same does not. Rows made by another method are stale and run again."""
    from .. import native
    from ..record import sources_digest

    digest = sources_digest(METHOD_SOURCES)
    rng = np.random.default_rng(0)
    samples = 6000
    ramp_c = 20.0 + 10.0 * np.sin(np.linspace(0.0, 3.0 * np.pi, samples))
    axes = [np.rint(level + 20.0 * rng.standard_normal(samples)) for level in (8000.0, -3000.0, 14000.0)]
    reset = np.zeros(samples, dtype=bool)
    reset[::1500] = True
    # Both paths the runs take: hide's registers, the replay's model values
    # channel by channel.
    processed = native.imu_process(*axes, np.rint((ramp_c - 21.0) * 8.0), reset)
    outputs = [processed[name] for name in native.OUTPUTS]
    outputs += [native.kalman_estimates(values, reset) for values in (*axes, ramp_c)]
    for values in outputs:
        digest.update(np.ascontiguousarray(values).tobytes())
    return digest.hexdigest()


def _number(value: float) -> str:
    return f"{value:.6g}"


def read_record(path: Path) -> list[dict[str, str]]:
    if not path.exists():
        return []
    with open(path, newline="", encoding="utf-8") as stream:
        return list(csv.DictReader(stream))


def _append(path: Path, row: dict[str, Any]) -> None:
    new = not path.exists() or path.stat().st_size == 0
    with open(path, "a", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, COLUMNS)
        if new:
            writer.writeheader()
        writer.writerow(row)


def write_record(path: Path, rows: list[dict[str, str]]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, COLUMNS)
        writer.writeheader()
        writer.writerows(rows)


def _sorted_record(path: Path) -> None:
    """The record in one order whatever order the runs finished in, so that
    a rerun diffs row by row."""

    def order(row: dict[str, str]) -> tuple:
        snr = float(row["snr"]) if row["snr"] else 0.0
        return KINDS.index(row["kind"]), row["effect"], snr, row["noise"], row["base"], int(row["index"])

    write_record(path, sorted(read_record(path), key=order))


@dataclass
class Progress:
    done: int
    todo: int
    failed: list[str]


def run_benchmark(  # noqa: PLR0913 - the cells, where rows and bases go, the cluster and what it reports to
    cells: list[Cell],
    record: Path,
    bases_folder: Path,
    client: Client,
    say: Callable[[str], None] = print,
    bar: Callable[[int, int], Any] | None = None,
    bases: Mapping[str, Base] = BASES,
    base_record: Path | None = None,
) -> Progress:
    """Every run of the cells not yet in the record, on the client's
    cluster; each finished row appended at once. A run that raises is
    reported and left out of the record, to be tried on the next start.
    bar(done, total) is told after every run; the seconds each base made
    here took are appended to base_record."""
    from distributed import as_completed

    tasks = [task for cell in cells for task in cell.tasks()]
    method = method_digest()
    rows = read_record(record)
    if any(row.get("method") != method for row in rows):
        stale = sum(row.get("method") != method for row in rows)
        say(f"{stale} rows of the record were made by other sources of discovery: they run again")
        write_record(record, [row for row in rows if row.get("method") == method])
    done = {row["key"] for row in rows if row.get("method") == method}
    # A round of indices at a time across the cells, so that a benchmark
    # stopped early leaves every cell about as many runs; within a round,
    # base by base, so that a worker's runs follow one another on a base
    # whose readings, cells and series it holds already (hide._Inputs,
    # SeriesMemo).
    todo = sorted(
        (task for task in tasks if task.key not in done),
        key=lambda task: (task.index // task.cell.bases, task.base, task.index),
    )
    progress = Progress(len(tasks) - len(todo), len(todo), [])
    if todo:
        made = make_bases(
            sorted({task.base for task in todo}),
            bases_folder,
            say,
            bases,
            made=None if base_record is None else base_recorder(base_record),
        )
        # Keys of this start's own (hash=False, the uuid): a key an earlier
        # start released may still be being forgotten by the scheduler, which
        # then loses the data a new task of the same key needs.
        shipped = {name: client.scatter(data, broadcast=True, hash=False) for name, data in made.items()}
        start = uuid.uuid4().hex
        record.parent.mkdir(parents=True, exist_ok=True)
        futures = {
            client.submit(run_task, task, shipped[task.base], key=f"bench-{task.key}-{start}", pure=False): task
            for task in todo
        }
        try:
            for future in as_completed(futures, loop=client.loop):
                task = futures.pop(future)
                try:
                    _append(record, future.result())
                except Exception as error:  # a run's failure is its row's, not the benchmark's
                    progress.failed.append(f"{task.key}: {type(error).__name__}: {error}")
                progress.todo -= 1
                progress.done += 1
                if bar is not None:
                    bar(progress.done, len(tasks))
        finally:
            client.cancel(list(futures))
    if record.exists():
        _sorted_record(record)
    return progress


def cell_summary(cells: list[Cell]) -> str:
    counts: dict[str, int] = {}
    for cell in cells:
        counts[cell.kind] = counts.get(cell.kind, 0) + cell.runs
    return ", ".join(f"{count} {kind}" for kind, count in counts.items())


def gap_ratio(row: dict[str, str]) -> float:
    """The largest gap of a run's channels in units of what the model's
    declared noise allows there (0 where none was tested)."""
    ratios = [0.0]
    for entry in filter(None, row["fit"].split(";")):
        gap, allowed = entry.split(":", 1)[1].split("/")
        ratios.append(float(gap) / float(allowed) if float(allowed) > 0 else np.inf)
    return max(ratios)


def named_right(row: dict[str, str]) -> bool:
    """The first effect found is the hidden one (on its channel, for a
    candidate with a value per axis or face)."""
    if row["verdict"] != FOUND or row["named"] != row["effect"]:
        return False
    return not BY_NAME[row["named"]].per_axis or row["named_channel"] == row["channel"]
