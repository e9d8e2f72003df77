"""Whether a sensor's certificate bounds what a monitoring user reads in
the field, over many field runs, each an independent task on a Dask
cluster (``make bench-field``; docs/benchmarks/field-accuracy.md).

Sensors drawn from the batch population are calibrated through one twin
campaign (``field_calibration``). Each field run is one sensor at one tilt
about X through one field profile, replayed on the host as the twin would
run it (``field_replay``: the sensor model and the firmware's processing
with that sensor's fitted coefficients), and read as ``thermotilt
validate`` reads a run against a certificate: the change of tilt from the
installation reading (``tilt_change``), each row held against the
certificate's U for it (``certificate.u95_at``), the rows
outside its domain (``certificate.in_domain``) left out.

The record (docs/benchmarks/field-runs.csv) is resumable, as discovery's
is: a row is written as its run finishes, a run whose key is in the record
with the current method is not run again, and a run's seed comes from its
key alone (``Task.seed``).
"""

from __future__ import annotations

import csv
import functools
import time
import uuid
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import stats

from ..lsm9ds0 import LSB_PER_G
from .field_calibration import BaseCampaign, BaseDesign, SensorCalibration, calibrate_sensor, ensure_base, sensor_model
from .field_replay import FIELD_PROFILES, field_inputs, field_scenario, printed, replay_frames

if TYPE_CHECKING:
    from distributed import Client

TILTS_DEG = (0.0, 20.0, 40.0)
DEFAULT_SENSORS = 10
FIT_AXES = ("X", "Y")
DOMAIN = "the certificate's domain"
YES, NO = "yes", "no"
COLUMNS = (
    "key",
    "sensor",
    "profile",
    "tilt_deg",
    "index",
    "seed",
    "p95_change_deg",
    "u95_deg",
    "within",
    "max_change_deg",
    "rows_within_share",
    "slope_u95_deg",
    "rows_within_slope_share",
    "p95_x_deg",
    "p95_y_deg",
    "u95_x_deg",
    "u95_y_deg",
    "rows",
    "outside_rows",
    "imu_min_c",
    "imu_max_c",
    "set_changes",
    "certificate_u95_deg",
    "seconds",
    "base",
    "method",
)
# The Python a run's outcome depends on; with the default model as loaded and
# what the native library computes (method_digest), a change makes every
# row stale. The base campaign's own digest is each row's "base".
METHOD_SOURCES = (
    "calibration/field_bench.py",
    "calibration/field_calibration.py",
    "calibration/field_replay.py",
    "calibration/dataset.py",
    "calibration/fit.py",
    "calibration/newey_west.py",
    "calibration/tilt_change.py",
    "calibration/certificate",
    "calibration/surface_change.py",
    "physics/sensor.py",
    "physics/batch.py",
    "physics/model.py",
    "physics/document.py",
    "physics/parameters.py",
    "physics/terms",
    "twin/scenarios.py",
    "twin/weather.py",
    "run/log.py",
    "run/positions.py",
    "lsm9ds0.py",
    "surfaces.py",
    "set_blend.py",
    "program.py",
)


@dataclass(frozen=True)
class Design:
    """The benchmark's runs: each sensor of the batch through each profile
    at each tilt about X, `runs` times with independent seeds."""

    sensors: int = DEFAULT_SENSORS
    profiles: tuple[str, ...] = FIELD_PROFILES
    tilts_deg: tuple[float, ...] = TILTS_DEG
    runs: int = 1
    base: BaseDesign = BaseDesign()
    # A profile's length, s (None: the scenario's own: 3 h, 9 h, 12 h, 2 days).
    duration_s: float | None = None

    @property
    def sensor_ids(self) -> tuple[str, ...]:
        return tuple(f"TT-{number:02d}" for number in range(1, self.sensors + 1))

    def tasks(self) -> list[Task]:
        return [
            Task(sensor, profile, tilt, index)
            for index in range(self.runs)
            for sensor in self.sensor_ids
            for profile in self.profiles
            for tilt in self.tilts_deg
        ]


