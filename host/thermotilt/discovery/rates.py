"""Discovery's error rates from the benchmark's record (benchmark.py): the
tables of docs/discovery.md ("Benchmark") with Wilson 95 % intervals
(statsmodels' proportion_confint) and the figure beside them. Everything
here is computed from the record's rows; nothing is typed in."""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from ..record import Share
from .bases import chamber_change, index_of, kind_of
from .benchmark import (
    AMBIGUOUS,
    COLLINEAR,
    EFFECT,
    FOUND,
    NONE,
    NOT_TESTABLE,
    NULL,
    SNRS,
    UNEXPLAINED,
    WORLD,
    default_cells,
    gap_ratio,
    named_right,
)
from .candidates import CANDIDATES
from .channel import HALF_WIDTH_95
from .noise_families import NOISE_FAMILIES
from .replay import CHAMBER_CHANNELS

# The benchmark's targets, which the tables of docs/discovery.md
# ("Benchmark") state beside each rate: the share of null runs that name
# anything, by its 95 % upper bound; the right name at SNR >= 2 and at
# SNR 1; ambiguous on the designed pairs; the true value inside the
# reported 95 % interval.
MAX_FALSE_DISCOVERY = 0.05
MIN_RIGHT_AT_2 = 0.95
MIN_RIGHT_AT_1 = 0.70
MIN_AMBIGUOUS = 0.90
# A null family whose runs leave a gap at least GAP_RATIO times what the
# declared noise allows (by the median run) must be called unexplained in
# at least MIN_UNEXPLAINED of its runs.
GAP_RATIO = 2.0
MIN_UNEXPLAINED = 0.90
# A world the model does not describe, with its gap at least GAP_RATIO:
# unexplained (no candidate can be right) at least this often, none at most
# MAX_FALSE_DISCOVERY of the time.
MIN_DIAGNOSED = 0.95
COVERAGE_RANGE = (0.90, 0.98)
ANOTHER_EFFECT = "another effect"
ANOTHER_CHANNEL = "the effect on another channel"
RIGHT_BUT_PARTIAL = "unexplained, the right name partial"
BEGIN = "<!-- bench-discovery: make bench-discovery writes from here on, from docs/benchmarks/discovery-runs.csv -->"
END = "<!-- /bench-discovery -->"

Row = dict[str, str]


class Rate(Share):
    def __str__(self) -> str:
        return self.shown(_percent)


def _percent(share: float) -> str:
    """Whole percent, with a decimal below 10 %: 1 run of 200 is 0.5 %, not 0 %."""
    return f"{share:.1%}" if 0.0005 <= share < 0.1 else f"{share:.0%}"


def rate(rows: list[Row], hit: Callable[[Row], bool]) -> Rate:
    return Rate(sum(map(hit, rows)), len(rows))


def _covered(row: Row) -> bool:
    return float(row["low"]) <= float(row["truth"]) <= float(row["high"])


def _error_in_standard_errors(rows: list[Row]) -> str:
    """Mean and spread of (value - truth) / SE over runs named right, the SE
    read back from the 95 % interval (HALF_WIDTH_95 either side): intervals
    of the right width give a spread of 1 about a mean of 0."""
    errors = []
    for row in rows:
        standard_error = (float(row["high"]) - float(row["low"])) / (2.0 * HALF_WIDTH_95)
        if standard_error > 0.0:
            errors.append((float(row["value"]) - float(row["truth"])) / standard_error)
    if len(errors) < 2:
        return "–"
    return f"{np.mean(errors):+.2f} ± {np.std(errors, ddof=1):.2f}"


def _pair_ambiguous(row: Row) -> bool:
    pair = set(row["expected_pair"].split("+"))
    return row["verdict"] == AMBIGUOUS and any(pair <= set(group.split("+")) for group in row["ambiguous"].split(";"))


def _right_target(snr: float) -> float | None:
    """The share of runs a cell at this SNR should name right, if any."""
    return MIN_RIGHT_AT_2 if snr >= 2.0 else MIN_RIGHT_AT_1 if snr >= 1.0 else None


