"""A certificate issued: the campaign's errors and budget bands assembled
into certificate.json's document (``certify``), then, once coefficients.bin
is written, numbered after its sha256 and written as JSON, HTML and PDF
(``write_certificate``)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..dataset import Campaign
from ..fit import SurfaceFit
from . import document as fields
from .budget import COVERAGE_PROBABILITY, FIELD_RATE_LIMIT_C_PER_MIN, axis_inputs
from .crossing import estimate_crossing
from .errors import AxisErrors, NoNominalAngle, axis_errors, nominal_angles, tilt_allowance_deg
from .points import axis_points, coverage
from .stability import PreviousCalibration
from .uncertainty import MIN_BAND_POSITIONS, Cell, axis_cells, table

CERTIFICATE_JSON = "certificate.json"
CERTIFICATE_HTML = "certificate.html"
CERTIFICATE_PDF = "certificate.pdf"
COEFFICIENTS_BIN = "coefficients.bin"
MEASURAND = (
    "The change of tilt about the axis (X or Y) from an installation reading: a single compensated reading at "
    "an IMU-indicated temperature in the reading's band less the installation reading, taken at an "
    "IMU-indicated temperature in the installation's band once the device's set is decided (the temperature "
    "has moved its set transition one way since power-up), the tilt static."
)
METHOD = (
    "Per axis, U is tabulated by bands of the installation reading's IMU temperature, of the reading's (5 "
    "degC each) and of |nominal tilt| (0-15, 15-30, 30-45 deg, a band of fewer than "
    f"{MIN_BAND_POSITIONS} positions merged with its neighbour). The mounting-to-mounting component is "
    "evaluated out of sample: each position's rows compensated with surfaces fitted without it; per cell the "
    "RMS over positions of the difference of their mean errors in the two temperature bands (positions - 1 "
    "degrees of freedom, GUM H.5, F.1.1.2) and the rows' scatter about each mean (their effective count, "
    "Newey-West). Type B components (GUM 4.3) as the budget lists them, each a bound over its cell. u_c is "
    "their root sum of squares, nu_eff by Welch-Satterthwaite (G.4.1), k from Student's t at p = 95 %, "
    "U = k u_c rounded up to two significant digits; tilt_u95_deg is the largest U of the table, a bound "
    "over the domain. The calibration points' errors are about their reference reading at 25 degC: they "
    "are held against U for an installation in the band of 25 degC."
)


class NotCertifiable(ValueError):
    """A fit no certificate can be issued for; one readable line."""


@dataclass
class Certification:
    """certificate.json's document before its number, and the rows its figure shows."""

    document: dict
    errors: dict[str, AxisErrors]


def _temperature_domain(fits: list[SurfaceFit]) -> tuple[float, float]:
    """Where every set of every axis was fitted: each row could be compensated with either set."""
    return max(f.temperature_range_c[0] for f in fits), min(f.temperature_range_c[1] for f in fits)


def _budget(cell: Cell) -> dict:
    return {
        "axis": cell.axis,
        "installation_band_c": list(cell.installation_band_c),
        "temperature_band_c": list(cell.temperature_band_c),
        "tilt_band_deg": list(cell.tilt_band_deg),
        "positions": cell.positions,
        "components": [component.document() for component in cell.components],
        "standard_deg": cell.combined.standard_deg,
        "effective_dof": None if math.isinf(cell.combined.effective_dof) else cell.combined.effective_dof,
        "coverage_factor": cell.combined.coverage_factor,
        "expanded_deg": cell.expanded_deg,
    }


def _cell_summary(cell: Cell) -> dict:
    return {
        "axis": cell.axis,
        "installation_band_c": list(cell.installation_band_c),
        "temperature_band_c": list(cell.temperature_band_c),
        "tilt_band_deg": list(cell.tilt_band_deg),
        "contributions_deg": {c.name: round(c.contribution_deg, 6) for c in cell.components},
        "type_a_expanded_deg": cell.type_a.expanded_deg,
        "expanded_deg": cell.expanded_deg,
    }


def _axis_results(
    campaign: Campaign,
    fits: list[SurfaceFit],
    angles: dict,
    domain_c: tuple[float, float],
    previous: PreviousCalibration | None,
) -> dict:
    errors_by_axis = {
        axis: axis_errors(campaign, fits, axis, angles[axis]) for axis in dict.fromkeys(f.axis for f in fits)
    }
    crossing = estimate_crossing(errors_by_axis, fits)
    results = {}
    for axis, errors in errors_by_axis.items():
        cells = axis_cells(errors, axis_inputs(errors, fits, crossing, previous), domain_c)
        if not cells:
            raise NotCertifiable(f"{axis} axis: no band of IMU temperature and tilt holds rows of two positions")
        axis_table = table(cells, domain_c, errors)
        results[axis] = (errors, cells, axis_table, axis_points(errors, campaign.positions, axis_table))
    return results


