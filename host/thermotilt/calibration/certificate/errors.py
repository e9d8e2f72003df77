"""Every calibration row's tilt error, three ways, per axis: before
compensation (as found), after it with the campaign's surfaces (as left,
in sample) and after it with surfaces fitted without the row's position
(leave-one-position-out: what a new mounting sees, GUM H.5's "between"
draws evaluated out of sample).

The error is about the position's one reference reading (``dataset``'s
residual reference: the mean of its warming and cooling 25 degC readings),
converted to degrees as ``lsm9ds0.tilt_deg`` converts a reading, after the
axis's zero reading: tilt = asin((a - zero) / 1 g).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ...lsm9ds0 import LSB_PER_G, tilt_deg
from ...surfaces import SETS
from ..dataset import Campaign, SetData
from ..fit import SurfaceFit, design

# A quadratic in the acceleration needs three levels of it (fit.MIN_POSITIONS):
# a fold left with fewer would extrapolate a surface its data cannot determine.
MIN_FOLD_LEVELS = 3
# dataset labels a position "<run> (x 15.00 deg, y 0.00 deg)": the tilt table's angles.
_ANGLES = re.compile(r"\(x (?P<x>-?[0-9.]+) deg, y (?P<y>-?[0-9.]+) deg\)")


class NoNominalAngle(ValueError):
    """A position whose label does not give the tilt table's angles."""


@dataclass(frozen=True)
class AxisErrors:
    """One axis's calibration rows, both sets concatenated (W then C)."""

    axis: str
    set_name: np.ndarray  # "W" or "C" per row
    position: np.ndarray  # index into Campaign.positions
    temperature_c: np.ndarray
    acceleration_lsb: np.ndarray  # the filtered reading the surfaces take
    rate_c_per_s: np.ndarray  # NaN where the campaign has none
    time_s: np.ndarray  # the log's time; NaN where the campaign has none
    as_found_deg: np.ndarray  # before compensation
    as_left_deg: np.ndarray  # after, the campaign's surfaces
    out_of_sample_deg: np.ndarray  # after, the surfaces fitted without the row's position
    residual_lsb: np.ndarray  # as_found in LSB: the reading less the position's reference
    in_sample_lsb: np.ndarray  # as_left in LSB
    deg_per_lsb: np.ndarray  # d tilt / d a at the row's reference reading
    nominal_deg: np.ndarray  # per position (index): the tilt table's angle about this axis
    # per position: its fold keeps MIN_FOLD_LEVELS angles about this axis; the
    # out_of_sample errors of one that does not are its in-sample errors
    evaluable: np.ndarray
    reference_lsb: np.ndarray  # per position: its reference reading
    zero_reading_lsb: float


def nominal_angles(positions: tuple[str, ...]) -> dict[str, np.ndarray]:
    """Per axis, each position's tilt-table angle from its label; raises
    NoNominalAngle for a position whose log did not record them."""
    angles = {"X": [], "Y": []}
    for label in positions:
        match = _ANGLES.search(label)
        if match is None:
            raise NoNominalAngle(f"{label}: the log does not give the tilt table's angles")
        angles["X"].append(float(match["x"]))
        angles["Y"].append(float(match["y"]))
    return {axis: np.array(values) for axis, values in angles.items()}


def evaluable_positions(nominal_deg: np.ndarray, present: np.ndarray) -> np.ndarray:
    """Per position, whether the others present keep MIN_FOLD_LEVELS
    distinct angles about the axis (a fold without it then still
    determines the surface's quadratic in the acceleration)."""
    levels = np.round(nominal_deg, 2)
    evaluable = np.zeros(len(nominal_deg), dtype=bool)
    for position in np.flatnonzero(present):
        others = present.copy()
        others[position] = False
        evaluable[position] = np.unique(levels[others]).size >= MIN_FOLD_LEVELS
    return evaluable


def left_out_predictions(data: SetData, axis: str, evaluable: np.ndarray) -> np.ndarray:
    """Each row's drift as the surface fitted without the row's position
    predicts it (NaN for a position not evaluable): ``fit.fit_surface``'s
    OLS on ``fit.design``'s columns, solved per fold from the normal
    equations of every position less the left-out one's (the scaled design
    is well conditioned; as ``families.score`` does for its cross-validation)."""
    columns = design(data.temperature_c, data.acceleration[axis])
    residual = data.residual[axis]
    masks = [data.position == position for position in np.unique(data.position)]
    grams = [columns[mask].T @ columns[mask] for mask in masks]
    moments = [columns[mask].T @ residual[mask] for mask in masks]
    total_gram, total_moment = sum(grams), sum(moments)
    predictions = np.full(len(residual), np.nan)
    for position, mask, gram, moment in zip(np.unique(data.position), masks, grams, moments):
        if not evaluable[position]:
            continue
        params, *_ = np.linalg.lstsq(total_gram - gram, total_moment - moment, rcond=None)
        predictions[mask] = columns[mask] @ params
    return predictions


