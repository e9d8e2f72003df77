"""The field benchmark's page from its record (field_bench.py): the share of
field runs whose 95th percentile of the tilt change lies within the
certificate's U, overall, per profile, per tilt and per cell, each with its
Wilson 95 % interval (statsmodels' proportion_confint), the pooled share of
rows within U, the largest misses, and the figure beside them
(docs/benchmarks/field-accuracy.md). Everything is computed from the
record's rows; nothing is typed in."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from ..record import Share as RunShare
from .certificate.budget import two_significant_text
from .field_bench import NO, YES
from .field_replay import FIELD_PROFILES

# What the product aims at: most runs within U, but not all (a U that holds
# every run is padded), and not every row (each row is held against its own
# U, so some should fall outside).
RUNS_WITHIN_TARGET = (0.90, 0.99)
ROWS_WITHIN_MAX = 0.99
LARGEST_MISSES = 10
BEGIN = "<!-- bench-field: make bench-field writes from here on, from docs/benchmarks/field-runs.csv -->"
END = "<!-- /bench-field -->"

Row = dict[str, str]


class Share(RunShare):
    def __str__(self) -> str:
        return self.shown(_percent)


def _percent(share: float, decimals: int = 1) -> str:
    return f"{share:.{decimals}%}"


def judged(rows: list[Row]) -> list[Row]:
    """The runs with a verdict: a p95 and a U (in-domain rows after the installation minute)."""
    return [row for row in rows if row["within"] in (YES, NO)]


def runs_within(rows: list[Row]) -> Share:
    rows = judged(rows)
    return Share(sum(row["within"] == YES for row in rows), len(rows))


def rows_within(rows: list[Row], column: str = "rows_within_share") -> float | None:
    """The share of in-domain rows within U, pooled over runs (each row
    against its own U); column, another column of such shares."""
    counted = [(float(row[column]), int(row["rows"])) for row in rows if row.get(column)]
    total = sum(count for _, count in counted)
    return sum(share * count for share, count in counted) / total if total else None


def ratio(row: Row) -> float:
    """p95 change over the run's U."""
    return float(row["p95_change_deg"]) / float(row["u95_deg"])


def _axis_ratio(row: Row, axis: str) -> float | None:
    p95, u95 = row[f"p95_{axis}_deg"], row[f"u95_{axis}_deg"]
    return float(p95) / float(u95) if p95 and u95 else None


def binding_axis(row: Row) -> str:
    """The axis whose p95 is the larger share of its own U."""
    ratios = {axis.upper(): _axis_ratio(row, axis) for axis in ("x", "y")}
    known = {axis: value for axis, value in ratios.items() if value is not None}
    return max(known, key=known.get) if known else "–"


def _both_axes_within(row: Row) -> bool:
    return all((_axis_ratio(row, axis) or 0.0) <= 1.0 for axis in ("x", "y"))


def _met(share: Share) -> str:
    if not share.runs:
        return "–"
    low, high = RUNS_WITHIN_TARGET
    if share.share < low:
        return "**missed: below**"
    return "**missed: above**" if share.share > high else "met"


def _groups(rows: list[Row], key: Callable[[Row], str], order: Iterable[str]) -> list[tuple[str, list[Row]]]:
    return [
        (name, [row for row in rows if key(row) == name]) for name in order if any(key(row) == name for row in rows)
    ]


def _median(values: list[float]) -> str:
    return f"{np.median(values):.2f}" if values else "–"


def _largest_row_ratio(rows: list[Row]) -> str:
    """The largest change of a row over its run's U, over the runs."""
    ratios = [float(row["max_change_deg"]) / float(row["u95_deg"]) for row in judged(rows) if row["max_change_deg"]]
    return f"{max(ratios):.2f}" if ratios else "–"


