"""The tilt a monitoring user reads: each axis's compensated reading as a
change from the node's installation reading, over the whole run, whichever
set the device is in (Geokon-style "zero reading" practice; the paper's
field tests, section 4.3, read the same sensor through warming and cooling).

The installation reading is each axis's median compensated reading over
INSTALLATION_WINDOW_S: the first settled minute (from ``run.SETTLE_S``
after the first row, the time a table move takes to settle in a campaign)
once the sensor's set is known, or the minute from a time the user names.
Neither the device nor the host knows which set the sensor's history left
it in at power-up; once the temperature has moved a whole transition one
way, a sensor that started in either set has crossed to the same one, as
has the device's blend (which starts halfway, lib/Compensation's
COMP_SET_POWER_UP_SHARE). A reading taken before would carry the unknown
part of the sets' difference into every later change. A row's change is its reading
less that one, in LSB, mg and degrees of tilt (``tilt_deg`` of each, so the
degrees are those of the axis's whole reading, measuring offset included).

Rows outside the certificate's domain (or, without a certificate, outside
the coefficients' fitted range) are counted apart and left out of every
percentile: the certificate says nothing of them. With a certificate, each
row's change is also held against the certificate's U for it: at the
installation reading's temperature and the row's own temperature and tilt
(``certificate.u95_at``); none where the installation is outside the
certificate's domain.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..lsm9ds0 import MG_PER_LSB, tilt_deg
from ..run import SETTLE_S
from ..set_blend import FIRMWARE_TRANSITION_C, warming_shares
from .dataset import FIT_AXES, CalibrationDataError

# A switch between the sets is measured as the change of the compensated
# reading from the median of the SWITCH_WINDOW_S before it to the median of
# the SWITCH_WINDOW_S after it, each SWITCH_GAP_S away from the switch
# (where the Kalman filter's ~10 s settle), with at least SWITCH_MIN_ROWS rows
# on each side and no other switch in between.
SWITCH_WINDOW_S = 60.0
SWITCH_GAP_S = 30.0
SWITCH_MIN_ROWS = 10
INSTALLATION_WINDOW_S = 60.0
CHANGE_PERCENTILE = 95.0
# Fewer rows than this in the installation minute is no reading to hold a run against.
INSTALLATION_MIN_ROWS = 10


@dataclass(frozen=True)
class Installation:
    """The reading the changes are taken from: its minute and each axis's median."""

    start_s: float
    end_s: float
    rows: int
    temperature_c: float
    reading_lsb: dict[str, float]
    named: bool  # the user named its time (--baseline)
    set_decided: bool  # the sensor's set was known by then (set_decided_s)


@dataclass(frozen=True)
class AxisChange:
    axis: str
    rows: int  # inside the domain: the rows every figure is of
    outside_rows: int
    p95_lsb: float | None
    p95_mg: float | None
    p95_deg: float | None
    max_deg: float | None
    # The share of the rows whose change is within the certificate's U for it.
    within_u_share: float | None
    # The certificate's U at the run's rows, the largest: what the run is held to.
    u95_max_deg: float | None = None


@dataclass(frozen=True)
class TiltChange:
    installation: Installation
    axes: list[AxisChange]
    p95_deg: float | None  # X and Y pooled
    within_u_share: float | None  # X and Y pooled
    domain: str  # what decided the rows outside
    before_rows: int  # before the installation reading: in no figure
    # Per axis, each row's change in degrees (NaN outside the domain), and the
    # certificate's U there (None without one), for figures.
    change_deg: dict[str, np.ndarray]
    u95_deg: dict[str, np.ndarray] | None = None

    def axis(self, name: str) -> AxisChange:
        return next(change for change in self.axes if change.axis == name)

    def document(self) -> dict[str, object]:
        return {
            "installation": {
                "start_s": self.installation.start_s,
                "end_s": self.installation.end_s,
                "rows": self.installation.rows,
                "temperature_c": self.installation.temperature_c,
                "reading_lsb": self.installation.reading_lsb,
                "named": self.installation.named,
                "set_decided": self.installation.set_decided,
            },
            "domain": self.domain,
            "rows_before_installation": self.before_rows,
            "tilt_change_p95_deg": self.p95_deg,
            "rows_within_u_share": self.within_u_share,
            "axes": [vars(change) for change in self.axes],
        }


