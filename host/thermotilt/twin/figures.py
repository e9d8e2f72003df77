"""Figures of a run log compared with the paper: the chamber's step response
(Figure 8) and the accelerometer's drift and its compensation (section 4.1).

Everything here reads run.csv columns the firmware produced, so the same
figures come from the twin and from a real rig.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..run.log import RunColumns

# Figure 8 is read over the last third of a one-minute step: the settled value.
SETTLED_WINDOW_S = 20.0
# A step is complete once 90 % of the change between two settled holds is done.
COMPLETION_FRACTION = 0.9

# What the paper reports (section 3.1, Figure 8); how far the twin may be from
# it is asserted in host/tests/test_figure8.py.
PAPER_STEP_TIME_S = 13.0
PAPER_OFFSET_C = 0.5


@dataclass(frozen=True)
class Hold:
    setpoint_c: float
    start_s: float
    end_s: float
    settled_c: float

    @property
    def offset_c(self) -> float:
        """Programmed minus measured, once settled, as the paper states it:
        negative below the outside temperature, positive above."""
        return self.setpoint_c - self.settled_c


@dataclass(frozen=True)
class StepResponse:
    from_c: float
    to_c: float
    completion_s: float
    overshoot_c: float


def holds(log: RunColumns) -> list[Hold]:
    """Consecutive rows with the same programmed temperature; the last one
    counts only if it lasted long enough to settle."""
    time_s = log.numbers["time_s"]
    setpoint = log.numbers["setpoint_c"]
    chamber = log.numbers["chamber_c"]
    found: list[Hold] = []
    start = 0
    for index in range(1, log.rows + 1):
        if index < log.rows and setpoint[index] == setpoint[start]:
            continue
        if not np.isnan(setpoint[start]):
            window = (time_s >= time_s[index - 1] - SETTLED_WINDOW_S) & (time_s <= time_s[index - 1])
            window[:start] = False
            found.append(
                Hold(
                    float(setpoint[start]),
                    float(time_s[start]),
                    float(time_s[index - 1]),
                    float(np.nanmean(chamber[window])),
                )
            )
        start = index
    return [hold for hold in found if hold.end_s - hold.start_s >= 2 * SETTLED_WINDOW_S]


def step_responses(log: RunColumns) -> list[StepResponse]:
    """How long each change between two settled holds took, and how far the
    chamber went past its new settled value."""
    time_s = log.numbers["time_s"]
    chamber = log.numbers["chamber_c"]
    found = []
    settled = holds(log)
    for before, after in zip(settled, settled[1:]):
        in_step = (time_s >= after.start_s) & (time_s <= after.end_s)
        change = after.settled_c - before.settled_c
        progress = (chamber[in_step] - before.settled_c) / change
        done = np.nonzero(progress >= COMPLETION_FRACTION)[0]
        completion = float(time_s[in_step][done[0]] - after.start_s) if done.size else float("nan")
        beyond = np.sign(change) * (chamber[in_step] - after.settled_c)
        found.append(StepResponse(before.setpoint_c, after.setpoint_c, completion, float(max(0.0, np.nanmax(beyond)))))
    return found


def warming_rows(log: RunColumns) -> RunColumns:
    """Figure 8 is a warming experiment: its steps are the program's warming phase."""
    return log.where(log.texts["phase"] == "W")


def ambient_of(log: RunColumns) -> float:
    return float(np.nanmedian(log.numbers["ambient_c"]))


def crossing_step(steps: list[StepResponse], ambient_c: float) -> StepResponse | None:
    """The step whose setpoints lie on both sides of the outside temperature."""
    for step in steps:
        if min(step.from_c, step.to_c) < ambient_c < max(step.from_c, step.to_c):
            return step
    return None


def imu_temperature_offset_c(log: RunColumns) -> float:
    """The LSM9DS0's reading minus the chamber's, over the settled part of the holds."""
    time_s = log.numbers["time_s"]
    settled = np.zeros(log.rows, dtype=bool)
    for hold in holds(log):
        settled |= (time_s >= hold.end_s - SETTLED_WINDOW_S) & (time_s <= hold.end_s)
    return float(np.nanmean(log.numbers["imu_temp_c"][settled] - log.numbers["chamber_c"][settled]))


def fig8_figures(log: RunColumns) -> dict:
    """Figure 8's numbers from the warming steps: step times, settled offsets
    (programmed - measured), overshoots, the crossing of the outside
    temperature and the IMU's temperature offset."""
    warming = warming_rows(log)
    ambient = ambient_of(warming)
    steps = step_responses(warming)
    crossing = crossing_step(steps, ambient)
    others = [step.overshoot_c for step in steps if step is not crossing]
    settled = holds(warming)
    return {
        "ambient_c": round(ambient, 2),
        "holds": [
            {"setpoint_c": hold.setpoint_c, "settled_c": round(hold.settled_c, 3), "offset_c": round(hold.offset_c, 3)}
            for hold in settled
        ],
        "steps": [
            {
                "from_c": step.from_c,
                "to_c": step.to_c,
                "completion_s": round(step.completion_s, 2),
                "overshoot_c": round(step.overshoot_c, 3),
            }
            for step in steps
        ],
        "crossing_overshoot_c": None if crossing is None else round(crossing.overshoot_c, 3),
        "other_overshoot_c": round(max(others), 3) if others else None,
        "imu_temperature_offset_c": round(imu_temperature_offset_c(warming), 2) if settled else None,
    }


