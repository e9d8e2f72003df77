"""``thermotilt validate``: a field run as a monitoring user reads it, and
the paper's field check (section 4.3).

First the change of each axis's compensated reading from the installation
reading, across both sets, against the certificate's U where there is one
(tilt_change). Then the paper's measure: the RMS, over a field run, of each
axis's reading minus its reading at 25 degC — before compensation (284 and
161 LSB for X and Y while warming 9 -> 48 degC; 122 and 70 while cooling
26 -> 16 degC) and after (11, 8; 4, 4) — per axis and per set the device
chose (the paper's own reference per set), on the filtered acceleration the
firmware compensates:

    before: ax_filt - ax_filt(25 degC)
    after:  ax_comp - ax_comp(25 degC)

The 25 degC reading is the set's straight line through its rows within
1.5 degC of 25 degC, read at 25 degC (the campaign fit's reference); a set
that never comes that near 25 degC has no reference and no RMS.

``after`` is the firmware's own output (``ax_comp``) unless coefficients
are given: then the run's filtered readings are compensated here with
those surfaces, blended between the sets as the firmware blends them,
which is the paper's post-processing of raw field data.

The coefficients cover a temperature and acceleration range (a fit's, or
the paper's -10..45 degC and +-45 deg); rows outside it (or outside the
certificate's domain, given one) are counted, reported and left out of
every percentile, because a surface is not known there. Coefficients the
board loaded from its EEPROM carry their own temperature range, which the
host does not know: then the board's flag on each row (``temp_domain``, the
IMU frame's) counts the rows outside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..lsm9ds0 import LSB_PER_G, MG_PER_LSB, tilt_deg
from ..run import SETTLE_S
from ..run.folder import RunFolder, RunFolderError
from ..run.log import RunLogError, read_run_columns
from ..set_blend import FIRMWARE_POWER_UP_SHARE, FIRMWARE_TRANSITION_C, blend, warming_shares
from ..surfaces import AXES, PAPER_DEFAULTS, REFERENCE_C, SET_NAMES, SETS, ZERO_SURFACE, CoefficientTable
from .certificate import change_u95, in_domain, read_certificate
from .compare import CALIBRATED_C, read_fit
from .dataset import FIT_AXES, REFERENCE_BAND_C, CalibrationDataError, reading_at_25
from .tilt_change import INSTALLATION_WINDOW_S, SetSwitch, TiltChange, format_tilt_change, set_switches, tilt_change

# The paper's calibration covered +-45 deg of tilt.
CALIBRATED_INCLINATION_DEG = 45.0
TILT_PERCENTILE = 95.0
PAPER_ACCELERATION_LSB = LSB_PER_G * math.sin(math.radians(CALIBRATED_INCLINATION_DEG))
# temp_domain (docs/protocol.md, IMU): inside or outside the block's range.
DOMAIN_FLAGS = ("I", "O")
OUTSIDE_FLAG = "O"
BOARD_DOMAIN = "the block the board loaded (run.csv's temp_domain)"
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
    # The change of tilt from the installation reading (tilt_change).
    change: TiltChange | None = None

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
            "tilt_change_p95_deg": self.change.p95_deg if self.change else None,
            "rows_within_u_share": self.change.within_u_share if self.change else None,
            "tilt_change": self.change.document() if self.change else None,
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


def validate(
    run: Path,
    coefficients: Coefficients | None = None,
    baseline_s: float | None = None,
    certificate: dict | None = None,
) -> Validation:
    """The run checked as a monitoring user reads it (the change from the
    installation reading, tilt_change) and as the paper did (each set about
    its 25 degC reading); rows outside the certificate's domain, or the
    coefficients' range without one, are left out of every percentile."""
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
    after = _compensated(rows, coefficients)
    outside, inside_what = _outside_rows(rows, after, domain, board_outside, certificate)
    series = {"time_s": rows.time_s, "temperature_c": rows.temperature, "set": rows.sets}
    results = [
        _axis_result(rows, set_name, axis, after[axis], outside[axis], series)
        for set_name in SETS
        if (rows.sets == set_name).any()
        for axis in FIT_AXES
    ]
    difference = None
    if coefficients is not None:
        difference = max(float(np.nanmax(np.abs(after[axis] - rows.firmware[axis]))) for axis in FIT_AXES)
    u95_for = change_u95(certificate, rows.temperature, after) if certificate is not None else None
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
        set_switches(rows.time_s, rows.sets, after),
        tilt_change(rows.time_s, rows.temperature, after, outside, baseline_s, u95_for, inside_what),
    )


