"""``thermotilt fit``'s workflow: a campaign folder (one sensor's, or a
batch's, a folder per sensor) fitted, certified and, if asked, scored by
surface family; the result writes its files and says what it did.

A certificate is issued only for an identified item (ISO/IEC 17025
7.8.2.1 e): a fit without a sensor ID writes its coefficients and report,
and no certificate."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any

from .campaign.folder import CampaignFolder
from .dataset import FIT_AXES, CalibrationDataError

CERTIFICATE_FILES = ("certificate.json", "certificate.html", "certificate.pdf")
NO_ID_REASON = "the item has no sensor ID (a campaign.json that records it, or --sensor-id, gives one)"


@dataclass(frozen=True)
class FitOptions:
    axes: tuple[str, ...] = FIT_AXES
    settle_s: float | None = None
    # The sensor the campaign calibrated, where its campaign.json does not say.
    sensor_id: str | None = None
    compare_families: bool = False
    # Each sensor's calibration before this one, by ID: its fit folder.
    previous_fits: Mapping[str, Path] = field(default_factory=dict)
    # For a sensor previous_fits does not name: its latest fit from a
    # campaign that ended before this one started (sensor ID, start), if any.
    find_previous: Callable[[str, datetime | None], Path | None] | None = None


@dataclass
class SensorFit:
    """One sensor's campaign fitted, for out_dir."""

    campaign_dir: Path
    out_dir: Path
    campaign: Any
    fits: list[Any]
    # The certification, or why there is none (no_certificate).
    certificate: Any
    no_certificate: str | None
    families: list[Any] | None
    fitted_for: str
    report: Path | None = None

    def write(self) -> None:
        from .families import format_families, write_families
        from .fit import write_outputs
        from .report import write_fit_report

        try:
            write_outputs(self.fits, self.campaign, self.out_dir, self.fitted_for)
            if self.families is not None:
                write_families(self.families, self.out_dir)
            families = format_families(self.families) if self.families else None
            self.report = write_fit_report(self.out_dir, self.fits, self.campaign, families)
            self._write_certificate()
        except OSError as error:
            raise CalibrationDataError(f"cannot write {self.out_dir}: {error.strerror or error}") from None

    def _write_certificate(self) -> None:
        """The certificate, after coefficients.bin (it states the block's
        sha256); without one, a previous fit's certificate files in out_dir
        go, since they describe other coefficients."""
        if self.certificate is None:
            for name in CERTIFICATE_FILES:
                (self.out_dir / name).unlink(missing_ok=True)
            return
        from .certificate import write_certificate

        write_certificate(self.out_dir, self.certificate)

    def uncertainty_line(self) -> str:
        """U to two significant digits with k and p, or the one line that says no certificate was issued."""
        if self.certificate is None:
            return f"no certificate issued: {self.no_certificate}"
        from .certificate.budget import two_significant_text

        document = self.certificate.document
        axes = ", ".join(f"{axis} {two_significant_text(u)}" for axis, u in document["u95_max_deg"].items())
        return (
            f"tilt uncertainty, the largest over the calibrated domain: U = {two_significant_text(document['tilt_u95_deg'])} "
            f"deg (k = {document['coverage_factor']:.2f}, p = {document['coverage_probability'] * 100:g} %); per axis {axes} deg"
        )

    def summary(self) -> str:
        from .families import format_families
        from .fit import format_table

        campaign = self.campaign
        lines = [
            f"{len(campaign.positions)} positions, {sum(fit.points for fit in self.fits)} points"
            + (f" ({campaign.skipped_rows} rows with empty cells skipped)" if campaign.skipped_rows else "")
        ]
        if campaign.stabilizing_rows:
            lines.append(
                f"{campaign.stabilizing_rows} rows left out: the chamber had not yet reached its "
                f"program's setpoint (docs/calibration.md)"
            )
        lines += [
            format_table(self.fits),
            "bounds: Newey-West (HAC) 95 % within each position; coefficients.json also has the "
            "OLS bounds, which ignore the rows' autocorrelation",
        ]
        if self.families is not None:
            lines.append(format_families(self.families))
        lines.append(
            f"fitted for sensor {self.fitted_for}"
            if self.fitted_for
            else "fitted for no particular sensor (no sensor ID)"
        )
        written = f"wrote {self.out_dir / 'coefficients.json'}, coefficients.bin (EEPROM block), coefficients.h, "
        written += f"{self.report.name} with figures"
        if self.certificate is not None:
            number = self.certificate.document.get("certificate_number")
            written += f", certificate {number}: certificate.json, .html and .pdf" if number else ", certificate.*"
        lines += [self.uncertainty_line(), written]
        return "\n".join(lines)