def fig8_table(figures: dict) -> list[str]:
    """Figure 8's four features beside the paper's statements."""

    def listed(values, form, unit):
        return ", ".join(format(value, form) for value in values) + f" {unit}"

    if not figures["holds"]:
        return [
            f"Figure 8: no hold lasted {2 * SETTLED_WINDOW_S:g} s, too short to settle; its features "
            f"need --hold-seconds of at least {2 * SETTLED_WINDOW_S:g}"
        ]
    below = [hold["offset_c"] for hold in figures["holds"] if hold["setpoint_c"] < figures["ambient_c"]]
    above = [hold["offset_c"] for hold in figures["holds"] if hold["setpoint_c"] > figures["ambient_c"]]
    crossing = figures["crossing_overshoot_c"]
    features = [
        (
            "(a) 2 degC step time",
            f"about {PAPER_STEP_TIME_S:g} s",
            listed([step["completion_s"] for step in figures["steps"]], ".1f", "s"),
        ),
        ("(b) offset below outside", f"about -{PAPER_OFFSET_C:g} degC", listed(below, "+.2f", "degC")),
        ("    offset above outside", f"about +{PAPER_OFFSET_C:g} degC", listed(above, "+.2f", "degC")),
        (
            "(c) overshoot, crossing",
            "a transient overshoot",
            "no crossing step"
            if crossing is None
            else f"{crossing:.2f} degC (others at most {figures['other_overshoot_c']:.2f})",
        ),
        ("(d) IMU temperature offset", "consistently negative", f"{figures['imu_temperature_offset_c']:+.2f} degC"),
    ]
    lines = [f"Figure 8 (outside {figures['ambient_c']:g} degC; offsets programmed - measured)"]
    lines += [f"{feature:<28} paper: {paper:<22} run: {measured}" for feature, paper, measured in features]
    return lines


def settled_mask(log: RunColumns, settled_fraction: float = 0.5) -> np.ndarray:
    """The rows in the last settled_fraction of every hold."""
    time_s = log.numbers["time_s"]
    settled = np.zeros(log.rows, dtype=bool)
    for hold in holds(log):
        begin = hold.end_s - (hold.end_s - hold.start_s) * settled_fraction
        settled |= (time_s >= begin) & (time_s <= hold.end_s)
    return settled


def drift_figures(log: RunColumns, settled_fraction: float = 0.5) -> dict:
    """Per axis, over the settled part of every hold: how far the filtered
    raw output and the compensated output move (max - min, LSB)."""
    settled = settled_mask(log, settled_fraction)
    temperature = log.numbers["imu_temp_c"][settled]
    figures = {
        "samples": int(settled.sum()),
        "imu_temp_range_c": [round(float(np.nanmin(temperature)), 2), round(float(np.nanmax(temperature)), 2)],
    }
    for axis in ("x", "y"):
        raw = log.numbers[f"a{axis}_filt"][settled]
        compensated = log.numbers[f"a{axis}_comp"][settled]
        figures[axis] = {
            "raw_span_lsb": round(float(np.nanmax(raw) - np.nanmin(raw)), 1),
            "compensated_span_lsb": round(float(np.nanmax(compensated) - np.nanmin(compensated)), 1),
        }
    return figures


def figure8_lines(log: RunColumns) -> list[str]:
    """Figure 8's holds, steps and features beside the paper's, as lines to print."""
    figures = fig8_figures(log)
    lines = [
        f"hold {hold['setpoint_c']:g} degC: settled {hold['settled_c']:.2f}, "
        f"offset (programmed - measured) {hold['offset_c']:+.2f} degC"
        for hold in figures["holds"]
    ]
    lines += [
        f"step {step['from_c']:g} -> {step['to_c']:g} degC: {step['completion_s']:.1f} s, "
        f"overshoot {step['overshoot_c']:.2f} degC"
        for step in figures["steps"]
    ]
    return lines + fig8_table(figures)


def drift_lines(log: RunColumns) -> list[str]:
    """Section 4.1's drift and what compensation leaves of it, as lines to
    print; none for holds shorter than the settling window (no drift to measure)."""
    if not holds(log):
        return []
    figures = drift_figures(log)
    return [
        f"{axis.upper()}: raw drift {figures[axis]['raw_span_lsb']:.0f} LSB, "
        f"compensated {figures[axis]['compensated_span_lsb']:.0f} LSB"
        for axis in ("x", "y")
    ]
