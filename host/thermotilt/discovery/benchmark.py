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
import subprocess
import sys
import tempfile
import time
import uuid
import zlib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..run.folder import RunFolder
from .candidates import BY_NAME, CANDIDATES
from .noise_families import NOISE_FAMILIES
from .replay import CHAMBER_CHANNELS

if TYPE_CHECKING:
    from distributed import Client

SNRS = (0.5, 1.0, 2.0, 4.0)
NULL, EFFECT, COLLINEAR = "null", "effect", "collinear"
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
    "discovery/benchmark.py",
    "discovery/candidates.py",
    "discovery/chamber_readings.py",
    "discovery/channel.py",
    "discovery/hide.py",
    "discovery/noise_families.py",
    "discovery/nonlinear.py",
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
class Base:
    """A run the benchmark hides effects in: `make(folder)` writes it (a run
    folder with run.csv) on the machine that submits the runs."""

    name: str
    what: str
    make: Callable[[Path], None]


def _staircase(folder: Path) -> None:
    from .hide import staircase_inputs

    staircase_inputs(RunFolder.at(folder).log)


def _wave(folder: Path) -> None:
    from .hide import wave_inputs

    wave_inputs(RunFolder.at(folder).log)


def _twin(scenario: str, *options: str) -> Callable[[Path], None]:
    def make(folder: Path) -> None:
        subprocess.run(
            [sys.executable, "-m", "thermotilt", "simulate", scenario, *options, "--out", str(folder)],
            check=True,
            stdout=subprocess.DEVNULL,
        )

    return make


# The scatter terms off in the twin's own runs: hide_effect generates the
# sensor side again with the family's noise.
_SCATTER_OFF = ("--disable", "drift_repeatability", "--disable", "bias_instability")
BASES = {
    base.name: base
    for base in (
        Base(
            "staircase", "0..40 degC in 5 degC steps held 40 s at X +30, X -30 and Y +30 deg (inputs only)", _staircase
        ),
        Base("wave", "a temperature wave 15..35 degC, period 2000 s, 1.5 periods at X +30 deg (inputs only)", _wave),
        Base(
            "cycle",
            "the twin's calibration cycle, -10..45 degC (simulate cycle --rest-seconds 60)",
            _twin("cycle", "--rest-seconds", "60", *_SCATTER_OFF),
        ),
        Base("fig8", "the twin's Figure 8 run, 342 s (simulate fig8)", _twin("fig8", *_SCATTER_OFF)),
    )
}


@dataclass(frozen=True)
class Cell:
    """Runs alike but for their seed. effect: a candidate, or "none";
    channel: the channel it is sized on, or None for one drawn per run;
    pair: for a collinear cell, the candidates that run cannot tell apart."""

    kind: str
    effect: str
    snr: float | None
    noise: str
    base: str
    runs: int
    channel: str | None = None
    pair: tuple[str, ...] = ()

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
    def seed(self) -> int:
        return zlib.crc32(self.key.encode())


# 100 per family and base: a family's 200 null runs show a rate of 1 %
# below 5 % at 95 % (Wilson: 3/200 has 4.3 % as its upper bound), where 80
# could not show it with a single false discovery (1/80: 6.8 %).
NULL_RUNS = 100


def default_cells(null_runs: int = NULL_RUNS, effect_runs: int = 50, collinear_runs: int = 50) -> list[Cell]:
    """The benchmark's design: null runs in every noise family on a sensor
    run and a chamber run; every candidate at every SNR with the model's
    noise, on the staircase (sensor) or the twin's cycle (chamber); the two
    designed collinear pairs."""
    cells = [
        Cell(NULL, "none", None, noise, base, null_runs) for base in ("staircase", "cycle") for noise in NOISE_FAMILIES
    ]
    for candidate in CANDIDATES:
        base = "cycle" if set(candidate.channels) <= set(CHAMBER_CHANNELS) else "staircase"
        cells += [Cell(EFFECT, candidate.name, snr, "model", base, effect_runs) for snr in SNRS]
    cells += [
        Cell(COLLINEAR, "sensor_lag", 4.0, "model", "wave", collinear_runs, pair=("rate_sensitivity", "sensor_lag")),
        Cell(
            COLLINEAR,
            "temperature_offset",
            4.0,
            "model",
            "fig8",
            collinear_runs,
            pair=("temperature_offset", "thermistor_offset"),
        ),
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
        "base": cell.base,
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
    kinds = (NULL, EFFECT, COLLINEAR)

    def order(row: dict[str, str]) -> tuple:
        snr = float(row["snr"]) if row["snr"] else 0.0
        return kinds.index(row["kind"]), row["effect"], snr, row["noise"], row["base"], int(row["index"])

    write_record(path, sorted(read_record(path), key=order))


def make_bases(
    names: Iterable[str], folder: Path, say: Callable[[str], None], bases: Mapping[str, Base] = BASES
) -> dict[str, bytes]:
    """Each base's run.csv, made once into folder/NAME and read from there
    after."""
    made = {}
    for name in names:
        target = folder / name
        if not RunFolder.at(target).log.exists():
            say(f"making the base run {name}: {bases[name].what}")
            target.mkdir(parents=True, exist_ok=True)
            bases[name].make(target)
        made[name] = RunFolder.at(target).log.read_bytes()
    return made


@dataclass
class Progress:
    done: int
    todo: int
    failed: list[str]


def run_benchmark(
    cells: list[Cell],
    record: Path,
    bases_folder: Path,
    client: Client,
    say: Callable[[str], None] = print,
    bar: Callable[[int, int], Any] | None = None,
    bases: Mapping[str, Base] = BASES,
) -> Progress:
    """Every run of the cells not yet in the record, on the client's
    cluster; each finished row appended at once. A run that raises is
    reported and left out of the record, to be tried on the next start.
    bar(done, total) is told after every run."""
    from distributed import as_completed

    tasks = [task for cell in cells for task in cell.tasks()]
    method = method_digest()
    rows = read_record(record)
    if any(row.get("method") != method for row in rows):
        stale = sum(row.get("method") != method for row in rows)
        say(f"{stale} rows of the record were made by other sources of discovery: they run again")
        write_record(record, [row for row in rows if row.get("method") == method])
    done = {row["key"] for row in rows if row.get("method") == method}
    # Index by index across the cells, so that a benchmark stopped early
    # leaves every cell about as many runs.
    todo = sorted((task for task in tasks if task.key not in done), key=lambda task: task.index)
    progress = Progress(len(tasks) - len(todo), len(todo), [])
    if todo:
        made = make_bases(sorted({task.cell.base for task in todo}), bases_folder, say, bases)
        # Keys of this start's own (hash=False, the uuid): a key an earlier
        # start released may still be being forgotten by the scheduler, which
        # then loses the data a new task of the same key needs.
        shipped = {name: client.scatter(data, broadcast=True, hash=False) for name, data in made.items()}
        start = uuid.uuid4().hex
        record.parent.mkdir(parents=True, exist_ok=True)
        futures = {
            client.submit(run_task, task, shipped[task.cell.base], key=f"bench-{task.key}-{start}", pure=False): task
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