def fit_sensor(campaign_dir: Path, out_dir: Path, options: FitOptions) -> SensorFit:
    """One sensor's campaign fitted and certified (nothing written yet)."""
    from .certificate import NotCertifiable, certify
    from .certificate.stability import PreviousCalibration
    from .dataset import load
    from .families import compare_families
    from .fit import fit_campaign

    campaign = load(campaign_dir, settle_s=options.settle_s)
    fits = fit_campaign(campaign, options.axes)
    fitted_for = campaign.sensor_id or ""
    if options.sensor_id is not None:
        if fitted_for and options.sensor_id != fitted_for:
            raise CalibrationDataError(
                f"--sensor-id {options.sensor_id}: the campaign in {campaign_dir} was logged with sensor {fitted_for}"
            )
        fitted_for = options.sensor_id
    certificate, no_certificate = None, NO_ID_REASON
    if fitted_for:
        previous_fit = _previous_fit(options, fitted_for, campaign_dir)
        previous = None if previous_fit is None else PreviousCalibration.read(previous_fit, fitted_for)
        try:
            certificate, no_certificate = certify(campaign, fits, campaign_dir, fitted_for, previous), None
        except NotCertifiable as error:
            no_certificate = str(error)
    families = compare_families(campaign, options.axes) if options.compare_families else None
    return SensorFit(campaign_dir, out_dir, campaign, fits, certificate, no_certificate, families, fitted_for)


def _previous_fit(options: FitOptions, sensor_id: str, campaign_dir: Path) -> Path | None:
    from .certificate.document import calibration_dates, campaign_record

    if sensor_id in options.previous_fits or options.find_previous is None:
        return options.previous_fits.get(sensor_id)
    started = calibration_dates(campaign_record(campaign_dir))["started_utc"]
    return options.find_previous(sensor_id, datetime.strptime(started, "%Y-%m-%dT%H:%M:%SZ") if started else None)


def fits_by_sensor(fit_dir: Path) -> dict[str, Path]:
    """The fit folders fit_dir holds, by their sensor's ID: itself (one
    sensor's fit) or, for a batch's, each sensor's folder in it."""
    from .compare import fitted_sensor_id

    if (fit_dir / "coefficients.json").is_file():
        folders = [fit_dir]
    else:
        folders = sorted(path.parent for path in fit_dir.glob("*/coefficients.json"))
    found = {fitted_sensor_id(folder): folder for folder in folders}
    found.pop("", None)
    if not found:
        raise CalibrationDataError(f"{fit_dir}: no fit of an identified sensor (coefficients.json with a sensor ID)")
    return found


@dataclass
class FolderFit:
    """A campaign folder's fits: one sensor's, or a batch's (a folder each
    in out_dir, by sensor ID)."""

    out_dir: Path
    sensors: dict[str, SensorFit]
    batch: bool

    def write(self) -> None:
        for fit in self.sensors.values():
            fit.write()

    def summary(self) -> str:
        if not self.batch:
            return next(iter(self.sensors.values())).summary()
        lines = []
        for sensor, fit in self.sensors.items():
            lines += [f"== sensor {sensor}", fit.summary()]
        lines.append(f"{len(self.sensors)} sensors fitted, one folder each in {self.out_dir}:")
        lines += [f"  {sensor:<8}  {fit.uncertainty_line()}  -> {fit.out_dir}" for sensor, fit in self.sensors.items()]
        return "\n".join(lines)


def fit_folder(campaign_dir: Path, out_dir: Path, options: FitOptions) -> FolderFit:
    """The campaign in campaign_dir fitted, each sensor of a batch on its own."""
    try:
        sensor_ids = CampaignFolder(campaign_dir).batch()
    except ValueError as error:
        raise CalibrationDataError(str(error)) from None
    if not sensor_ids:
        return FolderFit(out_dir, {"": fit_sensor(campaign_dir, out_dir, options)}, batch=False)
    if options.sensor_id is not None:
        raise CalibrationDataError(
            f"--sensor-id names one sensor; {campaign_dir} is a batch, each sensor named by its campaign"
        )
    fits = {sensor: fit_sensor(campaign_dir / sensor, out_dir / sensor, options) for sensor in sensor_ids}
    return FolderFit(out_dir, fits, batch=True)
