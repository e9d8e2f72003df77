"""What discovery writes: discovery.json (docs/discovery.md gives its
schema), model.toml, report.md and residuals.png."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..physics.document import write_model
from .channel import NOTHING_MOVES_IT
from .replay import ACCELERATION_CHANNELS, CHAMBER_CHANNEL_COLUMNS, CHANNEL_COLUMNS, Measured
from .search import ALPHA, MIN_GAP_REDUCTION, Outcome

UNITS = {"temperature": "degC", "X": "LSB", "Y": "LSB", "Z": "LSB", "inner": "degC", "outer": "degC"}
COLUMNS = {**CHANNEL_COLUMNS, **CHAMBER_CHANNEL_COLUMNS}


PARTIAL = "These effects explain only a part of the gap: with them, a channel is still beyond the declared noise"


def _number(value: float) -> float | None:
    return None if not math.isfinite(value) else value


def document(
    outcome: Outcome,
    measured: Measured,
    model_in: str,
    model_out: Path,
    twin: dict[str, dict[str, float]] | None = None,
) -> dict[str, Any]:
    return {
        "measured": measured.source,
        "model_in": model_in,
        "verdict": outcome.verdict,
        "effects": [
            {
                "name": effect.candidate,
                "channel": effect.channel,
                "parameters": {effect.parameter: effect.value},
                "unit": effect.unit,
                "interval_95": {effect.parameter: list(effect.interval)},
                "adjusted_p": effect.adjusted_p,
                "gap_reduction": effect.gap_reduction,
            }
            for effect in outcome.effects
        ],
        "ambiguous": [
            {"names": list(group.names), "channel": group.channel, "experiment": group.experiment}
            for group in outcome.ambiguous
        ],
        "not_testable": outcome.not_testable,
        "fit": {
            channel: {
                "unit": UNITS[channel],
                "gap": fit.gap,
                "allowed": fit.allowed,
                "p_value": fit.p_value,
                "level": fit.level,
                "explained": fit.explained,
            }
            for channel, fit in outcome.fit.items()
        },
        "gap": {
            channel: {
                "unit": UNITS[channel],
                "replay": gap,
                **({"twin": twin[channel]} if twin and twin.get(channel) else {}),
            }
            for channel, gap in outcome.gap.items()
        },
        "regimes": regimes(outcome, measured),
        "skipped_channels": dict(measured.skipped_channels),
        "skipped_rows": measured.skipped_rows,
        "tests": [
            [
                {
                    "name": test.candidate,
                    "channel": test.channel,
                    "testable": test.testable,
                    "why_not": test.why_not,
                    "value": _number(test.value),
                    "interval_95": [_number(test.interval[0]), _number(test.interval[1])],
                    "p_value": _number(test.p_value),
                    "adjusted_p": _number(test.adjusted_p),
                    "gap_reduction": _number(test.gap_reduction),
                }
                for test in tests
            ]
            for tests in outcome.rounds
        ],
        "rules": {"fdr": ALPHA, "min_gap_reduction": MIN_GAP_REDUCTION},
        "model": str(model_out),
    }


# Regimes of a run the residual is split by: the chamber reading's 10 degC
# bands, its rate (above this, warming or cooling; else holding) over
# RATE_WINDOW_S, the table's positions and the run's quarters.
BAND_C = 10.0
HOLDING_C_PER_S = 0.005
RATE_WINDOW_S = 10.0


def _regime_labels(measured: Measured) -> dict[str, np.ndarray]:
    time_s, chamber_c = measured.time_s, measured.chamber_c
    band = np.floor(chamber_c / BAND_C) * BAND_C
    late = np.interp(time_s + RATE_WINDOW_S / 2, time_s, chamber_c)
    early = np.interp(time_s - RATE_WINDOW_S / 2, time_s, chamber_c)
    rate = (late - early) / RATE_WINDOW_S
    quarter = np.minimum(((time_s - time_s[0]) / max(np.ptp(time_s), 1e-9) * 4).astype(int), 3)
    return {
        "temperature": np.array([f"{low:g}…{low + BAND_C:g} °C" for low in band]),
        "rate": np.where(rate > HOLDING_C_PER_S, "warming", np.where(rate < -HOLDING_C_PER_S, "cooling", "holding")),
        "position": np.array([f"X {x:+g}°, Y {y:+g}°" for x, y in zip(measured.incl_x_deg, measured.incl_y_deg)]),
        "time": np.array([f"quarter {q + 1}" for q in quarter]),
    }


def regimes(outcome: Outcome, measured: Measured) -> dict[str, list[dict[str, Any]]]:
    """Per channel and regime: rows, and the residual's mean and RMS before
    and after (on the acceleration channels about the channel's mean, as
    its constant offset is not known)."""
    labels = _regime_labels(measured)
    table: dict[str, list[dict[str, Any]]] = {}
    for channel in measured.channels:
        used = measured.used[channel]
        centred = {}
        for when, residual in (
            ("before", outcome.residual_before[channel]),
            ("after", outcome.residual_after[channel]),
        ):
            centred[when] = residual - (residual[used].mean() if channel in ACCELERATION_CHANNELS else 0.0)
        rows = []
        for kind, label in labels.items():
            for name in sorted(set(label[used].tolist())):
                inside = used & (label == name)
                entry: dict[str, Any] = {"regime": kind, "name": name, "rows": int(np.count_nonzero(inside))}
                for when, residual in centred.items():
                    entry[when] = {
                        "mean": float(residual[inside].mean()),
                        "rms": float(np.sqrt(np.mean(residual[inside] ** 2))),
                    }
                rows.append(entry)
        table[channel] = rows
    return table


def _figure(outcome: Outcome, measured: Measured, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    channels = measured.channels
    figure, axes = plt.subplots(len(channels), 2, figsize=(12, 2.6 * len(channels)), squeeze=False)
    temperature = measured.observed.get("temperature")
    for row, channel in enumerate(channels):
        used = measured.used[channel]
        for label, residual, colour in (
            ("before", outcome.residual_before[channel], "tab:red"),
            ("after", outcome.residual_after[channel], "tab:blue"),
        ):
            shown = residual[used] - (residual[used].mean() if channel in ACCELERATION_CHANNELS else 0.0)
            axes[row][0].plot(measured.time_s[used], shown, ".", ms=1, color=colour, label=label)
            if temperature is not None:
                axes[row][1].plot(temperature[used], shown, ".", ms=1, color=colour, label=label)
        axes[row][0].set_ylabel(f"{channel} residual ({UNITS[channel]})")
        axes[row][0].set_xlabel("time (s)")
        axes[row][1].set_xlabel("IMU temperature (degC)")
        axes[row][0].legend(loc="upper right", markerscale=8)
    figure.suptitle("measured minus replay, before and after the found effects")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def write_model_file(outcome: Outcome, measured: Measured, model_in: str, out_dir: Path) -> Path:
    out_dir.mkdir(parents=True, exist_ok=True)
    model_path = out_dir / "model.toml"
    names = ", ".join(effect.candidate for effect in outcome.effects) or "nothing"
    write_model(
        outcome.model, model_path, f"thermotilt discover: {model_in} with what {measured.source} showed ({names})"
    )
    return model_path


def write(
    outcome: Outcome,
    measured: Measured,
    model_in: str,
    out_dir: Path,
    twin: dict[str, dict[str, float]] | None = None,
    model_path: Path | None = None,
) -> dict[str, Any]:
    """Everything; model_path: model.toml as write_model_file already wrote it."""
    if model_path is None:
        model_path = write_model_file(outcome, measured, model_in, out_dir)
    result = document(outcome, measured, model_in, model_path, twin)
    (out_dir / "discovery.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    _figure(outcome, measured, out_dir / "residuals.png")
    (out_dir / "report.md").write_text(_markdown(result), encoding="utf-8")
    return result


def _markdown(result: dict[str, Any]) -> str:
    lines = [
        "# Discovery report",
        "",
        f"Measured: `{result['measured']}`; model: `{result['model_in']}`.",
        "",
        f"**Verdict: {result['verdict']}.**",
        "",
        *_findings(result),
        *_fit_table(result),
        *_gap_table(result),
        *_regime_tables(result),
        "![residuals before and after](residuals.png)",
        "",
        f"Found means: Benjamini–Yekutieli adjusted p below {result['rules']['fdr']} across every "
        f"candidate and channel of a round, and at least "
        f"{100 * result['rules']['min_gap_reduction']:.0f} % off the channel's RMS residual "
        "(docs/discovery.md).",
        "",
        *_tests_table(result),
    ]
    return "\n".join(lines) + "\n"


def _findings(result: dict[str, Any]) -> list[str]:
    """The effects found, the ambiguous groups, what was not testable and
    the channels skipped."""
    lines = []
    if result["effects"] and result["verdict"] == "unexplained":
        lines += [PARTIAL + " (the table below the effects says where).", ""]
    if result["effects"]:
        lines += [
            "| effect | channel | parameter | value | 95 % interval | adjusted p | gap reduction |",
            "|---|---|---|---|---|---|---|",
        ]
        for effect in result["effects"]:
            ((parameter, value),) = effect["parameters"].items()
            low, high = effect["interval_95"][parameter]
            lines.append(
                f"| {effect['name']} | {effect['channel']} | {parameter} ({effect['unit']}) | "
                f"{value:.4g} | {low:.4g} … {high:.4g} | {effect['adjusted_p']:.2g} | "
                f"{100 * effect['gap_reduction']:.0f} % |"
            )
        lines.append("")
    for group in result["ambiguous"]:
        lines += [
            f"Ambiguous on {group['channel']}: {', '.join(group['names'])} explain the same "
            f"residual on this run. To tell them apart: {group['experiment']}.",
            "",
        ]
    for name, why in result["not_testable"].items():
        lines += [f"Not testable on this run: {name} ({why}).", ""]
    for channel, why in result["skipped_channels"].items():
        lines += [f"Channel {channel} skipped: {why}.", ""]
    return lines


def untested_on(channel: str, result: dict[str, Any]) -> str:
    """The candidates acting on the channel that the run could not test
    there, each with why: what a gap left there may hold."""
    return "; ".join(
        f"{test['name']} ({test['why_not']})"
        for test in (result["tests"][0] if result["tests"] else [])
        if test["channel"] == channel and not test["testable"] and test["why_not"] != NOTHING_MOVES_IT
    )


def unexplained_line(channel: str, fit: dict[str, Any], result: dict[str, Any]) -> str:
    untested = untested_on(channel, result)
    return (
        f"{channel}: {fit['gap']:.3g} {fit['unit']} RMS where the model allows {fit['allowed']:.3g} "
        f"(p {fit['p_value']:.2g})" + (f"; not testable there: {untested}" if untested else "")
    )


def _fit_table(result: dict[str, Any]) -> list[str]:
    if not result["fit"]:
        return []
    level = next(iter(result["fit"].values()))["level"]
    lines = [
        "## Does the model's noise explain what is left? (RMS of the 20 s block means about their mean; "
        f"'allowed' is what the declared noise exceeds with probability {level:.3g})",
        "",
        "| channel | gap | allowed | p | explained |",
        "|---|---|---|---|---|",
    ]
    for channel, fit in result["fit"].items():
        lines.append(
            f"| {channel} | {fit['gap']:.3g} {fit['unit']} | {fit['allowed']:.3g} {fit['unit']} | "
            f"{fit['p_value']:.2g} | {'yes' if fit['explained'] else '**no**'} |"
        )
    lines.append("")
    for channel, fit in result["fit"].items():
        untested = untested_on(channel, result)
        if not fit["explained"] and untested:
            lines += [f"Not testable on {channel}, which the declared noise does not explain: {untested}.", ""]
    return lines


def _gap_table(result: dict[str, Any]) -> list[str]:
    lines = [
        "## Gap per channel (RMS of measured minus replay, and minus the twin run again when "
        "it was; acceleration about its mean)",
        "",
        "| channel | column | replay before | replay after | twin before | twin after |",
        "|---|---|---|---|---|---|",
    ]
    for channel, gap in result["gap"].items():
        unit = gap["unit"]
        twin = gap.get("twin", {})
        cells = [f"{twin[when]:.3f} {unit}" if when in twin else "" for when in ("before", "after")]
        lines.append(
            f"| {channel} | {COLUMNS[channel]} | {gap['replay']['before']:.3f} {unit} | "
            f"{gap['replay']['after']:.3f} {unit} | {cells[0]} | {cells[1]} |"
        )
    return lines


def _regime_tables(result: dict[str, Any]) -> list[str]:
    lines = ["", "## Where the gap is: residual by regime (mean / RMS, before → after)", ""]
    for channel, rows in result["regimes"].items():
        unit = result["gap"][channel]["unit"]
        lines += [f"### {channel} ({unit})", "", "| regime | | rows | before | after |", "|---|---|---|---|---|"]
        for row in rows:
            before, after = row["before"], row["after"]
            lines.append(
                f"| {row['regime']} | {row['name']} | {row['rows']} | "
                f"{before['mean']:+.3g} / {before['rms']:.3g} | {after['mean']:+.3g} / {after['rms']:.3g} |"
            )
        lines.append("")
    return lines


def _tests_table(result: dict[str, Any]) -> list[str]:
    lines = [
        "## Every test",
        "",
        "| round | candidate | channel | value | p | adjusted p | gap reduction |",
        "|---|---|---|---|---|---|---|",
    ]
    for number, tests in enumerate(result["tests"], start=1):
        for test in tests:
            if not test["testable"]:
                lines.append(f"| {number} | {test['name']} | {test['channel']} | not testable | | | |")
                continue
            lines.append(
                f"| {number} | {test['name']} | {test['channel']} | {test['value']:.4g} | "
                f"{test['p_value']:.2g} | {test['adjusted_p']:.2g} | "
                f"{100 * test['gap_reduction']:.0f} % |"
            )
    return lines


def summary_lines(result: dict) -> list[str]:
    """What ``thermotilt discover`` prints of a discovery.json."""
    lines = [f"verdict: {result['verdict']}"]
    if result["effects"] and result["verdict"] == "unexplained":
        lines.append(f"  {PARTIAL}:")
    for effect in result["effects"]:
        ((parameter, value),) = effect["parameters"].items()
        low, high = effect["interval_95"][parameter]
        lines.append(
            f"  {effect['name']} on {effect['channel']}: {parameter} = {value:.4g} {effect['unit']} "
            f"(95 % {low:.4g} .. {high:.4g}), adjusted p {effect['adjusted_p']:.2g}, "
            f"gap -{100 * effect['gap_reduction']:.0f} %"
        )
    for group in result["ambiguous"]:
        lines.append(
            f"  ambiguous on {group['channel']}: {', '.join(group['names'])}; to separate them: {group['experiment']}"
        )
    for name, why in result["not_testable"].items():
        lines.append(f"  not testable here: {name} ({why})")
    for channel, fit in result["fit"].items():
        if not fit["explained"]:
            lines.append(f"  unexplained: {unexplained_line(channel, fit, result)}")
    for channel, gap in result["gap"].items():
        twin_text = f"; twin {gap['twin']['before']:.3f} -> {gap['twin']['after']:.3f}" if "twin" in gap else ""
        lines.append(
            f"  gap {channel}: {gap['replay']['before']:.3f} -> {gap['replay']['after']:.3f} "
            f"{gap['unit']} RMS{twin_text}"
        )
    return lines