def _group_table(title: str, groups: list[tuple[str, list[Row]]]) -> list[str]:
    lines = [
        f"| {title} | runs within U | target | rows within U (pooled) | median p95 / U | largest p95 / U "
        "| largest row change / U |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, rows in groups:
        share = runs_within(rows)
        ratios = [ratio(row) for row in judged(rows)]
        pooled = rows_within(rows)
        lines.append(
            f"| {name} | {share} | {_met(share)} | {'–' if pooled is None else _percent(pooled, 2)} "
            f"| {_median(ratios)} | {f'{max(ratios):.2f}' if ratios else '–'} | {_largest_row_ratio(rows)} |"
        )
    return lines + [""]


def _order(rows: list[Row]) -> tuple[list[str], list[str], list[str]]:
    present = set(row["profile"] for row in rows)
    profiles = [p for p in FIELD_PROFILES if p in present] + sorted(present - set(FIELD_PROFILES))
    tilts = sorted({row["tilt_deg"] for row in rows}, key=float)
    sensors = sorted({row["sensor"] for row in rows})
    return profiles, tilts, sensors


def _cell_table(rows: list[Row], profiles: list[str], tilts: list[str]) -> list[str]:
    lines = [
        "| profile | " + " | ".join(f"{tilt}°" for tilt in tilts) + " |",
        "|---|" + "---|" * len(tilts),
    ]
    for profile in profiles:
        cells = []
        for tilt in tilts:
            share = runs_within([row for row in rows if row["profile"] == profile and row["tilt_deg"] == tilt])
            low = RUNS_WITHIN_TARGET[0]
            cells.append(f"**{share}**" if share.runs and share.share < low else str(share))
        lines.append(f"| {profile} | " + " | ".join(cells) + " |")
    return lines + [""]


def _sensor_table(rows: list[Row], sensors: list[str]) -> list[str]:
    lines = [
        "| sensor | certificate's largest U (deg) | runs within U | median p95 / U | misses by axis |",
        "|---|---|---|---|---|",
    ]
    for sensor in sensors:
        mine = [row for row in rows if row["sensor"] == sensor]
        misses = [binding_axis(row) for row in judged(mine) if row["within"] == NO]
        by_axis = ", ".join(f"{axis} {misses.count(axis)}" for axis in sorted(set(misses))) or "–"
        lines.append(
            f"| {sensor} | {two_significant_text(float(mine[0]['certificate_u95_deg']))} | {runs_within(mine)} "
            f"| {_median([ratio(row) for row in judged(mine)])} | {by_axis} |"
        )
    return lines + [""]


def _misses_table(rows: list[Row]) -> list[str]:
    misses = sorted((row for row in judged(rows) if row["within"] == NO), key=ratio, reverse=True)
    if not misses:
        return [*_margin_lines(rows), ""]
    lines = [
        f"The largest misses ({min(len(misses), LARGEST_MISSES)} of {len(misses)}), by p95 / U: the axis whose "
        "p95 is the larger share of its own U, the IMU's temperature span, the share of rows outside the "
        "certificate's domain, and how often the device changed its set of surfaces.",
        "",
        "| run | p95 (deg) | U (deg) | p95 / U | axis | X p95 / U | Y p95 / U | IMU °C | outside | set changes | rows within U |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in misses[:LARGEST_MISSES]:
        x, y = _axis_ratio(row, "x"), _axis_ratio(row, "y")
        total = int(row["rows"]) + int(row["outside_rows"])
        lines.append(
            f"| {row['key']} | {float(row['p95_change_deg']):.4f} | {float(row['u95_deg']):.4f} | {ratio(row):.2f} "
            f"| {binding_axis(row)} | {'–' if x is None else f'{x:.2f}'} | {'–' if y is None else f'{y:.2f}'} "
            f"| {float(row['imu_min_c']):.1f}..{float(row['imu_max_c']):.1f} "
            f"| {_percent(int(row['outside_rows']) / total) if total else '–'} | {row['set_changes']} "
            f"| {_percent(float(row['rows_within_share']))} |"
        )
    return lines + [""]


def _margin_lines(rows: list[Row]) -> list[str]:
    """How far below U the runs stayed, where none missed."""
    graded = judged(rows)
    if not graded:
        return ["No run has a verdict."]
    closest = max(graded, key=ratio)
    line = f"No run's p95 change exceeds its U: the largest p95 / U is {ratio(closest):.2f} ({closest['key']})"
    changes = [row for row in graded if row["max_change_deg"]]
    if changes:
        largest = max(changes, key=lambda row: float(row["max_change_deg"]) / float(row["u95_deg"]))
        share = float(largest["max_change_deg"]) / float(largest["u95_deg"])
        line += f", and the largest change of any in-domain row {share:.2f} of its run's U ({largest['key']})"
    return [line + "."]


def _why_lines(rows: list[Row]) -> list[str]:
    """What tells the misses from the runs within U, by the record's own columns."""
    graded = judged(rows)
    misses = [row for row in graded if row["within"] == NO]
    held = [row for row in graded if row["within"] == YES]
    if not misses:
        return []
    axes = [binding_axis(row) for row in misses]

    def median_of(group: list[Row], column: str) -> str:
        return _median([float(row[column]) for row in group])

    return [
        f"Of the {len(misses)} misses, {axes.count('X')} are bound by X (the tilted axis) and {axes.count('Y')} by Y. "
        f"Median set changes: {median_of(misses, 'set_changes')} in the misses, {median_of(held, 'set_changes')} in "
        f"the runs within U; median IMU span: {_median([float(r['imu_max_c']) - float(r['imu_min_c']) for r in misses])} "
        f"against {_median([float(r['imu_max_c']) - float(r['imu_min_c']) for r in held])} °C.",
        "",
    ]


def _slope_lines(rows: list[Row], profiles: list[str]) -> list[str]:
    """The runs against the drift-slope yardstick (field_bench.slope_reference_u95),
    per profile: what a U that knew the model's mounting scatter would hold,
    and how far above it the certificate's U is."""
    graded = [row for row in judged(rows) if row.get("slope_u95_deg")]
    if not graded:
        return []
    lines = [
        "**Against the drift-slope yardstick.** A U that knew the model's mounting-to-mounting drift-slope "
        "scatter exactly and nothing else (`field_bench.slope_reference_u95`: 1.96 σ |T − T0| per axis, σ "
        "of `drift_repeatability`) leaves out noise, flicker and the set switch, so it is no bound; it shows how "
        "much of the certificate's U the scatter a field mounting brings accounts for. The ratio U / yardstick "
        "is what the calibration's estimate of that scatter (leave-one-position-out over the base's positions, "
        "Student's k at their degrees of freedom) and the budget's Type B rows add.",
        "",
        "| profile | runs within the yardstick | rows within the yardstick (pooled) | median U / yardstick |",
        "|---|---|---|---|",
    ]
    for name, mine in [*_groups(graded, lambda row: row["profile"], profiles), ("all", graded)]:
        held = Share(sum(float(r["p95_change_deg"]) <= float(r["slope_u95_deg"]) for r in mine), len(mine))
        pooled = rows_within(mine, "rows_within_slope_share")
        factor = _median([float(r["u95_deg"]) / float(r["slope_u95_deg"]) for r in mine])
        lines.append(f"| {name} | {held} | {'–' if pooled is None else _percent(pooled, 2)} | {factor} |")
    return lines + [""]


def _cost(rows: list[Row], profiles: list[str]) -> list[str]:
    seconds = [float(row["seconds"]) for row in rows if row["seconds"]]
    parts = [
        f"{profile} {np.mean([float(r['seconds']) for r in rows if r['profile'] == profile]):.1f} s"
        for profile in profiles
    ]
    return [
        f"Cost: {sum(seconds) / 60:.1f} min of worker time for the {len(rows)} runs (the mean run: "
        + ", ".join(parts)
        + "), as each run timed itself on its worker; the sensors' calibrations and the base campaign come on top.",
        "",
    ]


def _stale_lines(rows: list[Row], method: str | None) -> list[str]:
    """A notice of the rows another method made than the current one (method)."""
    stale = [row for row in rows if method is not None and row["method"] != method]
    if not stale:
        return []
    made_by = ", ".join(sorted({row["method"] for row in stale}))
    return [
        f"**Stale**: {len(stale)} of the {len(rows)} runs below were made by method {made_by}; the sources, "
        f"model and build here give {method}. `make bench-field` runs them again.",
        "",
    ]


def report(rows: list[Row], method: str | None = None) -> str:
    """The Markdown of the shares, their targets, the misses and the cost;
    with method (field_bench.method_digest), a notice of the rows another
    method made."""
    if not rows:
        return "The record holds no runs yet: `make bench-field` runs them.\n"
    profiles, tilts, sensors = _order(rows)
    overall = runs_within(rows)
    pooled = rows_within(rows)
    unjudged = len(rows) - len(judged(rows))
    both = Share(sum(_both_axes_within(row) for row in judged(rows)), len(judged(rows)))
    lines = [
        *_stale_lines(rows, method),
        f"{len(rows)} field runs: {len(sensors)} sensors × {len(profiles)} profiles × {len(tilts)} tilts about X"
        + (f"; {unjudged} without a verdict (no in-domain row after the installation minute)" if unjudged else "")
        + ". Each share with its Wilson 95 % interval.",
        "",
        "| measure | measured | target | |",
        "|---|---|---|---|",
        f"| runs whose p95 change is within U | {overall} | {RUNS_WITHIN_TARGET[0]:.0%}–{RUNS_WITHIN_TARGET[1]:.0%} "
        f"| {_met(overall)} |",
        f"| rows within U, pooled | {'–' if pooled is None else _percent(pooled, 2)} | at most {ROWS_WITHIN_MAX:.0%} "
        f"| {'–' if pooled is None else 'met' if pooled <= ROWS_WITHIN_MAX else '**missed: above**'} |",
        f"| runs with each axis's p95 within its own U | {both} | (not a target) | |",
        "",
        "The rows are not independent (10 Hz rows of a filtered reading, hours long): the pooled share of rows "
        "carries no interval; the runs are independent, their shares carry Wilson's.",
        "",
        "**By profile**",
        "",
        *_group_table("profile", _groups(rows, lambda row: row["profile"], profiles)),
        "**By tilt about X**",
        "",
        *_group_table("tilt", _groups(rows, lambda row: row["tilt_deg"], tilts)),
        "**By cell** (profile × tilt; a cell below 90 % in bold)",
        "",
        *_cell_table(rows, profiles, tilts),
        "**By sensor**",
        "",
        *_sensor_table(rows, sensors),
        "**Misses**",
        "",
        *_misses_table(rows),
        *_why_lines(rows),
        *_slope_lines(rows, profiles),
        *_cost(rows, profiles),
    ]
    return "\n".join(lines).rstrip("\n") + "\n"


def figure(rows: list[Row], path: Path) -> None:
    """Each judged run's p95 change against its U, coloured by profile, a
    marker per tilt, with the line p95 = U: a run above it misses."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    import matplotlib.pyplot as plt

    graded = judged(rows)
    profiles, tilts, _ = _order(graded) if graded else ([], [], [])
    markers = dict(zip(tilts, "os^Dv<>"))
    figure_, axes = plt.subplots(figsize=(7.0, 5.5))
    colours = plt.get_cmap("tab10")
    for index, profile in enumerate(profiles):
        for tilt in tilts:
            mine = [row for row in graded if row["profile"] == profile and row["tilt_deg"] == tilt]
            if mine:
                axes.scatter(
                    [float(row["u95_deg"]) for row in mine],
                    [float(row["p95_change_deg"]) for row in mine],
                    color=colours(index),
                    marker=markers[tilt],
                    s=28,
                    alpha=0.8,
                    label=f"{profile}, {tilt}°",
                )
    if graded:
        top = 1.15 * max(float(row[column]) for row in graded for column in ("u95_deg", "p95_change_deg"))
        axes.plot([0.0, top], [0.0, top], color="black", linewidth=1.0, label="p95 = U")
        axes.set_xlim(0.0, top)
        axes.set_ylim(0.0, top)
        axes.set_aspect("equal")
    axes.set_xlabel("U at the run's conditions (deg): the largest over its in-domain rows")
    axes.set_ylabel("p95 of the tilt change from the installation reading (deg)")
    axes.set_title("Field runs against their sensors' certificates (above the line: a miss)")
    axes.grid(True, alpha=0.3)
    axes.legend(fontsize=7, ncol=2, loc="upper left")
    figure_.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure_.savefig(path, dpi=110)
    plt.close(figure_)