def _compensated(rows: _Rows, coefficients: Coefficients | None) -> dict[str, np.ndarray]:
    """Each axis's compensated reading on every row: the firmware's, or
    computed here as the firmware does, the two sets' surfaces blended by
    the device's warming share from its power-up at the log's first row
    (set_blend on the logged filtered temperature), one share for every axis."""
    if coefficients is None:
        return {axis: rows.firmware[axis] for axis in FIT_AXES}
    temperature = rows.temperature
    share = warming_shares(FIRMWARE_TRANSITION_C, float(temperature[0]), temperature, FIRMWARE_POWER_UP_SHARE)
    after = {}
    for axis in FIT_AXES:
        before = rows.filtered[axis]
        warming = coefficients.table.surface("W", axis).evaluate(temperature, before)
        cooling = coefficients.table.surface("C", axis).evaluate(temperature, before)
        after[axis] = before - blend(share, warming, cooling)
    return after


def _outside_rows(
    rows: _Rows,
    after: dict[str, np.ndarray],
    domain: Domain | None,
    board_outside: np.ndarray | None,
    certificate: dict | None,
) -> tuple[dict[str, np.ndarray], str]:
    """Per axis, the rows outside the certificate's domain, or else the
    coefficients' fitted range (or the board's flag); and whose it is."""
    if certificate is not None:
        masks = {axis: ~in_domain(certificate, axis, rows.temperature, after[axis]) for axis in FIT_AXES}
        return masks, "the certificate's domain"
    if domain is None:
        nowhere = np.zeros(rows.count, dtype=bool)
        return {axis: nowhere if board_outside is None else board_outside for axis in FIT_AXES}, (
            "every row (the coefficients' range is unknown)" if board_outside is None else BOARD_DOMAIN
        )
    masks = {}
    for axis in FIT_AXES:
        masks[axis] = np.zeros(rows.count, dtype=bool)
        for set_name in SETS:
            in_set = rows.sets == set_name
            masks[axis][in_set] = _outside(
                domain, set_name, axis, rows.temperature[in_set], rows.filtered[axis][in_set]
            )
    return masks, domain.source


def _axis_result(
    rows: _Rows, set_name: str, axis: str, after: np.ndarray, outside: np.ndarray, series: dict[str, np.ndarray]
) -> AxisResult:
    """One set's and axis's figures about its 25 degC reading, its
    percentiles of the rows inside the domain; its rows' before, after and
    tilt error go into series."""
    in_set = rows.sets == set_name
    t = rows.temperature[in_set]
    before, after = rows.filtered[axis][in_set], after[in_set]
    inside = ~outside[in_set]
    series.setdefault(f"{axis} before", np.full(rows.count, np.nan))[in_set] = before
    series.setdefault(f"{axis} after", np.full(rows.count, np.nan))[in_set] = after
    rms_before, tilt_before = _about_25(t, before)
    rms_after, tilt_after = _about_25(t, after)
    if tilt_after is not None:
        series.setdefault(f"{axis} tilt error after", np.full(rows.count, np.nan))[in_set] = np.where(
            inside, tilt_after, np.nan
        )
    return AxisResult(
        set_name,
        axis,
        int(in_set.sum()),
        rms_before,
        rms_after,
        int(np.count_nonzero(~inside)),
        _percentile_of_size(None if tilt_before is None else tilt_before[inside]),
        _percentile_of_size(None if tilt_after is None else tilt_after[inside]),
    )


def _about_25(temperature: np.ndarray, values: np.ndarray) -> tuple[float | None, np.ndarray | None]:
    """The values' RMS about their 25 degC reading, and each row's tilt less
    that reading's tilt (both None without a reading)."""
    reference = reading_at_25(temperature, values)
    if reference is None:
        return None, None
    return float(np.sqrt(np.mean((values - reference) ** 2))), tilt_deg(values) - tilt_deg(np.array(reference))


def _percentile_of_size(errors: np.ndarray | None) -> float | None:
    if errors is None or not len(errors):
        return None
    return float(np.percentile(np.abs(errors), TILT_PERCENTILE))