@dataclass(frozen=True)
class SetSwitch:
    """The device changed its set at time_s: the compensated reading's step
    there per axis (after minus before), in LSB and in degrees of tilt."""

    time_s: float
    to_set: str
    step_lsb: dict[str, float]
    step_deg: dict[str, float]


def set_switches(time_s: np.ndarray, sets: np.ndarray, compensated: dict[str, np.ndarray]) -> list[SetSwitch]:
    """Each change of the device's set that has SWITCH_MIN_ROWS rows in both
    of its windows and no other change between them, with the compensated
    reading's step there (SWITCH_WINDOW_S, SWITCH_GAP_S)."""
    changes = np.flatnonzero(sets[1:] != sets[:-1]) + 1
    change_times = time_s[changes]
    reach = SWITCH_GAP_S + SWITCH_WINDOW_S
    switches = []
    for index, at in zip(changes, change_times):
        if np.count_nonzero(np.abs(change_times - at) <= reach) > 1:
            continue
        before = (time_s >= at - reach) & (time_s < at - SWITCH_GAP_S)
        after = (time_s > at + SWITCH_GAP_S) & (time_s <= at + reach)
        if min(np.count_nonzero(before), np.count_nonzero(after)) < SWITCH_MIN_ROWS:
            continue
        levels = {axis: (np.median(values[before]), np.median(values[after])) for axis, values in compensated.items()}
        switches.append(
            SetSwitch(
                float(at),
                str(sets[index]),
                {axis: float(late - early) for axis, (early, late) in levels.items()},
                {
                    axis: float(tilt_deg(np.array(late)) - tilt_deg(np.array(early)))
                    for axis, (early, late) in levels.items()
                },
            )
        )
    return switches


def set_decided_s(time_s: np.ndarray, temperature_c: np.ndarray) -> float | None:
    """When the sensor's set became known after the device's power-up at
    the first row: when the device's stop operator (lib/Compensation
    SetBlend on the filtered temperature) started from the warming set and
    from the cooling set first agree; None if they never do."""
    start = float(temperature_c[0])
    from_cooling = warming_shares(FIRMWARE_TRANSITION_C, start, temperature_c, 0.0)
    from_warming = warming_shares(FIRMWARE_TRANSITION_C, start, temperature_c, 1.0)
    decided = np.flatnonzero(from_cooling == from_warming)
    return float(time_s[decided[0]]) if decided.size else None


def installation(
    time_s: np.ndarray,
    temperature_c: np.ndarray,
    compensated: dict[str, np.ndarray],
    baseline_s: float | None,
    decided_s: float | None = None,
) -> Installation | None:
    """The installation reading: the minute from baseline_s, or from
    SETTLE_S after the first row or from decided_s (when the sensor's set
    became known; None never), whichever is later (None where the run has no
    such minute; a named minute without rows is an error)."""
    start = float(baseline_s) if baseline_s is not None else float(time_s[0] + SETTLE_S)
    if baseline_s is None and decided_s is not None:
        start = max(start, decided_s)
    end = start + INSTALLATION_WINDOW_S
    minute = (time_s >= start) & (time_s < end)
    if np.count_nonzero(minute) < INSTALLATION_MIN_ROWS:
        if baseline_s is None:
            return None
        raise CalibrationDataError(
            f"--baseline {baseline_s:g}: {np.count_nonzero(minute)} rows in {start:g}..{end:g} s, the installation reading "
            f"needs {INSTALLATION_MIN_ROWS} (the run's rows span {time_s[0]:g}..{time_s[-1]:g} s)"
        )
    return Installation(
        start,
        end,
        int(np.count_nonzero(minute)),
        float(np.median(temperature_c[minute])),
        {axis: float(np.median(values[minute])) for axis, values in compensated.items()},
        baseline_s is not None,
        decided_s is not None and decided_s <= start,
    )


def _percentile(values: np.ndarray) -> float | None:
    return float(np.percentile(np.abs(values), CHANGE_PERCENTILE)) if len(values) else None


