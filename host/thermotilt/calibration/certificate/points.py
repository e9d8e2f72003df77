"""The certificate's results per calibration point (a position's rows of
one set, on one axis): its nominal angle, the error as found (before
compensation) and as left (after), out of sample, and U there; and how
many points' errors the table's U holds (U for an installation reading
at the points' reference temperature)."""

from __future__ import annotations

import numpy as np

from ...lsm9ds0 import MG_PER_LSB
from .domain import band_index
from .errors import AxisErrors

PERCENTILE = 95.0
# A point's errors are about its reference reading at 25 degC (dataset.reading_at_25):
# a change from an installation there.
REFERENCE_C = 25.0


def _p95(values: np.ndarray) -> float | None:
    values = values[np.isfinite(values)]
    return float(np.percentile(np.abs(values), PERCENTILE)) if len(values) else None


def _band_checks(errors: AxisErrors, mine: np.ndarray, table: dict, lookup: dict) -> list[dict]:
    """Per temperature band the point's rows reach: p95 in and out of sample beside U."""
    rows = band_index(errors.temperature_c[mine], table["temperature_bands_c"], closed_above=False)
    column = int(band_index(np.abs(errors.nominal_deg[errors.position[mine][:1]]), table["tilt_bands_deg"], True)[0])
    checks = []
    for row in np.unique(rows[rows >= 0]):
        u95 = lookup.get((int(row), column))
        if u95 is None:
            continue
        in_band = rows == row
        checks.append(
            {
                "temperature_band_c": table["temperature_bands_c"][row],
                "u95_deg": u95,
                "as_left_p95_deg": _p95(errors.as_left_deg[mine][in_band]),
                "out_of_sample_p95_deg": _p95(errors.out_of_sample_deg[mine][in_band]),
            }
        )
    return checks


def axis_points(errors: AxisErrors, labels: tuple[str, ...], table: dict) -> list[dict]:
    """Each calibration point of the axis, in campaign order, W before C."""
    at_reference = int(band_index(np.array([REFERENCE_C]), table["temperature_bands_c"], closed_above=False)[0])
    lookup = (
        {}
        if at_reference < 0
        else {
            (i, j): value
            for i, row in enumerate(table["u95_deg"][at_reference])
            for j, value in enumerate(row)
            if value is not None
        }
    )
    points = []
    for position in np.unique(errors.position):
        for set_name in ("W", "C"):
            mine = (errors.position == position) & (errors.set_name == set_name)
            if not mine.any():
                continue
            checks = _band_checks(errors, mine, table, lookup)
            rms_lsb = float(np.sqrt(np.mean(errors.in_sample_lsb[mine] ** 2)))
            points.append(
                {
                    "position": labels[position],
                    "set_name": set_name,
                    "axis": errors.axis,
                    "nominal_deg": float(errors.nominal_deg[position]),
                    "rows": int(np.count_nonzero(mine)),
                    "temperature_range_c": [
                        float(errors.temperature_c[mine].min()),
                        float(errors.temperature_c[mine].max()),
                    ],
                    "as_found_p95_deg": _p95(errors.as_found_deg[mine]),
                    "as_left_p95_deg": _p95(errors.as_left_deg[mine]),
                    "as_left_rms_lsb": rms_lsb,
                    "as_left_rms_mg": rms_lsb * MG_PER_LSB,
                    "out_of_sample_p95_deg": _p95(errors.out_of_sample_deg[mine]),
                    # False: the fold without the position could not be fitted; the errors are in sample.
                    "out_of_sample": bool(errors.evaluable[position]),
                    "u95_deg": max((check["u95_deg"] for check in checks), default=None),
                    "bands": checks,
                }
            )
    return points


def coverage(points: list[dict]) -> dict:
    """The share of calibration points, band by band, whose 95th percentile
    of |error| is within U there: in sample (the certificate's surfaces)
    and out of sample (surfaces fitted without the point's position)."""
    checks = [check for point in points for check in point["bands"]]

    def share(key: str) -> float | None:
        known = [check for check in checks if check[key] is not None]
        return sum(check[key] <= check["u95_deg"] for check in known) / len(known) if known else None

    return {
        "point_bands": len(checks),
        "as_left_within_u95": share("as_left_p95_deg"),
        "out_of_sample_within_u95": share("out_of_sample_p95_deg"),
    }
