"""Where a certificate's expanded uncertainty applies, and how much it is at
a reading: the bands of IMU temperature and of nominal tilt its table is
made of, the conversion of a compensated reading to nominal tilt through
the certificate's zero reading, and ``u95_at``/``in_domain`` for a run's
rows (what ``validate`` asks of a certificate).

The tilt bands are of |nominal tilt| about the axis, closed above
(0-15, 15-30, 30-45 deg): a calibration point at 15 deg belongs to the first.
The temperature bands are TEMPERATURE_BAND_C wide on multiples of it, the
outer two cut at the domain's ends, closed below.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ...lsm9ds0 import tilt_deg
from ..dataset import CalibrationDataError

TEMPERATURE_BAND_C = 5.0
TILT_BAND_EDGES_DEG = (0.0, 15.0, 30.0, 45.0)


def temperature_bands(low_c: float, high_c: float) -> list[tuple[float, float]]:
    """[low, high] cut into TEMPERATURE_BAND_C bands on multiples of it."""
    first = math.floor(low_c / TEMPERATURE_BAND_C) * TEMPERATURE_BAND_C
    edges = [low_c]
    edge = first + TEMPERATURE_BAND_C
    while edge < high_c:
        edges.append(edge)
        edge += TEMPERATURE_BAND_C
    edges.append(high_c)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:])]


def nominal_tilt_deg(compensated_lsb: np.ndarray, zero_reading_lsb: float) -> np.ndarray:
    """The tilt a compensated reading stands for once the axis's zero
    reading (the measuring offset, paper section 4.1) is taken off:
    asin((a - zero) / 1 g), in degrees, as ``lsm9ds0.tilt_deg`` converts."""
    return tilt_deg(np.asarray(compensated_lsb, dtype=float) - zero_reading_lsb)


def band_index(values: np.ndarray, bands: list[list[float]], closed_above: bool) -> np.ndarray:
    """Each value's band (index into bands, contiguous and in order), -1
    outside them all."""
    values = np.asarray(values, dtype=float)
    inner = np.array([band[1] for band in bands[:-1]], dtype=float)
    index = np.searchsorted(inner, values, side="left" if closed_above else "right")
    inside = (values >= bands[0][0]) & (values <= bands[-1][1])
    return np.where(inside & np.isfinite(values), index, -1)


def _cells(document: dict, axis: str, temperature_c: np.ndarray, compensated_lsb: np.ndarray):
    """Each row's reading band and tilt band of the axis's table, and
    whether the row is inside the domain (None without a table)."""
    table = document.get("uncertainty_table", {}).get(axis)
    if table is None:
        return None
    temperature = np.asarray(temperature_c, dtype=float)
    compensated = np.asarray(compensated_lsb, dtype=float)
    domain = document["domain"]
    tilt = nominal_tilt_deg(compensated, document["zero_reading_lsb"][axis])
    low, high = domain["tilt_deg"][axis]
    allowance = domain["tilt_allowance_deg"][axis]
    low_c, high_c = domain["temperature_c"]
    inside = (tilt >= low - allowance) & (tilt <= high + allowance)
    inside &= (temperature >= low_c) & (temperature <= high_c)
    tilt_bands = [list(band) for band in table["tilt_bands_deg"]]
    # The allowance beyond the outermost calibration point belongs to the last band.
    tilt_bands[-1][1] += allowance
    rows = band_index(np.clip(temperature, low_c, high_c), table["temperature_bands_c"], closed_above=False)
    columns = band_index(np.abs(tilt), tilt_bands, closed_above=True)
    return rows, columns, inside & (rows >= 0) & (columns >= 0)


def installation_band(document: dict, axis: str, installation_c: float) -> int:
    """The axis's table's band of an installation reading's IMU temperature, -1 outside the domain."""
    table = document.get("uncertainty_table", {}).get(axis)
    low_c, high_c = document["domain"]["temperature_c"]
    if table is None or not low_c <= installation_c <= high_c:
        return -1
    return int(band_index(np.array([installation_c]), table["temperature_bands_c"], closed_above=False)[0])


