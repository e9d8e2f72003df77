"""`make chamber-floor`: measure what the chamber's replay leaves on runs
whose chamber the model fits, and write it where discovery declares it
(thermotilt/discovery/chamber_floor.toml; chamber_floor.py says why).

The runs are the twin's own, from the default model: calibration cycles and
Figure 8 runs at ambients the benchmark's bases do not use (18.2, 19.0 ...
degC), each with the model's noise generated on it as the benchmark's null
runs have (hide-effect --effect none). One Gauss-Markov process per chamber
channel is fitted to all of them by REML; the table printed after says how
each run's gap compares with what the fitted floor allows.
"""

from __future__ import annotations

import argparse
import sys
from datetime import date
from pathlib import Path

import tomli_w

ROOT = Path(__file__).resolve().parents[2]
RUNS_PER_SCENARIO = 8


def _bases() -> dict:
    from thermotilt.discovery.bases import SCATTER_OFF, Base, cycle_options, twin

    bases = {}
    for index in range(RUNS_PER_SCENARIO):
        seed, ambient = str(101 + index), f"{18.2 + 0.8 * index:.1f}"
        bases[f"cycle-{index:02d}"] = Base(
            f"cycle-{index:02d}", f"cycle, ambient {ambient} degC", twin("cycle", *cycle_options(seed, ambient, 0.0))
        )
        bases[f"fig8-{index:02d}"] = Base(
            f"fig8-{index:02d}",
            f"Figure 8, ambient {ambient} degC",
            twin("fig8", "--seed", seed, "--ambient", ambient, *SCATTER_OFF),
        )
    return bases


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=Path, default=ROOT / "build" / "chamber-floor", help="where the twin runs go")
    parser.add_argument("--out", type=Path, default=None, help="the floor file (default: the package's)")
    args = parser.parse_args()

    from thermotilt.discovery.bases import make_bases
    from thermotilt.discovery.chamber_floor import FLOOR_FILE, fit_floor
    from thermotilt.discovery.channel import GoodnessOfFit
    from thermotilt.discovery.hide import hide_effect
    from thermotilt.discovery.replay import CHAMBER_CHANNELS, load_measured
    from thermotilt.discovery.search import ALPHA, Search
    from thermotilt.physics import Model

    bases = _bases()
    make_bases(sorted(bases), args.runs, print, bases)
    model = Model.load()
    series: dict[str, list] = {channel: [] for channel in CHAMBER_CHANNELS}
    names = []
    for number, name in enumerate(sorted(bases)):
        generated = args.runs / name / "null"
        hide_effect(args.runs / name, generated, "none", seed=number, model=model)
        channels = Search(load_measured(generated), model).channels()
        names.append(name)
        for channel in CHAMBER_CHANNELS:
            series[channel].append(channels[channel])
    floors = {channel: fit_floor(runs) for channel, runs in series.items()}
    level = ALPHA / 5  # discovery's share per channel on a run with all five channels tested
    print(f"{'run':<10}" + "".join(f"{channel + ' gap/allowed':>22}" for channel in CHAMBER_CHANNELS))
    for index, name in enumerate(names):
        cells = []
        for channel in CHAMBER_CHANNELS:
            run, floor = series[channel][index], floors[channel]
            declared = floor.sigma_c**2 * run.unit_covariance(floor.time_constant_s)
            fit = GoodnessOfFit.of(channel, run.y, run.times.counts, declared, level, run.nuisance)
            cells.append(f"{fit.gap:.4f}/{fit.allowed:.4f}")
        print(f"{name:<10}" + "".join(f"{cell:>22}" for cell in cells))
    document = {
        "channels": {
            channel: {"sigma_c": round(floor.sigma_c, 5), "time_constant_s": round(floor.time_constant_s, 1)}
            for channel, floor in floors.items()
        }
    }
    header = (
        "# What the chamber's replay leaves on the twin's own runs from the default model\n"
        f"# (thermotilt/discovery/chamber_floor.py): written by `make chamber-floor` on {date.today()},\n"
        f"# from {len(names)} runs ({RUNS_PER_SCENARIO} cycles, {RUNS_PER_SCENARIO} Figure 8 runs).\n"
    )
    out = args.out or FLOOR_FILE
    out.write_text(header + tomli_w.dumps(document), encoding="utf-8")
    for channel, floor in floors.items():
        print(f"{channel}: {floor.sigma_c:.4f} degC RMS, time constant {floor.time_constant_s:.0f} s")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
