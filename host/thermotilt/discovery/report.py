"""What discovery writes: discovery.json (docs/discovery.md gives its
schema), model.toml, report.md and residuals.png."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from ..physics.document import write_model
from .replay import CHANNEL_COLUMNS, Measured
from .search import ALPHA, MIN_GAP_REDUCTION, Outcome

UNITS = {"temperature": "degC", "X": "LSB", "Y": "LSB", "Z": "LSB"}


def _number(value: float) -> float | None:
    return None if not math.isfinite(value) else value


def document(outcome: Outcome, measured: Measured, model_in: str, model_out: Path) -> dict[str, Any]:
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
        "gap": {
            channel: {"unit": UNITS[channel], "replay": gap}
            for channel, gap in outcome.gap.items()
        },
        "skipped_channels": dict(measured.skipped_channels),
        "skipped_rows": measured.skipped_rows,
        "tests": [
            [
                {
                    "name": test.candidate,
                    "channel": test.channel,
                    "testable": test.testable,
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


def _figure(outcome: Outcome, measured: Measured, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    channels = measured.channels
    figure, axes = plt.subplots(len(channels), 2, figsize=(12, 2.6 * len(channels)), squeeze=False)
    temperature = measured.observed.get("temperature")
    for row, channel in enumerate(channels):
        used = measured.used[channel]
        for label, residual, colour in (("before", outcome.residual_before[channel], "tab:red"),
                                        ("after", outcome.residual_after[channel], "tab:blue")):
            shown = residual[used] - (residual[used].mean() if channel != "temperature" else 0.0)
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


def write(outcome: Outcome, measured: Measured, model_in: str, out_dir: Path) -> dict[str, Any]:
    out_dir.mkdir(parents=True, exist_ok=True)
    model_path = out_dir / "model.toml"
    names = ", ".join(effect.candidate for effect in outcome.effects) or "nothing"
    write_model(outcome.model, model_path,
                f"thermotilt discover: {model_in} with what {measured.source} showed ({names})")
    result = document(outcome, measured, model_in, model_path)
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
    ]
    if result["effects"]:
        lines += ["| effect | channel | parameter | value | 95 % interval | adjusted p | gap reduction |",
                  "|---|---|---|---|---|---|---|"]
        for effect in result["effects"]:
            (parameter, value), = effect["parameters"].items()
            low, high = effect["interval_95"][parameter]
            lines.append(f"| {effect['name']} | {effect['channel']} | {parameter} ({effect['unit']}) | "
                         f"{value:.4g} | {low:.4g} … {high:.4g} | {effect['adjusted_p']:.2g} | "
                         f"{100 * effect['gap_reduction']:.0f} % |")
        lines.append("")
    for group in result["ambiguous"]:
        lines += [f"Ambiguous on {group['channel']}: {', '.join(group['names'])} explain the same "
                  f"residual on this run. To tell them apart: {group['experiment']}.", ""]
    if result["not_testable"]:
        lines += ["Not testable on this run (nothing in it excites them): "
                  + ", ".join(result["not_testable"]) + ".", ""]
    for channel, why in result["skipped_channels"].items():
        lines += [f"Channel {channel} skipped: {why}.", ""]
    lines += ["## Gap per channel (RMS of measured minus replay; acceleration about its mean)", "",
              "| channel | column | before | after |", "|---|---|---|---|"]
    for channel, gap in result["gap"].items():
        unit = gap["unit"]
        lines.append(f"| {channel} | {CHANNEL_COLUMNS[channel]} | {gap['replay']['before']:.3f} {unit} | "
                     f"{gap['replay']['after']:.3f} {unit} |")
    lines += ["", "![residuals before and after](residuals.png)", "",
              f"Found means: Benjamini–Hochberg adjusted p below {result['rules']['fdr']} across every "
              f"candidate and channel of a round, and at least "
              f"{100 * result['rules']['min_gap_reduction']:.0f} % off the channel's RMS residual "
              "(docs/discovery.md).", ""]
    lines += ["## Every test", "", "| round | candidate | channel | value | p | adjusted p | gap reduction |",
              "|---|---|---|---|---|---|---|"]
    for number, tests in enumerate(result["tests"], start=1):
        for test in tests:
            if not test["testable"]:
                lines.append(f"| {number} | {test['name']} | {test['channel']} | not testable | | | |")
                continue
            lines.append(f"| {number} | {test['name']} | {test['channel']} | {test['value']:.4g} | "
                         f"{test['p_value']:.2g} | {test['adjusted_p']:.2g} | "
                         f"{100 * test['gap_reduction']:.0f} % |")
    return "\n".join(lines) + "\n"

