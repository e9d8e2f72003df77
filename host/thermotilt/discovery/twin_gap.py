"""The gap in the twin: when MEASURED came from a known scenario (its
summary.json names it and its options), the twin runs that scenario again
with the input model and with the model discovery wrote, same seed and
faults, and each run is compared with MEASURED channel by channel. Unlike
the replay this closes the chamber's loop through the real firmware, so it
shows what the found model changes in a whole run."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..physics import Fault, Model
from .channel import gap_rms
from .replay import DiscoveryDataError, Measured, load_measured


def scenario_of(measured: Path):
    """The scenario, seed and faults the summary.json of MEASURED (a run
    folder or its run.csv) says it was run with; asked before the search,
    so that a run the twin cannot run again is said at once."""
    from ..run.folder import RunFolder
    from ..run.summary import SUMMARY_FILE, TWIN, RunSummaryError, read_summary
    from ..twin.scenarios import ScenarioError, ScenarioOptions, build

    measured_dir = RunFolder.of(measured).path
    path = measured_dir / SUMMARY_FILE
    if not path.is_file():
        raise DiscoveryDataError(f"{measured_dir}: no {SUMMARY_FILE}, so no scenario to run the twin again")
    try:
        summary = read_summary(measured_dir)
    except RunSummaryError as error:
        raise DiscoveryDataError(str(error)) from None
    if summary.source != TWIN:
        raise DiscoveryDataError(f"{path}: a run on real boards, with no seed or faults to run the twin with")
    if summary.options is None:
        raise DiscoveryDataError(
            f"{path}: no scenario options (older runs did not record them), so no scenario to run again"
        )
    if summary.imu_eeprom_preloaded_bytes:
        raise DiscoveryDataError(f"{path}: the run started from a preloaded EEPROM, which is not kept")
    try:
        options = dict(summary.options)
        if options.get("positions") is not None:
            options["positions"] = tuple(options["positions"])
        scenario = build(summary.scenario, ScenarioOptions(**options))
        faults = [Fault(**fault) for fault in summary.faults]
        return scenario, int(summary.seed), faults
    except (TypeError, ValueError, ScenarioError) as error:
        raise DiscoveryDataError(f"{path}: no scenario to run again ({error})") from None


def twin_gap(
    scenario_run: tuple,
    measured: Measured,
    models: Mapping[str, Model],
    out_dir: Path,
    progress: Callable[[str], None] | None = None,
) -> dict[str, dict[str, float]]:
    """Per channel, the RMS of MEASURED minus the twin's run with each model
    (keyed as `models`: "before", "after"), over the rows discovery compares,
    the twin's values taken at MEASURED's times."""
    from ..twin import simulate
    from ..twin.boards import TwinError

    say = progress or (lambda message: None)
    scenario, seed, faults = scenario_run
    gaps: dict[str, dict[str, float]] = {channel: {} for channel in measured.channels}
    for when, model in models.items():
        run_dir = out_dir / f"twin-{when}"
        say(f"running the twin again: {scenario.name}, {scenario.duration_s:.0f} s, with the model {when} discovery")
        try:
            simulate.run(scenario, replace(model, faults=tuple(faults)), run_dir, seed=seed)
        except (TwinError, simulate.SimulationError) as error:
            raise DiscoveryDataError(f"the twin could not run {scenario.name} again: {error}") from None
        twin = load_measured(run_dir)
        for channel in measured.channels:
            if channel not in twin.observed:
                continue
            used = measured.used[channel]
            predicted = np.interp(measured.time_s, twin.time_s, twin.observed[channel])
            gaps[channel][when] = gap_rms(channel, (measured.observed[channel] - predicted)[used])
    return gaps
