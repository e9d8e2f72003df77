"""The budget's long-term stability component: a recalibration's
certificate takes it from how the sensor's drift surfaces changed since
its previous calibration (``surface_change.stability_bound``).

Thermal parameters of low-cost IMUs change with time, so a periodical
recalibration is needed (Wang, Li, Niu, J. Navigation 2015). Assumed: the
surfaces change by at most as much again before the next recalibration.
The change measured between two calibrations also carries both
calibrations' own scatter (a new mounting's drift slope each), so it
overstates the sensor's ageing: the component errs on the safe side.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ..compare import FittedSurface, fitted_sensor_id, read_fit
from ..dataset import CalibrationDataError
from ..fit import SurfaceFit
from ..surface_change import stability_bound, surface_change

NOT_EVALUATED = (
    "not evaluated: no earlier calibration of this sensor was given (a recalibration's certificate takes "
    "the change of its drift surfaces since the previous one: `thermotilt history`)"
)


@dataclass(frozen=True)
class PreviousCalibration:
    """The sensor's calibration before this one: its fit folder's surfaces and certificate."""

    fit_dir: Path
    surfaces: dict[str, FittedSurface]
    certificate_number: str | None
    calibrated: str | None  # the campaign's end, as its certificate gives it

    @classmethod
    def read(cls, fit_dir: Path, sensor_id: str) -> PreviousCalibration:
        """fit_dir's calibration of sensor_id; CalibrationDataError for another sensor's."""
        fitted_for = fitted_sensor_id(fit_dir)
        if fitted_for != sensor_id:
            raise CalibrationDataError(
                f"previous calibration {fit_dir}: fitted for {fitted_for or 'no sensor'}, not {sensor_id}"
            )
        surfaces = read_fit(fit_dir)
        try:
            certificate = json.loads((fit_dir / "certificate.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            certificate = {}
        dates = certificate.get("calibration_dates") or {}
        return cls(fit_dir, surfaces, certificate.get("certificate_number"), dates.get("ended_utc"))

    def stability(self, fits: list[SurfaceFit], axis: str) -> tuple[float | None, str]:
        """The axis's half-width in degrees and its source; None where the
        two fits share no domain for it."""
        changes = []
        for fit in fits:
            key = f"{fit.set_name}{axis}"
            change = surface_change(key, self.surfaces[key], fit) if fit.axis == axis and key in self.surfaces else None
            if change is not None:
                changes.append(change)
        previous = f"certificate {self.certificate_number}" if self.certificate_number else "no certificate"
        where = f"the previous calibration ({previous}, ended {self.calibrated or 'undated'}, fit {self.fit_dir})"
        if not changes:
            return None, f"not evaluated: {where} and this one share no domain on {axis}"
        bound = stability_bound(changes)
        sets = ", ".join(change.surface for change in changes)
        return bound, (
            f"change of the drift surfaces ({sets}) since {where}, new - old in degrees of tilt on a grid over "
            "the domain both calibrated: its widest spread over temperature and sets at one tilt, "
            f"{bound:.3g} deg, taken as the bound of their change until the next calibration (assumed; it "
            "carries both calibrations' own scatter, so it errs on the safe side)"
        )