def _outside(domain: Domain, set_name: str, axis: str, temperature: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
    key = f"{set_name}{axis}"
    if key not in domain.temperature_c:
        return np.zeros(len(temperature), dtype=bool)
    (t_low, t_high), (a_low, a_high) = domain.temperature_c[key], domain.acceleration_lsb[key]
    return (temperature < t_low) | (temperature > t_high) | (acceleration < a_low) | (acceleration > a_high)


def format_validation(
    validation: Validation, paper: dict[tuple[str, str], tuple[float, float]] | None, paper_table: bool = True
) -> str:
    """The change from the installation reading and the set switches; with
    paper_table, the paper's RMS table too, with its figures beside it when
    the run is one of its field tests (``paper`` maps (set, axis) -> (before,
    after))."""
    low, high = validation.temperature_range_c
    lines = [
        f"{validation.run}: {validation.rows} rows, IMU temperature {low:.1f}..{high:.1f} degC"
        + (f" ({validation.skipped_rows} rows with empty cells skipped)" if validation.skipped_rows else ""),
        f"compensated = {validation.after_from}",
    ]
    if validation.change is not None:
        lines.append(format_tilt_change(validation.change))
    else:
        lines.append(
            f"no change from an installation reading: the run has no settled minute "
            f"({SETTLE_S:g}..{SETTLE_S + INSTALLATION_WINDOW_S:g} s after its first row); --baseline TIME names one"
        )
    largest = validation.largest_switch_step("lsb")
    if largest is not None:
        degrees_step = validation.largest_switch_step("deg")
        lines.append(
            f"warming<->cooling switches measured: {len(validation.switches)}; the largest step of the "
            "compensated reading: "
            + ", ".join(f"{axis} {largest[axis]:.1f} LSB ({degrees_step[axis]:.4f} deg)" for axis in FIT_AXES)
        )
    if paper_table:
        lines += _paper_table(validation, paper)
    if validation.firmware_difference_lsb is not None:
        lines.append(
            f"the firmware's own compensated output ({validation.sources}) differs from this "
            f"by at most {validation.firmware_difference_lsb:.2f} LSB"
        )
    return "\n".join(lines)


def _paper_table(validation: Validation, paper: dict[tuple[str, str], tuple[float, float]] | None) -> list[str]:
    """Section 4.3's measure: per set and axis, the RMS about the set's own
    25 degC reading and the 95th percentile of the tilt error about it."""

    def lsb(value: float | None) -> str:
        return "n/a" if value is None else f"{value:.1f}"

    def degrees(value: float | None) -> str:
        return "n/a" if value is None else f"{value:.4f}"

    lines = [
        "the paper's measure (section 4.3): RMS about each set's 25 degC reading (LSB) and the 95th "
        "percentile of the tilt error about it (deg):",
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
    for result in validation.results:
        if result.rms_before_lsb is None:
            lines.append(
                f"note: the {SET_NAMES[result.set_name]} rows never come "
                f"within {REFERENCE_BAND_C:g} degC of {REFERENCE_C:g} degC: no reference, no RMS"
            )
            break
    return lines


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
    # Print the paper's per-set table (section 4.3) too.
    paper_table: bool = False
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
        lines = [format_validation(self.validation, self.paper, self.paper_table)]
        lines += [f"warning: {warning}" for warning in range_warnings(self.validation)]
        if self.written:
            lines.append(f"wrote {' and '.join(map(str, self.written))}")
        return "\n".join(lines)


@dataclass(frozen=True)
class ValidateOptions:
    # "paper" or a fit folder; None: the firmware's own compensated output.
    coefficients: str | None = None
    out_dir: Path | None = None
    # The installation reading's time (run.csv's time_s); None: the first settled minute.
    baseline_s: float | None = None
    # A certificate.json or the fit folder holding it; None: the fit's, if coefficients names one.
    certificate: Path | None = None
    paper_table: bool = False


def certificate_for(options: ValidateOptions) -> dict | None:
    """The certificate the run is held against: the one named, or the
    coefficients' fit folder's where it has one with a U table."""
    if options.certificate is not None:
        return read_certificate(options.certificate)
    if options.coefficients in (None, "paper"):
        return None
    try:
        return read_certificate(Path(options.coefficients))
    except CalibrationDataError:
        # No certificate, or one from before certificates had a U table.
        return None


def validate_run(run_path: Path, options: ValidateOptions) -> ValidationRun:
    """The run validated with the firmware's output or the named coefficients
    ("paper" or a fit folder), against a certificate where there is one;
    out_dir defaults to RUN/validation."""
    from ..run.summary import RunSummaryError
    from .paper import field_rms_lsb

    run = RunFolder.of(run_path)
    loaded = load_coefficients(options.coefficients) if options.coefficients else None
    validation = validate(run.log, loaded, options.baseline_s, certificate_for(options))
    try:
        summary = run.summary()
    except RunSummaryError as error:
        raise CalibrationDataError(str(error)) from None
    paper = field_rms_lsb(summary.scenario if summary is not None else None)
    return ValidationRun(
        run, validation, loaded, paper, options.out_dir or run.path / "validation", options.paper_table
    )
