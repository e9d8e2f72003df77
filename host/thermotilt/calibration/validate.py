"""``thermotilt validate``: the paper's field check (section 4.3).

The paper's measure: the RMS, over a field run, of each axis's reading minus
its reading at 25 degC — before compensation (284 and 161 LSB for X and Y
while warming 9 -> 48 degC; 122 and 70 while cooling 26 -> 16 degC) and after
(11, 8; 4, 4). Here, per axis and per set the device chose (warming rows
with the warming surfaces, cooling rows with the cooling ones, as the paper
did), on the filtered acceleration the firmware compensates:

    before: ax_filt - ax_filt(25 degC)
    after:  ax_comp - ax_comp(25 degC)

The 25 degC reading is the set's straight line through its rows within
1.5 degC of 25 degC, read at 25 degC (the campaign fit's reference); a set
that never comes that near 25 degC has no reference and no RMS.

``after`` is the firmware's own output (``ax_comp``) unless coefficients
are given: then the run's filtered readings are compensated here with
those surfaces, which is the paper's post-processing of raw field data.

The coefficients cover a temperature and acceleration range (a fit's, or
the paper's -10..45 degC and +-45 deg); rows outside it are counted and
reported, because a surface is not known there. Coefficients the board
loaded from its EEPROM carry their own temperature range, which the host
does not know: then the board's flag on each row (``temp_domain``, the
IMU frame's) counts the rows outside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..lsm9ds0 import LSB_PER_G, MG_PER_LSB
from ..run.folder import RunFolder, RunFolderError
from ..run.log import RunLogError, read_run_columns
from ..surfaces import AXES, PAPER_DEFAULTS, REFERENCE_C, SETS, ZERO_SURFACE, CoefficientTable
from .compare import CALIBRATED_C, read_fit
from .dataset import FIT_AXES, REFERENCE_BAND_C, CalibrationDataError, reading_at_25

# The paper's calibration covered +-45 deg of tilt.
CALIBRATED_INCLINATION_DEG = 45.0
TILT_PERCENTILE = 95.0
PAPER_ACCELERATION_LSB = LSB_PER_G * math.sin(math.radians(CALIBRATED_INCLINATION_DEG))
SET_NAMES = {"W": "warming", "C": "cooling"}
# temp_domain (docs/protocol.md, IMU): inside or outside the block's range.
DOMAIN_FLAGS = ("I", "O")
OUTSIDE_FLAG = "O"
BOARD_DOMAIN = "the block the board loaded (run.csv's temp_domain)"
# A switch between the sets is measured as the change of the compensated
# reading from the median of the SWITCH_WINDOW_S before it to the median of
# the SWITCH_WINDOW_S after it, each SWITCH_GAP_S away from the switch
# (where the Kalman filter's ~10 s settle), with at least SWITCH_MIN_ROWS rows
# on each side and no other switch in between.
SWITCH_WINDOW_S = 60.0
SWITCH_GAP_S = 30.0
SWITCH_MIN_ROWS = 10
_NEEDED = (
    "time_s",
    "imu_temp_c",
    "comp_set",
    "coef_source",
    *(f"a{axis.lower()}_{kind}" for axis in FIT_AXES for kind in ("filt", "comp")),
)


@dataclass(frozen=True)
class Domain:
    """Where a set of surfaces was fitted, per key ("WX", ...)."""

    temperature_c: dict[str, tuple[float, float]]
    acceleration_lsb: dict[str, tuple[float, float]]
    source: str


@dataclass(frozen=True)
class Coefficients:
    table: CoefficientTable
    domain: Domain
    source: str  # what the user named: "paper" or the fit folder


@dataclass(frozen=True)
class AxisResult:
    set_name: str
    axis: str
    rows: int
    rms_before_lsb: float | None
    rms_after_lsb: float | None
    outside_rows: int  # rows outside the coefficients' temperature or acceleration range
    # The axis's tilt (tilt_deg) less its tilt at the 25 degC reading: the
    # TILT_PERCENTILE-th percentile of its size, before and after.
    tilt_error_p95_before_deg: float | None = None
    tilt_error_p95_after_deg: float | None = None


@dataclass(frozen=True)
class SetSwitch:
    """The device changed its set at time_s: the compensated reading's step
    there per axis (after minus before), in LSB and in degrees of tilt."""

    time_s: float
    to_set: str
    step_lsb: dict[str, float]
    step_deg: dict[str, float]


@dataclass(frozen=True)
class Validation:
    run: str
    rows: int
    skipped_rows: int
    temperature_range_c: tuple[float, float]
    after_from: str  # "firmware (coef_source ...)" or "host, with <coefficients>"
    sources: str  # the run's coef_source cells, e.g. "coef_source E"
    domain_source: str | None
    results: list[AxisResult] = field(default_factory=list)
    # With coefficients given: the largest difference between the host's
    # compensation and the firmware's own output on the same rows.
    firmware_difference_lsb: float | None = None
    # The rows behind the table, for figures: time_s, temperature_c, set, and
    # per axis "X before", "X after"...
    series: dict[str, np.ndarray] = field(default_factory=dict)
    switches: list[SetSwitch] = field(default_factory=list)

    def largest_switch_step(self, unit: str) -> dict[str, float] | None:
        """Per axis, the largest size of a switch's step ("lsb" or "deg"); None without a measured switch."""
        if not self.switches:
            return None
        return {
            axis: max(abs((s.step_lsb if unit == "lsb" else s.step_deg)[axis]) for s in self.switches)
            for axis in FIT_AXES
        }

    def result(self, set_name: str, axis: str) -> AxisResult | None:
        return next((r for r in self.results if (r.set_name, r.axis) == (set_name, axis)), None)

    @property
    def tilt_error_p95_deg(self) -> float | None:
        """The TILT_PERCENTILE-th percentile of the compensated tilt's error
        about the 25 degC reading, over every row of X and Y in either set."""
        errors = [
            self.series[f"{axis} tilt error after"] for axis in FIT_AXES if f"{axis} tilt error after" in self.series
        ]
        pooled = np.concatenate(errors) if errors else np.empty(0)
        pooled = pooled[np.isfinite(pooled)]
        return _percentile_of_size(pooled) if len(pooled) else None

    def document(self) -> dict[str, object]:
        """validation.json: the table in LSB, mg and degrees of tilt."""

        def mg(lsb: float | None) -> float | None:
            return None if lsb is None else lsb * MG_PER_LSB

        return {
            "run": self.run,
            "rows": self.rows,
            "skipped_rows": self.skipped_rows,
            "temperature_range_c": list(self.temperature_range_c),
            "after_from": self.after_from,
            "domain": self.domain_source,
            "tilt_error_p95_deg": self.tilt_error_p95_deg,
            "results": [
                {
                    "set": SET_NAMES[r.set_name],
                    "axis": r.axis,
                    "rows": r.rows,
                    "rms_before_lsb": r.rms_before_lsb,
                    "rms_after_lsb": r.rms_after_lsb,
                    "rms_before_mg": mg(r.rms_before_lsb),
                    "rms_after_mg": mg(r.rms_after_lsb),
                    "tilt_error_p95_before_deg": r.tilt_error_p95_before_deg,
                    "tilt_error_p95_after_deg": r.tilt_error_p95_after_deg,
                    "outside_rows": r.outside_rows,
                }
                for r in self.results
            ],
            "firmware_difference_lsb": self.firmware_difference_lsb,
            "set_switches": {
                "count": len(self.switches),
                "largest_step_lsb": self.largest_switch_step("lsb"),
                "largest_step_deg": self.largest_switch_step("deg"),
            },
        }