@dataclass(frozen=True)
class Task:
    sensor: str
    profile: str
    tilt_deg: float
    index: int

    @property
    def key(self) -> str:
        return f"{self.sensor}/{self.profile}/{self.tilt_deg:g}/{self.index}"

    @property
    def seed(self) -> int:
        """The sensor's noise seed (and field-days' weather), from the key alone."""
        return zlib.crc32(self.key.encode())


@dataclass(frozen=True)
class Reading:
    """A field run as a monitoring user reads it against the certificate."""

    p95_change_deg: float | None  # X and Y pooled, in-domain rows (tilt_change)
    # The largest U over the run's in-domain rows from the installation on, either axis.
    u95_deg: float | None
    rows_within_share: float | None  # X and Y pooled, each row against its own U
    # The same against the drift-slope reference (slope_reference_u95), where the model has one.
    slope_u95_deg: float | None
    rows_within_slope_share: float | None
    max_change_deg: float | None  # the largest change of an in-domain row, either axis
    p95_deg: dict[str, float | None]  # per axis
    u95_axis_deg: dict[str, float | None]  # per axis, the same
    rows: int  # in-domain rows, X and Y counted apart
    outside_rows: int
    temperature_c: tuple[float, float]
    set_changes: int  # the device's changes of set over the run

    @property
    def within(self) -> bool | None:
        if self.p95_change_deg is None or self.u95_deg is None:
            return None
        return self.p95_change_deg <= self.u95_deg


def slope_reference_u95(
    sigma_lsb_per_c: dict[str, float], temperature_c: np.ndarray, compensated_lsb: dict[str, np.ndarray]
) -> Callable[[float], dict[str, np.ndarray]]:
    """A yardstick for the certificate's U, as ``change_u95`` gives it: the
    U a lab would state for a change if it knew the model's mounting-to-
    mounting drift-slope scatter exactly and nothing else. A new mounting's
    error is delta (T - 25 degC) with delta ~ N(0, sigma) per axis
    (``drift_repeatability``), so a change from an installation at T0 carries
    delta (T - T0): U = z(97.5 %) sigma |T - T0| |d tilt / d a|. It leaves out
    noise, flicker and the set switch, so it is not a bound; the certificate's
    U over it says how much of U the mounting scatter accounts for."""
    z = float(stats.norm.ppf(0.975))
    degrees_per_lsb = {
        axis: np.degrees(1.0 / np.sqrt(np.maximum(LSB_PER_G**2 - values.astype(float) ** 2, 1.0)))
        for axis, values in compensated_lsb.items()
    }

    def at_installation(installation_c: float) -> dict[str, np.ndarray]:
        excursion = np.abs(temperature_c - installation_c)
        return {axis: z * sigma_lsb_per_c[axis.lower()] * excursion * degrees_per_lsb[axis] for axis in compensated_lsb}

    return at_installation