def certify(
    campaign: Campaign,
    fits: list[SurfaceFit],
    campaign_dir: Path,
    sensor_id: str,
    previous: PreviousCalibration | None = None,
) -> Certification:
    """certificate.json's document (all but the fields write_certificate
    adds) for the sensor sensor_id, recalibrated after previous if given;
    NotCertifiable when the campaign cannot support one."""
    try:
        angles = nominal_angles(campaign.positions)
    except NoNominalAngle as error:
        raise NotCertifiable(str(error)) from None
    domain_c = _temperature_domain(fits)
    results = _axis_results(campaign, fits, angles, domain_c, previous)
    record, lab = fields.campaign_record(campaign_dir), fields.laboratory(campaign_dir)
    present = {axis: np.isfinite(errors.reference_lsb) for axis, (errors, *_) in results.items()}
    domain = {
        "temperature_c": list(domain_c),
        "tilt_deg": {
            axis: [float(np.min(e.nominal_deg[present[axis]])), float(np.max(e.nominal_deg[present[axis]]))]
            for axis, (e, *_) in results.items()
        },
        "tilt_allowance_deg": {axis: tilt_allowance_deg(e) for axis, (e, *_) in results.items()},
    }
    worst = {axis: max(cells, key=lambda cell: cell.expanded_deg) for axis, (_, cells, *_) in results.items()}
    headline = max(worst.values(), key=lambda cell: cell.expanded_deg)
    points = [point for *_, axis_points_ in results.values() for point in axis_points_]
    zero = {axis: e.zero_reading_lsb for axis, (e, *_) in results.items()}
    document = {
        "title": "Calibration certificate: thermal-drift compensated tilt of a MEMS accelerometer",
        "certificate_number": None,
        "issue_date": None,
        "laboratory": {"name": lab["name"], "address": lab["address"]},
        "customer": {"name": lab["customer"], "address": lab["customer_address"]},
        "item": fields.item(sensor_id, record, lab, list(results)),
        "sensor_id": sensor_id,
        "procedure": fields.procedure(),
        "calibration_dates": fields.calibration_dates(record),
        "campaign": str(campaign_dir),
        "previous_calibration": None
        if previous is None
        else {
            "certificate_number": previous.certificate_number,
            "ended_utc": previous.calibrated,
            "fit": str(previous.fit_dir),
        },
        "chamber_program": fields.chamber_program(record),
        "positions": len(campaign.positions),
        "references": {"tilt": lab["tilt_reference"], "temperature": lab["temperature_reference"]},
        "measurand": MEASURAND,
        "conversion": fields.conversion(zero),
        "zero_reading_lsb": zero,
        "domain": domain,
        "validity": fields.validity(domain, FIELD_RATE_LIMIT_C_PER_MIN),
        "tilt_u95_deg": headline.expanded_deg,
        "u95_max_deg": {axis: cell.expanded_deg for axis, cell in worst.items()},
        "coverage_factor": headline.combined.coverage_factor,
        "coverage_probability": COVERAGE_PROBABILITY,
        "uncertainty_table": {axis: axis_table for axis, (_, _, axis_table, _) in results.items()},
        "budget": {axis: _budget(cell) for axis, cell in worst.items()},
        "cells": [_cell_summary(cell) for _, cells, *_ in results.values() for cell in cells],
        "method": METHOD,
        "not_out_of_sample": {
            axis: [campaign.positions[p] for p in np.flatnonzero(present[axis] & ~e.evaluable)]
            for axis, (e, *_) in results.items()
        },
        "points": points,
        "coverage": coverage(points),
        "coefficients_sha256": None,
        "authorisation": {"authorised_by": lab["authorised_by"], "signature": ""},
        "statements": list(fields.STATEMENTS),
        "end": fields.END_MARKER,
    }
    return Certification(document, {axis: errors for axis, (errors, *_) in results.items()})


def write_certificate(out_dir: Path, certification: Certification) -> tuple[Path, Path, Path]:
    """certificate.json, .html and .pdf in out_dir, numbered after the
    coefficients.bin already written there (its bytes' sha256)."""
    from .render import figure_png, html_page, pdf_document

    coefficients = (out_dir / COEFFICIENTS_BIN).read_bytes()
    document = certification.document
    document.update(fields.issue_fields(document, coefficients))
    png = figure_png(document, certification.errors)
    paths = out_dir / CERTIFICATE_JSON, out_dir / CERTIFICATE_HTML, out_dir / CERTIFICATE_PDF
    paths[0].write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    paths[1].write_text(html_page(document, png), encoding="utf-8")
    paths[2].write_bytes(pdf_document(document, png))
    return paths