def paper_domain() -> Domain:
    keys = [f"{s}{a}" for s in SETS for a in FIT_AXES]
    return Domain(
        {key: CALIBRATED_C for key in keys},
        {key: (-PAPER_ACCELERATION_LSB, PAPER_ACCELERATION_LSB) for key in keys},
        "the paper's calibration (-10..45 degC, +-45 deg)",
    )


def load_coefficients(source: str) -> Coefficients:
    """``paper`` (Tables 2-3, the firmware's defaults) or a folder written by
    ``thermotilt fit``."""
    if source == "paper":
        return Coefficients(PAPER_DEFAULTS, paper_domain(), "paper")
    fits = read_fit(Path(source))
    surfaces = {(s, a): ZERO_SURFACE for s in SETS for a in AXES}
    surfaces.update({(key[0], key[1]): fit.surface for key, fit in fits.items()})
    domain = Domain(
        {key: fit.temperature_range_c for key, fit in fits.items()},
        {key: fit.acceleration_range_lsb for key, fit in fits.items()},
        f"the fit in {source}",
    )
    return Coefficients(CoefficientTable(surfaces), domain, source)


@dataclass(frozen=True)
class _Rows:
    """The run's rows that have a temperature, a set and every X/Y acceleration."""

    path: Path
    all_rows: int
    time_s: np.ndarray
    temperature: np.ndarray
    sets: np.ndarray
    filtered: dict[str, np.ndarray]
    firmware: dict[str, np.ndarray]
    sources: list[str]
    # The board's own word on each row's temperature (temp_domain): True outside.
    board_outside: np.ndarray | None

    @property
    def count(self) -> int:
        return len(self.time_s)