def _missed_by(row: Row) -> str:
    """What a run that did not name its hidden effect said instead."""
    if row["verdict"] == FOUND:
        return ANOTHER_EFFECT if row["named"] != row["effect"] else ANOTHER_CHANNEL
    if _partial(row) and row["named"] == row["effect"]:
        return RIGHT_BUT_PARTIAL
    return row["verdict"]


def _partial(row: Row) -> bool:
    """Called unexplained after naming an effect: the name explains a part
    of the gap only."""
    return row["verdict"] == UNEXPLAINED and bool(row["named"])


def _partial_names(rows: list[Row]) -> str:
    """How many runs named an effect as partial, and which."""
    partial = [r for r in rows if _partial(r)]
    names = ", ".join(sorted({r["named"] for r in partial}))
    return f"{len(partial)} ({names})" if partial else "0"


def _met(measured: Rate, ok: bool) -> str:
    if not measured.runs:
        return "–"
    return "met" if ok else "**missed**"


def report(rows: list[Row], base_seconds: Mapping[str, float] | None = None) -> str:
    """The Markdown of the rates, their targets and what the runs cost;
    base_seconds: what making each base took, where known."""
    null = [r for r in rows if r["kind"] == NULL]
    effect = [r for r in rows if r["kind"] == EFFECT]
    collinear = [r for r in rows if r["kind"] == COLLINEAR]
    world = [r for r in rows if r["kind"] == WORLD]
    lines = [
        f"{len(rows)} runs: {len(null)} null, {len(effect)} with a hidden effect, {len(collinear)} on collinear pairs, "
        f"{len(world)} in worlds the model does not describe; each rate with its Wilson 95 % interval.",
        "",
        *_null_table(null),
    ]
    if effect:
        lines += _effect_table(effect) + _channel_table(effect) + _axis_table(effect) + _missed_table(effect)
    if collinear:
        lines += _collinear_table(collinear)
    if world:
        lines += _world_table(world)
    lines += _coverage_table([r for r in effect if named_right(r)])
    lines += _cost(rows, base_seconds or {})
    return "\n".join(lines) + "\n"