def read_field_run(
    time_s: np.ndarray, frames: dict[str, np.ndarray], certificate: dict, slope_sigma: dict[str, float] | None = None
) -> Reading:
    """The run's frames (as printed) read as `validate` reads a run against a
    certificate: the change from the installation reading over the rows
    inside the certificate's domain, each held against the U for its change;
    with slope_sigma (LSB/degC by axis), also against slope_reference_u95."""
    from .certificate import change_u95, in_domain
    from .tilt_change import tilt_change

    temperature = frames["temp_c"]
    compensated = {"X": frames["ax_comp"], "Y": frames["ay_comp"]}
    inside = {axis: in_domain(certificate, axis, temperature, compensated[axis]) for axis in FIT_AXES}
    outside = {axis: ~inside[axis] for axis in FIT_AXES}
    change = tilt_change(
        time_s, temperature, compensated, outside, None, change_u95(certificate, temperature, compensated), DOMAIN
    )
    axes = {axis.axis: axis for axis in change.axes} if change is not None else {}
    largest = {axis: axes[axis].u95_max_deg if axes else None for axis in FIT_AXES}
    known = [value for value in largest.values() if value is not None]
    slope = None
    if change is not None and slope_sigma is not None:
        yardstick = slope_reference_u95(slope_sigma, temperature, compensated)
        slope = tilt_change(time_s, temperature, compensated, outside, None, yardstick, DOMAIN)
    slope_largest = [axis.u95_max_deg for axis in slope.axes if axis.u95_max_deg is not None] if slope else []
    return Reading(
        p95_change_deg=change.p95_deg if change is not None else None,
        u95_deg=max(known) if known else None,
        rows_within_share=change.within_u_share if change is not None else None,
        slope_u95_deg=max(slope_largest, default=None),
        rows_within_slope_share=slope.within_u_share if slope is not None else None,
        max_change_deg=max((a.max_deg for a in axes.values() if a.max_deg is not None), default=None),
        p95_deg={axis: axes[axis].p95_deg if axes else None for axis in FIT_AXES},
        u95_axis_deg=largest,
        rows=sum(int(np.count_nonzero(mask)) for mask in inside.values()),
        outside_rows=sum(int(np.count_nonzero(mask)) for mask in outside.values()),
        temperature_c=(float(np.min(temperature)), float(np.max(temperature))),
        set_changes=int(np.count_nonzero(np.diff(frames["set"].astype(int)))),
    )


@functools.cache
def _sensor_model(sensors: int, seed: int, sensor_id: str) -> Any:
    return sensor_model(sensors, seed, sensor_id)


def run_field(task: Task, calibration: SensorCalibration, design: Design) -> dict[str, Any]:
    """One field run: the sensor through the profile at the tilt, replayed
    with its fitted coefficients, read against its certificate; the row."""
    started = time.perf_counter()
    model = _sensor_model(design.sensors, design.base.seed, task.sensor)
    inputs = field_inputs(field_scenario(task.profile, task.tilt_deg, task.seed, design.duration_s))
    frames = replay_frames(model, task.seed, inputs, calibration.coefficients)
    shown = {**printed(frames), "set": frames["set"]}
    sigma = model.terms["drift_repeatability"]["sigma_lsb_per_c"] if model.enabled("drift_repeatability") else None
    reading = read_field_run(inputs.time_s, shown, calibration.certificate, sigma)
    return record_row(task, reading, calibration, time.perf_counter() - started)


def _number(value: float | None, form: str = ".6g") -> str:
    return "" if value is None else format(value, form)


def record_row(task: Task, reading: Reading, calibration: SensorCalibration, seconds: float) -> dict[str, Any]:
    within = reading.within
    return {
        "key": task.key,
        "sensor": task.sensor,
        "profile": task.profile,
        "tilt_deg": f"{task.tilt_deg:g}",
        "index": task.index,
        "seed": task.seed,
        "p95_change_deg": _number(reading.p95_change_deg),
        "u95_deg": _number(reading.u95_deg),
        "within": "" if within is None else YES if within else NO,
        "max_change_deg": _number(reading.max_change_deg),
        "rows_within_share": _number(reading.rows_within_share),
        "slope_u95_deg": _number(reading.slope_u95_deg),
        "rows_within_slope_share": _number(reading.rows_within_slope_share),
        "p95_x_deg": _number(reading.p95_deg["X"]),
        "p95_y_deg": _number(reading.p95_deg["Y"]),
        "u95_x_deg": _number(reading.u95_axis_deg["X"]),
        "u95_y_deg": _number(reading.u95_axis_deg["Y"]),
        "rows": reading.rows,
        "outside_rows": reading.outside_rows,
        "imu_min_c": _number(reading.temperature_c[0], ".2f"),
        "imu_max_c": _number(reading.temperature_c[1], ".2f"),
        "set_changes": reading.set_changes,
        "certificate_u95_deg": _number(calibration.certificate.get("tilt_u95_deg")),
        "seconds": f"{seconds:.1f}",
        "base": "",
        "method": method_digest(),
    }