def _usable_rows(run: Path) -> _Rows:
    try:
        path = RunFolder.of(run).log
        log = read_run_columns(str(path))
    except (RunFolderError, RunLogError) as error:
        raise CalibrationDataError(str(error)) from None
    numbers, texts = log.numbers, log.texts
    usable = np.isin(texts["comp_set"], SETS) & (texts["coef_source"] != "")
    for column in _NEEDED:
        if column in numbers:
            usable &= np.isfinite(numbers[column])
    if not usable.any():
        raise CalibrationDataError(f"{path}: no row with a temperature, a set and every X/Y acceleration")
    flags = texts.get("temp_domain")
    board_flags = flags is not None and np.isin(flags[usable], DOMAIN_FLAGS).any()
    return _Rows(
        path,
        log.rows,
        numbers["time_s"][usable],
        numbers["imu_temp_c"][usable],
        texts["comp_set"][usable],
        {axis: numbers[f"a{axis.lower()}_filt"][usable] for axis in FIT_AXES},
        {axis: numbers[f"a{axis.lower()}_comp"][usable] for axis in FIT_AXES},
        sorted(set(texts["coef_source"][usable].tolist())),
        flags[usable] == OUTSIDE_FLAG if board_flags else None,
    )


def validate(run: Path, coefficients: Coefficients | None = None) -> Validation:
    rows = _usable_rows(run)
    board_outside = None
    if coefficients is None:
        after_from = f"the firmware's output (coef_source {'/'.join(rows.sources)})"
        domain = paper_domain() if rows.sources == ["D"] else None
        # Where the host knows no range for the coefficients the board ran.
        board_outside = rows.board_outside if domain is None else None
    else:
        after_from = f"compensated here with {coefficients.source}"
        domain = coefficients.domain
    series = {"time_s": rows.time_s, "temperature_c": rows.temperature, "set": rows.sets}
    results = [
        _axis_result(rows, set_name, axis, coefficients, domain, board_outside, series)
        for set_name in SETS
        if (rows.sets == set_name).any()
        for axis in FIT_AXES
    ]
    difference = None
    if coefficients is not None:
        difference = max(float(np.nanmax(np.abs(series[f"{axis} after"] - rows.firmware[axis]))) for axis in FIT_AXES)
    return Validation(
        str(rows.path),
        rows.count,
        rows.all_rows - rows.count,
        (float(rows.temperature.min()), float(rows.temperature.max())),
        after_from,
        f"coef_source {'/'.join(rows.sources)}",
        domain.source if domain else BOARD_DOMAIN if board_outside is not None else None,
        results,
        difference,
        series,
        set_switches(rows.time_s, rows.sets, {axis: series[f"{axis} after"] for axis in FIT_AXES}),
    )


def set_switches(time_s: np.ndarray, sets: np.ndarray, compensated: dict[str, np.ndarray]) -> list[SetSwitch]:
    """Each change of the device's set that has SWITCH_MIN_ROWS rows in both
    of its windows and no other change between them, with the compensated
    reading's step there (SWITCH_WINDOW_S, SWITCH_GAP_S)."""
    changes = np.flatnonzero(sets[1:] != sets[:-1]) + 1
    change_times = time_s[changes]
    reach = SWITCH_GAP_S + SWITCH_WINDOW_S
    switches = []
    for index, at in zip(changes, change_times):
        if np.count_nonzero(np.abs(change_times - at) <= reach) > 1:
            continue
        before = (time_s >= at - reach) & (time_s < at - SWITCH_GAP_S)
        after = (time_s > at + SWITCH_GAP_S) & (time_s <= at + reach)
        if min(np.count_nonzero(before), np.count_nonzero(after)) < SWITCH_MIN_ROWS:
            continue
        levels = {axis: (np.median(values[before]), np.median(values[after])) for axis, values in compensated.items()}
        switches.append(
            SetSwitch(
                float(at),
                str(sets[index]),
                {axis: float(late - early) for axis, (early, late) in levels.items()},
                {
                    axis: float(tilt_deg(np.array(late)) - tilt_deg(np.array(early)))
                    for axis, (early, late) in levels.items()
                },
            )
        )
    return switches


