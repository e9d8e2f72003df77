"""The LSM9DS0's candidate effects: named effects the discovery workflow may
switch on (docs/discovery.md), each acting on one stage of the sensor
(SENSOR_STAGES). Off by default; each default is a plausible magnitude once
switched on."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ...surfaces import REFERENCE_C
from ..parameters import Bounds, Parameter, PerAxis
from . import SensorContext, SensorTerm, register
from .lag import first_order, first_order_series
from .sensor import OFFSET_BOUNDS, OFFSET_WHY

CANDIDATE_SOURCE = "candidate for discovery; no paper value"


@register
class SensorLag(SensorTerm):
    name = "sensor_lag"
    stage = "structure"
    enabled_by_default = False
    summary = (
        "the MEMS structure lags the temperature sensor: the drift surfaces are evaluated at "
        "a first-order lagged copy of the reported temperature (τ, starting at the first "
        "reported temperature); the temperature register keeps the reported one"
    )
    parameters = (
        Parameter(
            "time_constant_s",
            Bounds(0.0, 3600.0, "s", low_exclusive=True),
            30.0,
            CANDIDATE_SOURCE,
            "as `[die_lag]`; the LSM9DS0 is a system-in-package: its sensing element and "
            "its temperature sensor share a 4 × 4 × 1 mm package, which does not lag itself "
            "by hours",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        return first_order(self.values["time_constant_s"])

    def bind_series(self, context: SensorContext) -> Callable[..., Any] | None:
        return first_order_series(self.values["time_constant_s"]) if self.enabled else None


@register
class Hysteresis(SensorTerm):
    name = "hysteresis"
    stage = "error"
    enabled_by_default = False
    summary = (
        "a per-axis offset added as far as the sensor is in its cooling state (1 − the warming "
        "share of `[drift] set_transition_c`), beyond the surfaces' and `measuring_offset`'s two sets"
    )
    parameters = (
        Parameter(
            "cooling_offset_lsb",
            OFFSET_BOUNDS,
            {"x": 20.0, "y": 20.0, "z": 0.0},
            CANDIDATE_SOURCE,
            OFFSET_WHY,
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        cooling_x, cooling_y, cooling_z = (self.values["cooling_offset_lsb"][axis] for axis in "xyz")

        def error(
            warming_share: float, reported_c: float, rate: float, dt_s: float, mounting: int
        ) -> tuple[float, float, float]:
            cooling_share = 1.0 - warming_share
            return cooling_share * cooling_x, cooling_share * cooling_y, cooling_share * cooling_z

        return error


@register
class ScaleTempco(SensorTerm):
    name = "scale_tempco"
    stage = "scale"
    enabled_by_default = False
    summary = (
        "the scale factor depends on temperature: each axis reads a·(1 + c·(T − 25 °C)), a "
        "its ideal acceleration, c in ppm/°C, T the reported temperature"
    )
    parameters = (
        Parameter(
            "ppm_per_c",
            PerAxis(Bounds(-10000.0, 10000.0, "ppm per degC")),
            {"x": 100.0, "y": 100.0, "z": 0.0},
            CANDIDATE_SOURCE,
            "1 %/°C would change the gain by 60 % between 25 °C and the operating range's "
            "85 °C; ST's datasheets say the sensitivity \"changes very little over "
            'temperature"',
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        ppm = self.values["ppm_per_c"]
        gain_x, gain_y, gain_z = ppm["x"] * 1e-6, ppm["y"] * 1e-6, ppm["z"] * 1e-6

        def scale(reported_c: float, ideal_x: float, ideal_y: float, ideal_z: float) -> tuple[float, float, float]:
            excursion = reported_c - REFERENCE_C
            return (
                gain_x * excursion * ideal_x,
                gain_y * excursion * ideal_y,
                gain_z * excursion * ideal_z,
            )

        return scale


@register
class CrossAxis(SensorTerm):
    name = "cross_axis"
    stage = "ideal"
    enabled_by_default = False
    summary = (
        "each axis reads a share of another: x + s_x·a_y, y + s_y·a_x, z + s_z·a_x, a the "
        "ideal accelerations before this term"
    )
    parameters = (
        Parameter(
            "share",
            PerAxis(Bounds(-0.1, 0.1)),
            {"x": 0.005, "y": 0.005, "z": 0.0},
            CANDIDATE_SOURCE,
            "sin 5.7° = 0.1: a board that far askew on its mount shows by eye (the default 0.005 is 0.29°)",
        ),
    )

    def bound(self, context: SensorContext) -> Callable[..., Any]:
        shares = self.values["share"]
        share_x, share_y, share_z = shares["x"], shares["y"], shares["z"]

        def ideal(ax: float, ay: float, az: float) -> tuple[float, float, float]:
            return ax + share_x * ay, ay + share_y * ax, az + share_z * ax

        return ideal
