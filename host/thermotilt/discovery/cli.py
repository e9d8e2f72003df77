"""Discovery's commands: ``discover`` (which effect a run shows that the
model lacks) and ``hide-effect`` (a run with a known effect hidden in it,
to test discover) (docs/discovery.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..options import UsageError, existing_run, seed, settle_seconds, within
from ..run import SETTLE_S
from .noise_families import NOISE_FAMILIES


def add_commands(commands: argparse._SubParsersAction) -> None:
    discover = commands.add_parser(
        "discover", help="where a measured run and the model's replay disagree, and which effect explains it"
    )
    discover.add_argument(
        "measured", metavar="MEASURED", type=existing_run, help="a run folder or run.csv (true_* columns are ignored)"
    )
    discover.add_argument("--model", help="physics model file (default: the packaged default.toml)")
    discover.add_argument("--out", required=True, help="folder for discovery.json, model.toml, report.md")
    discover.add_argument(
        "--settle-seconds",
        type=settle_seconds,
        default=SETTLE_S,
        help=f"leave out rows this close to the start and to a table move (default {SETTLE_S:g})",
    )
    discover.add_argument(
        "--twin",
        action="store_true",
        help="MEASURED is a twin run: run its scenario (summary.json) again with the "
        "model before and after discovery and report the gap to each",
    )
    discover.set_defaults(run=_discover)

    hide = commands.add_parser(
        "hide-effect", help="a measured-looking run with one candidate effect hidden in it, for testing discover"
    )
    hide.add_argument(
        "--inputs",
        required=True,
        metavar="RUN",
        type=existing_run,
        help="a run (folder or run.csv) whose chamber temperature, drive and table angles to reuse, "
        "e.g. from thermotilt simulate",
    )
    hide.add_argument("--effect", required=True, help="a candidate's name, none or random")
    hide.add_argument("--seed", type=seed, default=1, help="noise and draw seed")
    hide.add_argument(
        "--snr",
        type=within(float, 0.01, 1000.0),
        help="effect RMS over noise RMS on its channel (default: drawn from 0.5..8)",
    )
    hide.add_argument(
        "--channel",
        choices=("temperature", "X", "Y", "Z", "inner", "outer"),
        help="the channel the effect is sized on (default: drawn)",
    )
    hide.add_argument(
        "--noise",
        choices=tuple(NOISE_FAMILIES),
        default="model",
        help="; ".join(f"{name}: {what}" for name, what in NOISE_FAMILIES.items()),
    )
    hide.add_argument("--model", help="physics model file the effect is added to (default: the packaged one)")
    hide.add_argument("--out", required=True, help="folder for run.csv and truth.json")
    hide.set_defaults(run=_hide_effect)


def _discover(args: argparse.Namespace) -> int:
    from ..native import NativeLibraryError
    from ..physics import Model, ModelError
    from . import report
    from .replay import DiscoveryDataError, load_measured
    from .search import Search

    try:
        model = Model.load(args.model)
        measured = load_measured(Path(args.measured), settle_s=args.settle_seconds)
        if args.twin:
            from .twin_gap import scenario_of

            scenario_run = scenario_of(Path(args.measured))
    except (ModelError, DiscoveryDataError) as error:
        raise UsageError(str(error)) from None
    for channel, why in measured.skipped_channels.items():
        print(f"channel {channel} skipped: {why}")
    if measured.skipped_rows:
        print(f"{measured.skipped_rows} rows without chamber_c, time or angles skipped")
    print(f"{len(measured.time_s)} rows, channels {', '.join(measured.channels)}")
    try:
        outcome = Search(measured, model, progress=print).run()
    except NativeLibraryError as error:
        raise UsageError(str(error)) from None
    out_dir = Path(args.out)
    twin = model_path = None
    try:
        if args.twin:
            from .twin_gap import twin_gap

            model_path = report.write_model_file(outcome, measured, model.source, out_dir)
            twin = twin_gap(
                scenario_run,
                measured,
                {"before": model, "after": Model.load(model_path)},
                out_dir,
                progress=print,
            )
        result = report.write(outcome, measured, model.source, out_dir, twin, model_path)
    except DiscoveryDataError as error:
        raise UsageError(str(error)) from None
    except OSError as error:
        raise UsageError(f"cannot write {out_dir}: {error.strerror or error}") from None
    for line in report.summary_lines(result):
        print(line)
    print(f"wrote {out_dir / 'discovery.json'}, model.toml, report.md, residuals.png")
    return 0


def _hide_effect(args: argparse.Namespace) -> int:
    from ..native import NativeLibraryError
    from ..physics import Model, ModelError
    from .hide import hide_effect
    from .replay import DiscoveryDataError

    try:
        model = Model.load(args.model)
        truth = hide_effect(
            Path(args.inputs),
            Path(args.out),
            args.effect,
            args.seed,
            snr=args.snr,
            channel=args.channel,
            noise=args.noise,
            model=model,
            progress=print,
        )
    except (ModelError, DiscoveryDataError, NativeLibraryError) as error:
        raise UsageError(str(error)) from None
    except OSError as error:
        raise UsageError(f"cannot write {args.out}: {error.strerror or error}") from None
    hidden = (
        f"{truth.effect} on {truth.channel} ({truth.parameter} {truth.value:.4g}, SNR {truth.snr:.2f})"
        if truth.effect != "none"
        else "no effect"
    )
    print(
        f"wrote {args.out}/run.csv with {hidden}, {truth.noise} noise "
        f"({truth.noise_rms:.3g} RMS); the truth is in truth.json"
    )
    return 0