def _out_of_sample(data: SetData, axis: str, evaluable: np.ndarray, in_sample: np.ndarray) -> np.ndarray:
    """The rows' errors left out of sample; in sample for a position
    whose fold could not determine the surface."""
    predictions = left_out_predictions(data, axis, evaluable)
    return np.where(np.isnan(predictions), in_sample, data.residual[axis] - predictions)


def _position_references(campaign: Campaign, axis: str) -> np.ndarray:
    """Each position's reference reading of the axis (NaN for one without rows)."""
    references = np.full(len(campaign.positions), np.nan)
    for data in campaign.sets.values():
        reference = data.acceleration[axis] - data.residual[axis]
        for position in np.unique(data.position):
            references[position] = float(np.median(reference[data.position == position]))
    return references


def zero_reading(references: np.ndarray, nominal_deg: np.ndarray) -> float:
    """The axis's reading at zero tilt: the mean over positions of the
    reference reading less 1 g sin(nominal angle) (the measuring offset of
    paper section 4.1)."""
    known = np.isfinite(references)
    return float(np.mean(references[known] - LSB_PER_G * np.sin(np.radians(nominal_deg[known]))))


def _degrees(reference: np.ndarray, error_lsb: np.ndarray, zero: float) -> np.ndarray:
    return tilt_deg(reference + error_lsb - zero) - tilt_deg(reference - zero)


def axis_errors(campaign: Campaign, fits: list[SurfaceFit], axis: str, nominal_deg: np.ndarray) -> AxisErrors:
    """The axis's rows of every set it was fitted in, with their errors."""
    references = _position_references(campaign, axis)
    zero = zero_reading(references, nominal_deg)
    evaluable = evaluable_positions(nominal_deg, np.isfinite(references))
    parts: dict[str, list[np.ndarray]] = {
        name: [] for name in ("set", "pos", "t", "a", "rate", "time", "r", "in", "oos")
    }
    for set_name in SETS:
        fit = next((f for f in fits if (f.set_name, f.axis) == (set_name, axis)), None)
        if fit is None:
            continue
        data = campaign.sets[set_name]
        temperature, acceleration = data.temperature_c, data.acceleration[axis]
        rate = data.rate_c_per_s if data.rate_c_per_s is not None else np.full(len(temperature), np.nan)
        time = data.time_s if data.time_s is not None else np.full(len(temperature), np.nan)
        residual = data.residual[axis]
        for name, values in (
            ("set", np.full(len(temperature), set_name)),
            ("pos", data.position),
            ("t", temperature),
            ("a", acceleration),
            ("rate", rate),
            ("time", time),
            ("r", residual),
            ("in", residual - fit.surface.evaluate(temperature, acceleration)),
            ("oos", _out_of_sample(data, axis, evaluable, residual - fit.surface.evaluate(temperature, acceleration))),
        ):
            parts[name].append(values)
    rows = {name: np.concatenate(values) for name, values in parts.items()}
    reference = references[rows["pos"]]
    share = np.clip((reference - zero) / LSB_PER_G, -1.0 + 1e-12, 1.0 - 1e-12)
    return AxisErrors(
        axis=axis,
        set_name=rows["set"],
        position=rows["pos"],
        temperature_c=rows["t"],
        acceleration_lsb=rows["a"],
        rate_c_per_s=rows["rate"],
        time_s=rows["time"],
        as_found_deg=_degrees(reference, rows["r"], zero),
        as_left_deg=_degrees(reference, rows["in"], zero),
        out_of_sample_deg=_degrees(reference, rows["oos"], zero),
        residual_lsb=rows["r"],
        in_sample_lsb=rows["in"],
        deg_per_lsb=np.degrees(1.0 / (LSB_PER_G * np.sqrt(1.0 - share**2))),
        nominal_deg=nominal_deg,
        evaluable=evaluable,
        reference_lsb=references,
        zero_reading_lsb=zero,
    )


def tilt_allowance_deg(errors: AxisErrors) -> float:
    """How far the zero reading's conversion puts a calibration point from
    its nominal angle (the sensitivity's and the table's deviations), at
    least 0.1 deg, rounded up to 0.1 deg: the domain's margin in nominal tilt."""
    known = np.isfinite(errors.reference_lsb)
    converted = tilt_deg(errors.reference_lsb[known] - errors.zero_reading_lsb)
    largest = float(np.max(np.abs(converted - errors.nominal_deg[known])))
    return max(0.1, math.ceil(largest * 10.0 - 1e-9) / 10.0)