@functools.cache
def method_digest() -> str:
    """A digest of what a run's outcome depends on: the Python sources
    (METHOD_SOURCES) as this process first read them, the default model as
    loaded, and the firmware's processing (native) on a fixed input with
    coefficients, both sets in turn, so that a change of the firmware's
    compensation counts and one that computes the same does not."""
    from .. import native
    from ..record import sources_digest

    digest = sources_digest(METHOD_SOURCES)
    rng = np.random.default_rng(0)
    samples = 6000
    temperature_c = 25.0 + 15.0 * np.sin(np.linspace(0.0, 3.0 * np.pi, samples))
    axes = [np.rint(level + 20.0 * rng.standard_normal(samples)) for level in (8000.0, -3000.0, 14000.0)]
    coefficients = np.linspace(-1.0, 1.0, native.COEFFICIENT_COUNT) * np.tile([50.0, 2.0, 1e-3, 0.05, 1e-4, 1e-7], 6)
    processed = native.imu_process(*axes, np.rint((temperature_c - 21.0) * 8.0), coefficients=coefficients)
    for name in native.OUTPUTS:
        digest.update(np.ascontiguousarray(processed[name]).tobytes())
    return digest.hexdigest()


def read_record(path: Path) -> list[dict[str, str]]:
    if not path.exists():
        return []
    with open(path, newline="", encoding="utf-8") as stream:
        return list(csv.DictReader(stream))