def _null_table(null: list[Row]) -> list[str]:
    lines = [
        "**Null runs** (nothing hidden): the share that names an effect, by noise family and base "
        f"(target: 95 % upper bound at most {MAX_FALSE_DISCOVERY:.0%} in every family), and apart from "
        "those the share called `unexplained` (a channel's gap beyond what the model's declared noise "
        "allows), of which partial: an effect named that leaves a channel far beyond it (counted apart from "
        "the names). Gap / allowed: the median run's largest ratio; where it is at least "
        f"{GAP_RATIO:g}, the target is `unexplained` in at least {MIN_UNEXPLAINED:.0%}.",
        "",
        "| noise | runs | named: staircase | named: cycle | named anything | target "
        "| unexplained: staircase | unexplained: cycle | of which partial | gap / allowed | target |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    families = [(noise, [r for r in null if r["noise"] == noise]) for noise in NOISE_FAMILIES]
    for noise, family in [*families, ("all", null)]:
        if not family:
            continue
        named = rate(family, _named)
        unexplained = rate(family, _unexplained)
        by_base = [
            [str(rate([r for r in family if kind_of(r["base"]) == kind], hit)) for kind in ("staircase", "cycle")]
            for hit in (_named, _unexplained)
        ]
        ratio = float(np.median([gap_ratio(r) for r in family]))
        asked = noise != "all" and ratio >= GAP_RATIO
        lines.append(
            f"| {noise} | {len(family)} | {by_base[0][0]} | {by_base[0][1]} | {named} | "
            f"{_met(named, named.interval[1] <= MAX_FALSE_DISCOVERY)} | {by_base[1][0]} | {by_base[1][1]} | "
            f"{_partial_names(family)} | {ratio:.2f} | {_met(unexplained, unexplained.share >= MIN_UNEXPLAINED) if asked else '–'} |"
        )
    return lines


def _named(row: Row) -> bool:
    return row["verdict"] == FOUND


def _unexplained(row: Row) -> bool:
    return row["verdict"] == UNEXPLAINED


def _effect_table(effect: list[Row]) -> list[str]:
    lines = [
        "",
        "**Hidden effects**: the share of runs whose first effect found is the hidden one (on its channel), "
        f"with the model's noise; in bold a cell below its target ({MIN_RIGHT_AT_1:.0%} at SNR 1, "
        f"{MIN_RIGHT_AT_2:.0%} at SNR 2 and 4). Covered: the true value inside the reported 95 % interval, "
        "of the candidate's runs named right; value − truth: its mean ± SD in standard errors.",
        "",
        "| candidate | " + " | ".join(f"SNR {snr:g}" for snr in SNRS) + " | not testable | covered | value − truth |",
        "|---|" + "---|" * (len(SNRS) + 3),
    ]
    short = targeted = 0
    for candidate in CANDIDATES:
        mine = [r for r in effect if r["effect"] == candidate.name]
        if not mine:
            continue
        cells = []
        for snr in SNRS:
            measured = _right_at(mine, snr)
            missed = _below_target(measured, snr)
            targeted += _right_target(snr) is not None and measured.runs > 0
            short += missed
            cells.append(f"**{measured}**" if missed else str(measured))
        untestable = sum(r["verdict"] == NOT_TESTABLE for r in mine)
        right = [r for r in mine if named_right(r)]
        covered = rate(right, _covered)
        lines.append(
            f"| `{candidate.name}` | "
            + " | ".join(cells)
            + f" | {untestable} | {covered} | {_error_in_standard_errors(right)} |"
        )
    at_2, at_1 = _right_at_2_and_1(effect)
    testable_at_2, testable_at_1 = _right_at_2_and_1([r for r in effect if r["verdict"] != NOT_TESTABLE])
    return lines + [
        f"| all | at SNR ≥ 2: {at_2} | target ≥ {MIN_RIGHT_AT_2:.0%}: {_met(at_2, at_2.share >= MIN_RIGHT_AT_2)} | "
        f"at SNR 1: {at_1} | target ≥ {MIN_RIGHT_AT_1:.0%}: {_met(at_1, at_1.share >= MIN_RIGHT_AT_1)} | | | |",
        "",
        f"Cells at their target: {targeted - short} of {targeted}. Of the runs the design lets the search test "
        f"(the targets count all): at SNR ≥ 2 {testable_at_2}, at SNR 1 {testable_at_1}.",
    ]


def _right_at(rows: list[Row], snr: float) -> Rate:
    return rate([r for r in rows if float(r["snr"]) == snr], named_right)


def _below_target(measured: Rate, snr: float) -> bool:
    target = _right_target(snr)
    return target is not None and measured.runs > 0 and measured.share < target


def _right_at_2_and_1(effect: list[Row]) -> tuple[Rate, Rate]:
    """The runs named right at SNR 2 and above, and at SNR 1."""
    return (
        rate([r for r in effect if float(r["snr"]) >= 2.0], named_right),
        rate([r for r in effect if float(r["snr"]) == 1.0], named_right),
    )


def _channel_table(effect: list[Row]) -> list[str]:
    """Power by the channel an effect was sized on, for the candidates with
    one value acting on several channels: sized on a channel where it is
    small against the noise, it is found on another, at another SNR."""
    shared = [
        c.name
        for c in CANDIDATES
        if not c.per_axis and len({r["channel"] for r in effect if r["effect"] == c.name}) > 1
    ]
    return _by_channel(
        effect,
        shared,
        "**By the channel the SNR was set on** (drawn per run), for the candidates with one value on several "
        "channels; found: where the first effect was named.",
        ("sized on", "found on"),
        lambda on: ", ".join(sorted({r["named_channel"] for r in on if named_right(r)})) or "–",
    )


def _axis_table(effect: list[Row]) -> list[str]:
    """Power by the axis a per-axis candidate was hidden on, for those with
    a cell below its target: where in the design its misses lie."""
    per_axis = [c.name for c in CANDIDATES if c.per_axis]
    short = [
        name
        for name in per_axis
        if any(_below_target(_right_at([r for r in effect if r["effect"] == name], snr), snr) for snr in SNRS)
    ]
    return _by_channel(
        effect,
        short,
        "**By the axis it was hidden on** (drawn per run), for the candidates with one value per axis and a cell "
        "below its target.",
        ("hidden on", "not testable"),
        lambda on: str(sum(r["verdict"] == NOT_TESTABLE for r in on)),
    )


def _by_channel(
    effect: list[Row], names: list[str], heading: str, columns: tuple[str, str], last: Callable[[list[Row]], str]
) -> list[str]:
    """A table of these candidates' right names per SNR, a row for each
    channel their runs were drawn on; columns: that channel's header and
    the last one's, which `last` fills from the row's runs."""
    if not names:
        return []
    channel_column, last_column = columns
    lines = [
        "",
        heading,
        "",
        f"| candidate | {channel_column} | " + " | ".join(f"SNR {snr:g}" for snr in SNRS) + f" | {last_column} |",
        "|---|---|" + "---|" * (len(SNRS) + 1),
    ]
    for name in names:
        mine = [r for r in effect if r["effect"] == name]
        for channel in sorted({r["channel"] for r in mine}):
            on = [r for r in mine if r["channel"] == channel]
            cells = " | ".join(str(_right_at(on, snr)) for snr in SNRS)
            lines.append(f"| `{name}` | {channel} | {cells} | {last(on)} |")
    return lines


def _missed_table(effect: list[Row]) -> list[str]:
    missed_rows = [r for r in effect if float(r["snr"]) >= 1.0 and not named_right(r)]
    if not missed_rows:
        return []
    answers = {_missed_by(r) for r in missed_rows}
    said = [
        a
        for a in (NONE, UNEXPLAINED, RIGHT_BUT_PARTIAL, AMBIGUOUS, NOT_TESTABLE, ANOTHER_EFFECT, ANOTHER_CHANNEL)
        if a in answers
    ]
    lines = [
        "",
        "What the runs at SNR ≥ 1 that missed their effect said instead:",
        "",
        "| candidate | " + " | ".join(answer.replace("_", " ") for answer in said) + " |",
        "|---|" + "---|" * len(said),
    ]
    for candidate in CANDIDATES:
        mine = [r for r in missed_rows if r["effect"] == candidate.name]
        if mine:
            counts = [sum(_missed_by(r) == answer for r in mine) for answer in said]
            lines.append(f"| `{candidate.name}` | " + " | ".join(map(str, counts)) + " |")
    return lines


def _collinear_table(collinear: list[Row]) -> list[str]:
    lines = [
        "",
        f"**Collinear pairs** (target: ambiguous, naming both, on at least {MIN_AMBIGUOUS:.0%}):",
        "",
        "| hidden | pair | base | ambiguous | found the hidden one (covered) | found another | none | target "
        "| in the design since |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    design = {(c.effect, "+".join(c.pair), c.base): c for c in default_cells() if c.kind == COLLINEAR}
    for key in dict.fromkeys((r["effect"], r["expected_pair"], kind_of(r["base"])) for r in collinear):
        mine = [r for r in collinear if (r["effect"], r["expected_pair"], kind_of(r["base"])) == key]
        ambiguous = rate(mine, _pair_ambiguous)
        hidden = [r for r in mine if named_right(r)]
        other = sum(r["verdict"] == FOUND for r in mine) - len(hidden)
        covered = sum(_covered(r) for r in hidden)
        none = sum(r["verdict"] == NONE for r in mine)
        cell = design.get(key)
        lines.append(
            f"| `{key[0]}` | {key[1].replace('+', ', ')} | {key[2]} | {ambiguous} | {len(hidden)} ({covered}) | "
            f"{other} | {none} | "
            f"{_met(ambiguous, ambiguous.share >= MIN_AMBIGUOUS)} | "
            f"{f'{cell.since}: {cell.note}' if cell else 'not in the design'} |"
        )
    return lines


def _world_table(world: list[Row]) -> list[str]:
    lines = [
        "",
        "**Chamber worlds** (nothing hidden; the twin's chamber had one parameter that no candidate varies "
        "scaled, the model discover is given has not): what discover said, by world. Gap / allowed: the median "
        f"run's largest ratio. Target, on the runs whose ratio is at least {GAP_RATIO:g}: `unexplained` in at "
        f"least {MIN_DIAGNOSED:.0%} (no candidate is right), `none` in at most {MAX_FALSE_DISCOVERY:.0%}.",
        "",
        "| world | runs | gap / allowed | unexplained | of which partial | named | ambiguous | none |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for base in sorted(dict.fromkeys(r["base"] for r in world), key=lambda name: chamber_change(index_of(name))):
        mine = [r for r in world if r["base"] == base]
        section, parameter, factor = chamber_change(index_of(base))
        names = ", ".join(sorted({r["named"] for r in mine if r["verdict"] == FOUND}))
        lines.append(
            f"| {section}.{parameter} ×{factor:g} | {len(mine)} | "
            f"{float(np.median([gap_ratio(r) for r in mine])):.2f} | {sum(map(_unexplained, mine))} | "
            f"{_partial_names(mine)} | {sum(map(_named, mine))}{f' ({names})' if names else ''} | "
            f"{sum(r['verdict'] == AMBIGUOUS for r in mine)} | {sum(r['verdict'] == NONE for r in mine)} |"
        )
    wide = [r for r in world if gap_ratio(r) >= GAP_RATIO]
    unexplained, none = rate(wide, _unexplained), rate(wide, lambda r: r["verdict"] == NONE)
    lines += [
        "",
        f"Of the {len(wide)} runs with a gap at least {GAP_RATIO:g} times what the model allows: unexplained "
        f"{unexplained} ({_met(unexplained, unexplained.share >= MIN_DIAGNOSED)}), none {none} "
        f"({_met(none, none.interval[1] <= MAX_FALSE_DISCOVERY)}).",
    ]
    return lines


def _coverage_table(named: list[Row]) -> list[str]:
    """named: the effect runs named right."""
    if not named:
        return []
    low, high = COVERAGE_RANGE
    lines = [
        "",
        f"**Coverage**: the true value inside the reported 95 % interval, of the runs named right "
        f"(target {low:.0%}–{high:.0%}).",
        "",
        "| side | covered | target |",
        "|---|---|---|",
    ]
    for side, on_side in (
        ("sensor", lambda r: r["channel"] not in CHAMBER_CHANNELS),
        ("chamber", lambda r: r["channel"] in CHAMBER_CHANNELS),
        ("all", lambda r: True),
    ):
        covered = rate([r for r in named if on_side(r)], _covered)
        if covered.runs:
            lines.append(f"| {side} | {covered} | {_met(covered, low <= covered.share <= high)} |")
    return lines


def _cost(rows: list[Row], base_seconds: Mapping[str, float]) -> list[str]:
    seconds = np.array([float(r["seconds"]) for r in rows])
    if not len(seconds):
        return []
    by_base = {
        kind: np.median([float(r["seconds"]) for r in rows if kind_of(r["base"]) == kind])
        for kind in dict.fromkeys(kind_of(r["base"]) for r in rows)
    }
    return [
        "",
        f"Cost: {seconds.sum() / 3600:.1f} CPU hours in all; a run (hiding and discovery) takes a median of "
        + ", ".join(f"{value:.1f} s on {base}" for base, value in by_base.items())
        + f". {_design_cost(rows, base_seconds)}",
    ]


def _design_cost(rows: list[Row], base_seconds: Mapping[str, float]) -> str:
    """The whole default design's CPU time at the record's mean seconds per
    kind and base (a run's cost depends on both: an effect found means
    another round of replays), and its bases' as they were made here."""
    mean: dict[tuple[str, str], float] = {}
    for key in dict.fromkeys((r["kind"], kind_of(r["base"])) for r in rows):
        mean[key] = float(np.mean([float(r["seconds"]) for r in rows if (r["kind"], kind_of(r["base"])) == key]))
    cells = default_cells()
    unknown = sorted({f"{c.kind} on {c.base}" for c in cells if (c.kind, c.base) not in mean})
    if unknown:
        return f"The whole design's cost is not known: no {', '.join(unknown)} runs in the record."
    cpu_s = sum(c.runs * mean[c.kind, c.base] for c in cells)
    cores = os.cpu_count() or 1
    text = (
        f"The whole design, {sum(c.runs for c in cells)} runs, takes {cpu_s / 3600:.1f} CPU hours at the record's "
        f"mean per kind and base: {cpu_s / 60 / cores:.0f} min on the {cores} cores of the machine that wrote this"
    )
    bases = sorted({task.base for cell in cells for task in cell.tasks()})
    if not all(base in base_seconds for base in bases):
        return text + "; what making its bases takes is not known."
    bases_s = sum(base_seconds[base] for base in bases)
    return (
        text + f". Its {len(bases)} bases took {bases_s / 60:.0f} CPU minutes to make here, "
        f"{bases_s / 60 / cores:.0f} min on {cores} cores: {(cpu_s + bases_s) / 60 / cores:.0f} min in all."
    )


def figure(rows: list[Row], path: Path) -> None:
    """Right-name rate against SNR per candidate; the null rate per noise
    family; each with its Wilson interval."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    effect = [r for r in rows if r["kind"] == EFFECT]
    null = [r for r in rows if r["kind"] == NULL]
    from matplotlib.ticker import NullFormatter

    fig, (power, false) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [3, 2]})
    colours = plt.get_cmap("tab20")(np.linspace(0.0, 1.0, len(CANDIDATES), endpoint=False))
    markers = "osD^v<>ph*X"
    for offset, candidate in enumerate(CANDIDATES):
        mine = [r for r in effect if r["effect"] == candidate.name]
        if not mine:
            continue
        rates = [rate([r for r in mine if float(r["snr"]) == snr], named_right) for snr in SNRS]
        x = np.array(SNRS) * (1.0 + 0.012 * (offset - len(CANDIDATES) / 2))
        shares = np.array([r.share for r in rates])
        bounds = np.array([r.interval for r in rates]).T
        power.errorbar(
            x,
            shares,
            yerr=np.abs(bounds - shares),
            color=colours[offset],
            marker=markers[offset % len(markers)],
            markersize=4,
            capsize=2,
            label=candidate.name,
        )
    power.axhline(MIN_RIGHT_AT_2, color="grey", linestyle=":", linewidth=1)
    power.axhline(MIN_RIGHT_AT_1, color="grey", linestyle=":", linewidth=1)
    power.set_xscale("log")
    power.set_xticks(SNRS, [f"{snr:g}" for snr in SNRS])
    power.xaxis.set_minor_formatter(NullFormatter())
    power.set_xlabel("SNR (effect RMS / noise RMS)")
    power.set_ylabel("named right")
    power.set_ylim(-0.02, 1.02)
    if effect:
        power.legend(fontsize=7, ncol=2, loc="lower right")
    power.set_title("Hidden effects")
    families = [noise for noise in NOISE_FAMILIES if any(r["noise"] == noise for r in null)]
    for hit, label, marker in ((_named, "named an effect", "o"), (_unexplained, "unexplained", "s")):
        rates = [rate([r for r in null if r["noise"] == noise], hit) for noise in families]
        shares = np.array([r.share for r in rates])
        bounds = np.array([r.interval for r in rates]).T.reshape(2, -1)
        false.errorbar(range(len(families)), shares, yerr=np.abs(bounds - shares), fmt=marker, capsize=3, label=label)
    false.axhline(MAX_FALSE_DISCOVERY, color="grey", linestyle=":", linewidth=1)
    false.set_xticks(range(len(families)), families, rotation=35, fontsize=7)
    false.set_ylabel("share of null runs")
    false.set_ylim(-0.02, 1.02)
    false.legend(fontsize=7)
    false.set_title("Null runs")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