def u95_at(
    document: dict, axis: str, temperature_c: np.ndarray, compensated_lsb: np.ndarray, installation_c: float
) -> np.ndarray:
    """The certificate's expanded uncertainty U (95 %, degrees) of each row's
    change from an installation reading at installation_c: the value of its
    table (``document["uncertainty_table"][axis]``) at the installation's
    IMU-temperature band, the row's and the row's |nominal tilt| band; NaN
    where the row or the installation is outside the certificate's domain
    or the axis has no table.

    temperature_c: the IMU's temperature reading (degC), as run.csv's
    ``imu_temp_c``. compensated_lsb: the device's compensated reading of that
    axis (``ax_comp``/``ay_comp``, or a host compensation of ``a*_filt``),
    which still carries the measuring offset (paper section 4.1: X about
    -1823 LSB): it is converted to nominal tilt with the certificate's
    ``zero_reading_lsb[axis]`` (``nominal_tilt_deg``). The domain is the
    calibrated IMU temperatures ``domain["temperature_c"]`` and the axis's
    nominal tilts ``domain["tilt_deg"][axis]`` widened by
    ``domain["tilt_allowance_deg"][axis]`` (how far the conversion put a
    calibration point from its nominal angle). The U is for a static tilt's
    single reading less the installation reading (the measurand
    ``document["measurand"]`` states)."""
    shape = np.broadcast(np.asarray(temperature_c), np.asarray(compensated_lsb)).shape
    result = np.full(shape, np.nan)
    cells = _cells(document, axis, temperature_c, compensated_lsb)
    early = installation_band(document, axis, installation_c)
    if cells is None or early < 0:
        return result
    rows, columns, inside = cells
    values = np.array(document["uncertainty_table"][axis]["u95_deg"], dtype=float)[early]
    result[inside] = values[rows[inside], columns[inside]]
    return result


def change_u95(
    document: dict, temperature_c: np.ndarray, compensated_lsb: dict[str, np.ndarray]
) -> Callable[[float], dict[str, np.ndarray]]:
    """``u95_at`` for each axis of compensated_lsb, as ``tilt_change`` asks
    for it once it knows the installation reading's temperature."""

    def at_installation(installation_c: float) -> dict[str, np.ndarray]:
        return {
            axis: u95_at(document, axis, temperature_c, values, installation_c)
            for axis, values in compensated_lsb.items()
        }

    return at_installation


def in_domain(document: dict, axis: str, temperature_c: np.ndarray, compensated_lsb: np.ndarray) -> np.ndarray:
    """Whether each row lies where the certificate states a U (same
    arguments and conventions as ``u95_at``): inside its domain, in a cell
    of its table with a number for some installation band."""
    cells = _cells(document, axis, temperature_c, compensated_lsb)
    if cells is None:
        return np.zeros(np.broadcast(np.asarray(temperature_c), np.asarray(compensated_lsb)).shape, dtype=bool)
    rows, columns, inside = cells
    stated = np.isfinite(np.array(document["uncertainty_table"][axis]["u95_deg"], dtype=float)).any(axis=0)
    result = inside.copy()
    result[inside] = stated[rows[inside], columns[inside]]
    return result


def read_certificate(path: Path) -> dict:
    """A certificate.json with its U table (a fit folder: the one in it);
    anything else is a CalibrationDataError of one line."""
    if path.is_dir():
        path = path / "certificate.json"
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise CalibrationDataError(f"certificate {path}: {error.strerror or error}") from None
    except ValueError as error:
        raise CalibrationDataError(f"certificate {path}: not JSON ({error})") from None
    if not isinstance(document, dict) or "uncertainty_table" not in document:
        raise CalibrationDataError(f"certificate {path}: not a certificate with a U table (thermotilt fit writes one)")
    return document