def _axis_result(
    rows: _Rows,
    set_name: str,
    axis: str,
    coefficients: Coefficients | None,
    domain: Domain | None,
    board_outside: np.ndarray | None,
    series: dict[str, np.ndarray],
) -> AxisResult:
    """One set's and axis's figures; its rows' before, after and tilt error go into series."""
    in_set = rows.sets == set_name
    t = rows.temperature[in_set]
    before = rows.filtered[axis][in_set]
    if coefficients is None:
        after = rows.firmware[axis][in_set]
    else:
        after = before - coefficients.table.surface(set_name, axis).evaluate(t, before)
    series.setdefault(f"{axis} before", np.full(rows.count, np.nan))[in_set] = before
    series.setdefault(f"{axis} after", np.full(rows.count, np.nan))[in_set] = after
    rms_before, tilt_before = _about_25(t, before)
    rms_after, tilt_after = _about_25(t, after)
    if tilt_after is not None:
        series.setdefault(f"{axis} tilt error after", np.full(rows.count, np.nan))[in_set] = tilt_after
    outside = (
        int(board_outside[in_set].sum()) if board_outside is not None else _outside(domain, set_name, axis, t, before)
    )
    return AxisResult(
        set_name,
        axis,
        int(in_set.sum()),
        rms_before,
        rms_after,
        outside,
        _percentile_of_size(tilt_before),
        _percentile_of_size(tilt_after),
    )


def _about_25(temperature: np.ndarray, values: np.ndarray) -> tuple[float | None, np.ndarray | None]:
    """The values' RMS about their 25 degC reading, and each row's tilt less
    that reading's tilt (both None without a reading)."""
    reference = reading_at_25(temperature, values)
    if reference is None:
        return None, None
    return float(np.sqrt(np.mean((values - reference) ** 2))), tilt_deg(values) - tilt_deg(np.array(reference))


def tilt_deg(acceleration_lsb: np.ndarray) -> np.ndarray:
    """The tilt about one axis from that axis's reading alone (the paper
    compensates X and Y, section 5): asin of its share of 1 g."""
    return np.degrees(np.arcsin(np.clip(acceleration_lsb / LSB_PER_G, -1.0, 1.0)))


def _percentile_of_size(errors: np.ndarray | None) -> float | None:
    return None if errors is None else float(np.percentile(np.abs(errors), TILT_PERCENTILE))


def _outside(domain: Domain | None, set_name: str, axis: str, temperature: np.ndarray, acceleration: np.ndarray) -> int:
    key = f"{set_name}{axis}"
    if domain is None or key not in domain.temperature_c:
        return 0
    (t_low, t_high), (a_low, a_high) = domain.temperature_c[key], domain.acceleration_lsb[key]
    outside = (temperature < t_low) | (temperature > t_high) | (acceleration < a_low) | (acceleration > a_high)
    return int(outside.sum())