def write_record(path: Path, rows: list[dict[str, Any]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)


def _append(path: Path, row: dict[str, Any]) -> None:
    new = not path.exists() or path.stat().st_size == 0
    with open(path, "a", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, COLUMNS, lineterminator="\n")
        if new:
            writer.writeheader()
        writer.writerow(row)


def sort_record(path: Path, design: Design) -> None:
    """The record in the design's order whatever order the runs finished
    in, so that a rerun diffs row by row; rows of other designs after."""

    def order(row: dict[str, str]) -> tuple:
        profile = design.profiles.index(row["profile"]) if row["profile"] in design.profiles else len(design.profiles)
        return row["sensor"], profile, float(row["tilt_deg"]), int(row["index"])

    write_record(path, sorted(read_record(path), key=order))


# Longer runs first (Dask runs higher priorities first), so that the last
# minutes are not one worker's field-days run; each sensor's calibration
# before the runs that need it.
RUN_PRIORITY = {"field-days": 3, "field-alternating": 2, "field-cooling": 1, "field-warming": 0}
CALIBRATION_PRIORITY = 10
BASE_FOLDER = "base"
CALIBRATIONS_FOLDER = "calibrations"


@dataclass
class Progress:
    done: int
    todo: int
    failed: list[str]


def _current(record: Path, keep: Callable[[dict[str, str]], bool], why: str, say: Callable[[str], None]) -> set[str]:
    """The keys of the record's rows that keep() keeps; the others are
    dropped from the record (they run again), said with why."""
    rows = read_record(record)
    kept = [row for row in rows if keep(row)]
    if len(kept) < len(rows):
        say(f"{len(rows) - len(kept)} rows of the record were made {why}: they run again")
        write_record(record, kept)
    return {row["key"] for row in kept}


def run_bench(
    design: Design,
    record: Path,
    folder: Path,
    client: Client,
    jobs: int = 1,
    say: Callable[[str], None] = print,
    bar: Callable[[int, int], Any] | None = None,
) -> Progress:
    """Every run of the design not yet in the record, on the client's
    cluster, each row appended as it comes; the base campaign and the
    sensors' calibrations kept in folder (the base made with `jobs`
    processes where missing). A run that raises is reported and left out of
    the record, to be tried on the next start. bar(done, total) is told
    after every run."""
    method = method_digest()
    tasks = design.tasks()
    done = _current(record, lambda row: row.get("method") == method, "by other sources", say)
    todo = [task for task in tasks if task.key not in done]
    base_folder = folder / BASE_FOLDER
    base = None
    if todo or base_folder.exists():
        base = ensure_base(base_folder, design.base, jobs, say)
        done = _current(record, lambda row: row.get("base") == base.digest, "on another base campaign", say)
        todo = [task for task in tasks if task.key not in done]
    progress = Progress(len(tasks) - len(todo), len(todo), [])
    if todo:
        cache = folder / CALIBRATIONS_FOLDER / f"{method}-{base.digest}"
        _Session(design, base, client, record, cache).run(todo, progress, say, bar, len(tasks))
    if record.exists():
        sort_record(record, design)
    return progress


@dataclass
class _Session:
    """One start's runs on the cluster: the base shipped to every worker
    once, each sensor's calibration read from the cache or made there (and
    cached as it comes back), each run after its sensor's calibration."""

    design: Design
    base: BaseCampaign
    client: Client
    record: Path
    cache: Path

    def calibrations(self, sensors: list[str], start: str) -> dict[str, Any]:
        """Per sensor its calibration, or a future of it."""
        shipped = None
        calibrations: dict[str, Any] = {}
        for sensor in sensors:
            cached = self.cache / f"{sensor}.json"
            if cached.exists():
                calibrations[sensor] = SensorCalibration.from_json(cached.read_text(encoding="utf-8"))
                continue
            if shipped is None:
                # Keys of this start's own (hash=False): a key an earlier start
                # released may still be being forgotten by the scheduler.
                shipped = self.client.scatter(self.base, broadcast=True, hash=False)
            calibrations[sensor] = self.client.submit(
                calibrate_sensor,
                sensor,
                self.design.sensors,
                shipped,
                key=f"field-calibrate-{sensor}-{start}",
                priority=CALIBRATION_PRIORITY,
                pure=False,
            )
        return calibrations

    def run(
        self,
        todo: list[Task],
        progress: Progress,
        say: Callable[[str], None],
        bar: Callable[[int, int], Any] | None,
        total: int,
    ) -> None:
        from distributed import Future, as_completed

        start = uuid.uuid4().hex
        calibrations = self.calibrations(sorted({task.sensor for task in todo}), start)
        made = {future: sensor for sensor, future in calibrations.items() if isinstance(future, Future)}
        futures = {
            self.client.submit(
                run_field,
                task,
                calibrations[task.sensor],
                self.design,
                key=f"field-{task.key}-{start}",
                priority=RUN_PRIORITY.get(task.profile, 0),
                pure=False,
            ): task
            for task in todo
        }
        self.record.parent.mkdir(parents=True, exist_ok=True)
        try:
            for future in as_completed([*made, *futures], loop=self.client.loop):
                if future in made:
                    self._keep(made.pop(future), future, say)
                    continue
                task = futures.pop(future)
                try:
                    _append(self.record, {**future.result(), "base": self.base.digest})
                except Exception as error:  # a run's failure is its row's, not the benchmark's
                    progress.failed.append(f"{task.key}: {type(error).__name__}: {error}")
                progress.todo -= 1
                progress.done += 1
                if bar is not None:
                    bar(progress.done, total)
        finally:
            self.client.cancel([*made, *futures])

    def _keep(self, sensor: str, future: Any, say: Callable[[str], None]) -> None:
        """A sensor's calibration as it comes back, into the cache."""
        try:
            calibration = future.result()
        except Exception as error:  # its runs fail with it, each said
            say(f"sensor {sensor} could not be calibrated: {type(error).__name__}: {error}")
            return
        self.cache.mkdir(parents=True, exist_ok=True)
        (self.cache / f"{sensor}.json").write_text(calibration.to_json(), encoding="utf-8")
        from .certificate.budget import two_significant_text

        largest = calibration.certificate.get("tilt_u95_deg")
        say(
            f"sensor {sensor} calibrated: U = {'n/a' if largest is None else two_significant_text(largest)} deg at most"
        )
