"""Days of weather at a monitoring site, as the air inside a closed box
outdoors follows them: the ``field-days`` scenario's ambient temperature.

Section 4.3 of the paper tests the compensation outdoors, the sensor in a
plastic black box: 9 -> 48 degC in 3 h of a March morning, 26 -> 16 degC in
a July night (section 3.3). A monitoring site sees days of that, one after
another. The profile here is built from a handful of numbers (SiteWeather,
each with its unit and source) and drawn once, when the scenario is built:

- the air: each day's mean and diurnal range drift from day to day as two
  AR(1) series; within a day a half cosine runs from the day's minimum at
  the coldest hour up to its maximum at the warmest hour and down to the
  next day's minimum (the shape of Parton & Logan 1981, cosine on both
  sides); a small coloured noise (gusts, minutes) rides on it;
- the sun: a half sine from sunrise to sunset heats the box, a cloud's
  shadow cuts it, and the day's cloud cover follows its diurnal range
  (cloudy days have small ranges: Dai, Trenberth & Karl 1999);
- the box: its inside follows air plus solar gain through one first-order
  lag, and is clipped to the calibration range (-10..45 degC).

Everything is drawn on a one-minute grid from the seed; ``ambient_c(t)``
only interpolates it (the twin asks every 10 ms of simulated time). The
same seed gives the same profile bit for bit, and a longer run continues the
same weather: the first N days of N + 1 are the N days. Time starts at
local (solar) midnight.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..program import CALIBRATION_MAX_C, CALIBRATION_MIN_C
from ..run.log import RunColumns

SECONDS_PER_DAY = 86400.0
# Fine enough for the box's 20 min lag and the gusts' 5 min; a 49-day run is 70,000 points.
GRID_S = 60.0
# The boards count time in uint32 milliseconds, which wrap after 49.7 days.
MAX_DAYS = 49.0
# A day's diurnal range drawn below this is taken as this: an overcast day still has one.
MIN_DIURNAL_RANGE_C = 1.0


@dataclass(frozen=True)
class SiteWeather:
    """A site's weather in a handful of numbers. The site and season are an
    assumption: the paper does not name its site; southern Italy in April,
    between its March morning and July night tests, represented by the
    Naples normals. Values marked "assumption" are chosen, not measured;
    docs/twin.md ("Weather at a site") lists them with their sources."""

    # degC. Naples, April: mean daily minimum 8, maximum 18 degC (rounded
    # monthly means, climieviaggi.it "Clima - Napoli"); their mean.
    daily_mean_c: float = 13.0
    # degC, daily maximum minus minimum: the same table, 18 - 8.
    diurnal_range_c: float = 10.0
    # degC, standard deviation of a day's mean about the normal. Assumption:
    # 2-3 degC is the order at a coastal mid-latitude site in spring (the
    # quantity James & Arguez 2015, J. Atmos. Oceanic Technol. 32, estimate
    # for U.S. stations, larger inland).
    daily_mean_sd_c: float = 2.5
    # degC, standard deviation of a day's diurnal range. Assumption; cloud
    # cover drives most of it (Dai, Trenberth & Karl 1999, J. Climate 12).
    diurnal_range_sd_c: float = 2.0
    # Lag-1 autocorrelation of both series from one day to the next.
    # Assumption: daily temperature anomalies persist for days (the
    # autoregressions of Campbell & Diebold 2005, JASA 100).
    day_to_day_correlation: float = 0.7
    # Local solar time, h: the minimum near sunrise, the air's maximum about
    # 2 h after solar noon at screen height (Parton & Logan 1981, Agric.
    # Meteorol. 23).
    coldest_hour: float = 6.0
    warmest_hour: float = 14.0
    # degC and s: coloured noise of the air (gusts, eddies). Assumption: a
    # few tenths of a kelvin over minutes in the surface layer (the order
    # Stull 1988, "An Introduction to Boundary Layer Meteorology", gives).
    gust_sd_c: float = 0.3
    gust_time_constant_s: float = 300.0
    # Local solar time, h: 13 h of daylight, mid-April at 41 deg N.
    sunrise_hour: float = 5.5
    sunset_hour: float = 18.5
    # K, the box's inside above the air at solar noon under a clear sky.
    # The paper's black box read 48 degC at 10 a.m. on 25 March (section
    # 3.3), some 30 K above such a morning's air; 20 K (a lighter or partly
    # shaded box) keeps a default run within the calibration range: an
    # assumption.
    clear_sky_gain_c: float = 20.0
    # Fraction of daylight under cloud on a day of normal range. Assumption:
    # about half the possible sunshine, a Mediterranean spring.
    cloud_cover: float = 0.45
    # Per degC: a day whose range is 1 degC below normal is this much
    # cloudier. Dai et al. 1999: overcast days' ranges are some 25-50 %
    # below clear days'; 40 % of 10 degC is 4 degC for cover 0 -> 1.
    cloud_cover_per_range_c: float = 0.25
    # s, mean length of a cloud's shadow on the box. Assumption: a cumulus a
    # few km across drifting at a few m/s.
    cloud_passage_s: float = 900.0
    # Fraction of the solar gain left under a cloud. Assumption: thick
    # cumulus pass some 20-40 % of the clear sky's irradiance.
    cloud_transmission: float = 0.3
    # s, the box's inside following its outside. Assumption: a small closed
    # plastic box.
    box_time_constant_s: float = 1200.0
    # degC: the inside is clipped to the range the calibration covers.
    lowest_c: float = CALIBRATION_MIN_C
    highest_c: float = CALIBRATION_MAX_C


SITE = SiteWeather()


@dataclass(frozen=True)
class WeatherDays:
    """One draw: the grid (s from the first midnight), the air, the box's
    inside, and the day-level draws (index 0 is the day before the run,
    which sets its first night, and the last is the day after it)."""

    days: float
    time_s: np.ndarray
    air_c: np.ndarray
    inside_c: np.ndarray
    daily_mean_c: np.ndarray
    diurnal_range_c: np.ndarray
    cloud_cover: np.ndarray

    def ambient_c(self, duration_s: float) -> Callable[[float], float]:
        """The inside's temperature at t s of a run that plays these days
        in duration_s: a linear interpolation on the grid, in Python floats."""
        values = self.inside_c.tolist()
        last = len(values) - 1
        step_s = GRID_S * duration_s / (self.days * SECONDS_PER_DAY)

        def ambient(t: float) -> float:
            position = min(max(float(t) / step_s, 0.0), float(last))
            index = min(int(position), last - 1)
            low = values[index]
            return low + (values[index + 1] - low) * (position - index)

        return ambient


def draw_weather(days: float, seed: int, site: SiteWeather = SITE) -> WeatherDays:
    """The weather of `days` days from local midnight, drawn from `seed`:
    a stream each for the days' means, their ranges, the clouds and the
    gusts, each drawn in time order (so that more days extend, not change)."""
    mean_rng, range_rng, cloud_rng, gust_rng = (
        np.random.default_rng(stream) for stream in np.random.SeedSequence(seed).spawn(4)
    )
    whole_days = math.ceil(days)
    mean_anomaly = _ar1(mean_rng, whole_days + 2, site.daily_mean_sd_c, site.day_to_day_correlation)
    range_anomaly = _ar1(range_rng, whole_days + 2, site.diurnal_range_sd_c, site.day_to_day_correlation)
    daily_mean = site.daily_mean_c + mean_anomaly
    diurnal_range = np.maximum(site.diurnal_range_c + range_anomaly, MIN_DIURNAL_RANGE_C)
    cover = np.clip(site.cloud_cover - site.cloud_cover_per_range_c * range_anomaly, 0.0, 1.0)
    steps = max(1, math.ceil(days * SECONDS_PER_DAY / GRID_S))
    time_s = np.arange(steps + 1) * GRID_S
    air = _diurnal_c(site, time_s, daily_mean, diurnal_range) + _ar1(
        gust_rng, len(time_s), site.gust_sd_c, math.exp(-GRID_S / site.gust_time_constant_s)
    )
    shade = _cloud_shade(site, time_s, cover[1 : whole_days + 1], cloud_rng)
    solar = site.clear_sky_gain_c * _daylight(site, time_s) * (1.0 - (1.0 - site.cloud_transmission) * shade)
    inside = np.clip(_lagged(air + solar, site.box_time_constant_s), site.lowest_c, site.highest_c)
    return WeatherDays(days, time_s, air, inside, daily_mean, diurnal_range, cover)


def _ar1(rng: np.random.Generator, count: int, sd: float, correlation: float) -> np.ndarray:
    """A stationary AR(1) series: standard deviation sd, lag-1 correlation."""
    # scipy.signal takes most of a second to import; only drawing the weather needs it.
    from scipy.signal import lfilter

    shocks = rng.standard_normal(count) * sd
    shocks[1:] *= math.sqrt(1.0 - correlation**2)
    return lfilter([1.0], [1.0, -correlation], shocks)


def _diurnal_c(site: SiteWeather, time_s: np.ndarray, mean_c: np.ndarray, range_c: np.ndarray) -> np.ndarray:
    """The air without gusts: half cosines between each day's minimum at the
    coldest hour and its maximum at the warmest, the draws' index 0 being
    the day before the run."""
    day = np.arange(len(mean_c)) - 1.0
    anchors_s = np.column_stack((day * 24 + site.coldest_hour, day * 24 + site.warmest_hour)).ravel() * 3600.0
    anchors_c = np.column_stack((mean_c - range_c / 2, mean_c + range_c / 2)).ravel()
    segment = np.searchsorted(anchors_s, time_s, side="right") - 1
    begin_s, end_s = anchors_s[segment], anchors_s[segment + 1]
    rise = (1.0 - np.cos(np.pi * (time_s - begin_s) / (end_s - begin_s))) / 2.0
    return anchors_c[segment] + (anchors_c[segment + 1] - anchors_c[segment]) * rise


def _daylight(site: SiteWeather, time_s: np.ndarray) -> np.ndarray:
    """The clear sky's solar gain as a fraction of noon's: a half sine from
    sunrise to sunset, zero at night."""
    hour = (time_s % SECONDS_PER_DAY) / 3600.0
    phase = (hour - site.sunrise_hour) / (site.sunset_hour - site.sunrise_hour)
    return np.where((phase > 0.0) & (phase < 1.0), np.sin(np.pi * np.clip(phase, 0.0, 1.0)), 0.0)


def _cloud_shade(site: SiteWeather, time_s: np.ndarray, cover: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """1 where a cloud's shadow lies on the box, 0 in sunshine: on each day
    shadows of mean length cloud_passage_s and sunny spells between them,
    both exponential, in proportion to the day's cover."""
    shade = np.zeros_like(time_s)
    midnights = np.searchsorted(time_s, np.arange(len(cover) + 1) * SECONDS_PER_DAY)
    for day, day_cover in enumerate(cover):
        within = slice(midnights[day], midnights[day + 1])
        shade[within] = _day_shade(time_s[within] - day * SECONDS_PER_DAY, float(day_cover), site.cloud_passage_s, rng)
    return shade