def format_validation(validation: Validation, paper: dict[tuple[str, str], tuple[float, float]] | None) -> str:
    """The RMS table, with the paper's figures beside it when the run is one
    of its field tests (``paper`` maps (set, axis) -> (before, after))."""

    def lsb(value: float | None) -> str:
        return "n/a" if value is None else f"{value:.1f}"

    def degrees(value: float | None) -> str:
        return "n/a" if value is None else f"{value:.4f}"

    low, high = validation.temperature_range_c
    lines = [
        f"{validation.run}: {validation.rows} rows, IMU temperature {low:.1f}..{high:.1f} degC"
        + (f" ({validation.skipped_rows} rows with empty cells skipped)" if validation.skipped_rows else ""),
        f"after = {validation.after_from}",
        "RMS about the 25 degC reading (LSB) and the 95th percentile of the tilt error about it (deg):",
        f"{'set':<8}{'axis':<6}{'rows':>8}{'before':>10}{'after':>10}{'deg before':>12}{'deg after':>11}"
        + (f"{'paper before':>14}{'paper after':>13}" if paper else ""),
    ]
    for result in validation.results:
        line = (
            f"{SET_NAMES[result.set_name]:<8}{result.axis:<6}{result.rows:>8}"
            f"{lsb(result.rms_before_lsb):>10}{lsb(result.rms_after_lsb):>10}"
            f"{degrees(result.tilt_error_p95_before_deg):>12}{degrees(result.tilt_error_p95_after_deg):>11}"
        )
        if paper and (result.set_name, result.axis) in paper:
            before, after = paper[(result.set_name, result.axis)]
            line += f"{before:>14.0f}{after:>13.0f}"
        lines.append(line)
    if validation.tilt_error_p95_deg is not None:
        lines.append(
            f"tilt error after compensation, X and Y: {validation.tilt_error_p95_deg:.4f} deg "
            f"({TILT_PERCENTILE:g}th percentile)"
        )
    largest = validation.largest_switch_step("lsb")
    if largest is not None:
        degrees_step = validation.largest_switch_step("deg")
        lines.append(
            f"warming<->cooling switches measured: {len(validation.switches)}; the largest step of the "
            "compensated reading: "
            + ", ".join(f"{axis} {largest[axis]:.1f} LSB ({degrees_step[axis]:.4f} deg)" for axis in FIT_AXES)
        )
    if validation.firmware_difference_lsb is not None:
        lines.append(
            f"the firmware's own compensated output ({validation.sources}) differs from this "
            f"by at most {validation.firmware_difference_lsb:.2f} LSB"
        )
    for result in validation.results:
        if result.rms_before_lsb is None:
            lines.append(
                f"note: the {SET_NAMES[result.set_name]} rows never come "
                f"within {REFERENCE_BAND_C:g} degC of {REFERENCE_C:g} degC: no reference, no RMS"
            )
            break
    return "\n".join(lines)


def range_warnings(validation: Validation) -> list[str]:
    warnings = []
    if validation.domain_source is None:
        warnings.append(
            "the coefficients' fitted range is unknown (coefficients from EEPROM or uploaded): "
            "give --coefficients FIT_DIR to check the run against it"
        )
        return warnings
    for result in validation.results:
        if result.outside_rows:
            share = 100.0 * result.outside_rows / result.rows
            warnings.append(
                f"{result.axis}: {result.outside_rows} of {result.rows} {SET_NAMES[result.set_name]} rows "
                f"({share:.1f} %) lie outside the range of {validation.domain_source}: "
                f"the surface is extrapolated there"
            )
    return warnings


@dataclass
class ValidationRun:
    """``thermotilt validate``'s workflow: a run checked; ``write`` puts its
    report and figures in out_dir and validation.json in the run folder."""

    run: RunFolder
    validation: Validation
    coefficients: Coefficients | None
    paper: dict[tuple[str, str], tuple[float, float]] | None
    out_dir: Path
    written: list[Path] = field(default_factory=list)

    def write(self) -> None:
        import json

        from .report import write_validation_report

        document = self.run.path / "validation.json"
        try:
            report = write_validation_report(self.out_dir, self.validation, self.coefficients, self.paper)
            document.write_text(json.dumps(self.validation.document(), indent=2) + "\n", encoding="utf-8")
        except OSError as error:
            raise CalibrationDataError(
                f"cannot write {error.filename or self.out_dir}: {error.strerror or error}"
            ) from None
        self.written = [report, document]

    def summary(self) -> str:
        lines = [format_validation(self.validation, self.paper)]
        lines += [f"warning: {warning}" for warning in range_warnings(self.validation)]
        if self.written:
            lines.append(f"wrote {' and '.join(map(str, self.written))}")
        return "\n".join(lines)


def validate_run(run_path: Path, coefficients: str | None, out_dir: Path | None) -> ValidationRun:
    """The run validated with the firmware's output or the named coefficients
    ("paper" or a fit folder); out_dir defaults to RUN/validation."""
    from ..run.summary import RunSummaryError
    from .paper import field_rms_lsb

    run = RunFolder.of(run_path)
    loaded = load_coefficients(coefficients) if coefficients else None
    validation = validate(run.log, loaded)
    try:
        summary = run.summary()
    except RunSummaryError as error:
        raise CalibrationDataError(str(error)) from None
    paper = field_rms_lsb(summary.scenario if summary is not None else None)
    return ValidationRun(run, validation, loaded, paper, out_dir or run.path / "validation")