def tilt_change(
    time_s: np.ndarray,
    temperature_c: np.ndarray,
    compensated: dict[str, np.ndarray],
    outside: dict[str, np.ndarray],
    baseline_s: float | None,
    u95_for: Callable[[float], dict[str, np.ndarray]] | None,
    domain: str,
) -> TiltChange | None:
    """The change of each axis's compensated reading from the installation
    reading, over the rows from it on. outside: per axis, the rows outside
    the domain (domain says whose); u95_for: given the installation
    reading's temperature, per axis the certificate's U of each row's change
    (None without a certificate; NaN where it states none). None where the
    run has no settled minute."""
    reference = installation(time_s, temperature_c, compensated, baseline_s, set_decided_s(time_s, temperature_c))
    if reference is None:
        return None
    u95_deg = u95_for(reference.temperature_c) if u95_for is not None else None
    # The rows before the installation reading are no change a user reads.
    installed = time_s >= reference.start_s
    axes, change_deg, pooled, pooled_within = [], {}, [], []
    for axis in FIT_AXES:
        inside = ~outside[axis] & installed
        change_lsb = compensated[axis] - reference.reading_lsb[axis]
        degrees = tilt_deg(compensated[axis]) - float(tilt_deg(np.array(reference.reading_lsb[axis])))
        change_deg[axis] = np.where(inside, degrees, np.nan)
        within = largest_u95 = None
        stated = inside & np.isfinite(u95_deg[axis]) if u95_deg is not None else np.zeros_like(inside)
        if stated.any():
            held = np.abs(degrees[stated]) <= u95_deg[axis][stated]
            pooled_within.append(held)
            within = float(np.mean(held))
            largest_u95 = float(np.max(u95_deg[axis][stated]))
        pooled.append(degrees[inside])
        p95_lsb = _percentile(change_lsb[inside])
        axes.append(
            AxisChange(
                axis,
                int(np.count_nonzero(inside)),
                int(np.count_nonzero(outside[axis] & installed)),
                p95_lsb,
                None if p95_lsb is None else p95_lsb * MG_PER_LSB,
                _percentile(degrees[inside]),
                float(np.max(np.abs(degrees[inside]))) if inside.any() else None,
                within,
                largest_u95,
            )
        )
    return TiltChange(
        reference,
        axes,
        _percentile(np.concatenate(pooled)),
        float(np.mean(np.concatenate(pooled_within))) if pooled_within else None,
        domain,
        int(np.count_nonzero(~installed)),
        change_deg,
        u95_deg,
    )


def format_tilt_change(change: TiltChange) -> str:
    """The table a monitoring user reads: per axis the rows, the 95th
    percentile of the change (LSB, mg, degrees), the largest, and the share
    within the certificate's U."""

    def shown(value: float | None, form: str) -> str:
        return "n/a" if value is None else format(value, form)

    reference = change.installation
    how = "named" if reference.named else "the first settled minute once the sensor's set was known"
    if not reference.set_decided:
        how += f" (it was not: the temperature had not moved {FIRMWARE_TRANSITION_C:g} degC one way)"
    lines = [
        f"change of tilt from the installation reading ({how}: {reference.start_s:g}..{reference.end_s:g} s, "
        f"{reference.rows} rows, IMU {reference.temperature_c:.1f} degC), rows from it on ({change.before_rows} before "
        f"it left out) inside {change.domain}:",
        f"{'axis':<6}{'rows':>8}{'outside':>9}{'p95 LSB':>10}{'p95 mg':>9}{'p95 deg':>10}{'max deg':>10}"
        f"{'U deg':>8}{'within U':>10}",
    ]
    for axis in change.axes:
        lines.append(
            f"{axis.axis:<6}{axis.rows:>8}{axis.outside_rows:>9}{shown(axis.p95_lsb, '.1f'):>10}"
            f"{shown(axis.p95_mg, '.2f'):>9}{shown(axis.p95_deg, '.4f'):>10}{shown(axis.max_deg, '.4f'):>10}"
            f"{shown(axis.u95_max_deg, '#.2g'):>8}"
            f"{shown(None if axis.within_u_share is None else 100 * axis.within_u_share, '.1f'):>9}"
            + ("%" if axis.within_u_share is not None else "")
        )
    pooled = f"X and Y: p95 {shown(change.p95_deg, '.4f')} deg"
    if change.within_u_share is not None:
        pooled += f", {100 * change.within_u_share:.1f} % of rows within the certificate's U at their conditions"
    elif change.u95_deg is not None:
        pooled += (
            f"; the certificate states no U for an installation reading at {reference.temperature_c:.1f} degC "
            "(outside its domain)"
        )
    lines.append(pooled)
    return "\n".join(lines)