def _day_shade(seconds: np.ndarray, cover: float, passage_s: float, rng: np.random.Generator) -> np.ndarray:
    if cover <= 0.0 or cover >= 1.0:
        return np.full_like(seconds, cover)
    lengths = {True: passage_s, False: passage_s * (1.0 - cover) / cover}
    cloudy = bool(rng.random() < cover)
    edges, states = [0.0], []
    while edges[-1] < SECONDS_PER_DAY:
        states.append(float(cloudy))
        edges.append(edges[-1] + rng.exponential(lengths[cloudy]))
        cloudy = not cloudy
    return np.asarray(states)[np.searchsorted(edges, seconds, side="right") - 1]


def _lagged(outside_c: np.ndarray, time_constant_s: float) -> np.ndarray:
    """A first-order lag on the grid, starting level with its input."""
    from scipy.signal import lfilter

    keep = math.exp(-GRID_S / time_constant_s)
    lagged, _ = lfilter([1.0 - keep], [1.0, -keep], outside_c, zi=[keep * outside_c[0]])
    return lagged


def day_lines(columns: RunColumns, seconds_per_day: float) -> list[str]:
    """What a field-days run saw, day by day: the box's inside (ambient_c)
    and what the IMU read (imu_temp_c), lowest..highest."""
    time_s = columns.numbers["time_s"]
    inside, imu = columns.numbers["ambient_c"], columns.numbers["imu_temp_c"]
    lines = [f"field days: {_span(inside)} inside the box, the IMU read {_span(imu)}"]
    day = np.floor(time_s / seconds_per_day)
    for number in np.unique(day[np.isfinite(day)]):
        today = day == number
        lines.append(f"day {int(number) + 1}: inside {_span(inside[today])}, the IMU read {_span(imu[today])}")
    return lines


def _span(values: np.ndarray) -> str:
    known = values[np.isfinite(values)]
    if not len(known):
        return "nothing"
    return f"{known.min():.1f}..{known.max():.1f} degC"
