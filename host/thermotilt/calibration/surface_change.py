"""How a sensor's drift surfaces changed between two of its calibrations:
f_new - f_old of one set and axis on compare's grid over the domain both
fits calibrated (the intersection of their temperature ranges, within
-10..45 degC as compare takes them, and of their acceleration ranges), in
LSB and in degrees of tilt (tilt_deg at each grid point's acceleration).
``thermotilt history`` shows it; the certificate of the newer calibration
takes its long-term stability component from it (``stability_bound``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np

from ..lsm9ds0 import tilt_deg
from ..surfaces import Surface
from .compare import calibrated_domain, domain_grid


class Fitted(Protocol):
    """A fitted surface and the domain it saw: fit.SurfaceFit or compare.FittedSurface."""

    surface: Surface
    temperature_range_c: tuple[float, float]
    acceleration_range_lsb: tuple[float, float]


@dataclass(frozen=True)
class SurfaceChange:
    """f_new - f_old of one set and axis over the common domain; largest is
    the value of greatest magnitude, with its sign. The grid's values are
    for figures and the stability bound."""

    surface: str
    temperature_c: tuple[float, float]
    acceleration_lsb: tuple[float, float]
    rms_lsb: float
    largest_lsb: float
    rms_deg: float
    largest_deg: float
    grid_deg: np.ndarray = field(repr=False, compare=False)

    def document(self) -> dict[str, Any]:
        return {name: value for name, value in asdict(self).items() if name not in ("surface", "grid_deg")}


def surface_change(key: str, old: Fitted, new: Fitted) -> SurfaceChange | None:
    """new - old over their common domain; None where they share none."""
    temperature_c = _intersection(calibrated_domain(old), calibrated_domain(new))
    acceleration_lsb = _intersection(old.acceleration_range_lsb, new.acceleration_range_lsb)
    if temperature_c is None or acceleration_lsb is None:
        return None
    temperature, acceleration = domain_grid(temperature_c, acceleration_lsb)
    change_lsb = new.surface.evaluate(temperature, acceleration) - old.surface.evaluate(temperature, acceleration)
    change_deg = tilt_deg(acceleration + change_lsb) - tilt_deg(acceleration)
    return SurfaceChange(
        key,
        temperature_c,
        acceleration_lsb,
        _rms(change_lsb),
        _largest(change_lsb),
        _rms(change_deg),
        _largest(change_deg),
        change_deg,
    )


def stability_bound(changes: list[SurfaceChange]) -> float:
    """The largest change of a change-of-tilt reading that the surfaces'
    change between the calibrations makes, degrees: a reading and its
    installation reading at one tilt, each in either set anywhere in the
    common temperature domain, differ by grid_deg between those two points,
    so the bound is the widest spread of grid_deg over temperature and sets
    at one acceleration (a change the same everywhere cancels in a change
    from installation). The sets' grids share their acceleration rows
    where their domains agree; else each set's own spread is taken."""
    grids = [change.grid_deg for change in changes]
    if not grids:
        return 0.0
    if all(grid.shape == grids[0].shape for grid in grids) and len({c.acceleration_lsb for c in changes}) == 1:
        stacked = np.concatenate(grids, axis=1)
        return float(np.max(np.ptp(stacked, axis=1)))
    return max(float(np.max(np.ptp(grid, axis=1))) for grid in grids)


def _intersection(first: tuple[float, float], second: tuple[float, float]) -> tuple[float, float] | None:
    low, high = max(first[0], second[0]), min(first[1], second[1])
    return (low, high) if low < high else None


def _rms(values: np.ndarray) -> float:
    return float(np.sqrt(np.mean(values**2)))


def _largest(values: np.ndarray) -> float:
    return float(values.flat[np.argmax(np.abs(values))])
