"""The runs the discovery benchmark hides effects in (benchmark.py): 20
of each kind, each a history of its own. Staircases, waves and ramps are
inputs only (hide.py); cycles, Figure 8 runs and chamber worlds are the
twin's, the last from a chamber the model does not describe."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..run.folder import RunFolder


@dataclass(frozen=True)
class Base:
    """A run the benchmark hides effects in: `make(folder)` writes it (a run
    folder with run.csv) on the machine that submits the runs."""

    name: str
    what: str
    make: Callable[[Path], None]


def _inputs(maker: str, **shape: Any) -> Callable[[Path], None]:
    def make(folder: Path) -> None:
        from . import hide

        getattr(hide, maker)(RunFolder.at(folder).log, **shape)

    return make


def twin(scenario: str, *options: str, changed: tuple[str, str, float] | None = None) -> Callable[[Path], None]:
    """A twin run of the scenario; changed: (term or hardware section,
    parameter, factor) for a world whose model the twin runs with that
    parameter scaled, written beside the run as world.toml."""

    def make(folder: Path) -> None:
        model_options: list[str] = []
        if changed is not None:
            from ..physics import Model
            from ..physics.document import with_values, write_model

            section, parameter, factor = changed
            model = Model.load()
            table = model.constants.get(section) or model.terms[section]
            world = with_values(model, section, {parameter: float(table[parameter]) * factor})
            write_model(world, folder / "world.toml", f"the default model with {section}.{parameter} x{factor:g}")
            model_options = ["--model", str(folder / "world.toml")]
        subprocess.run(
            [sys.executable, "-m", "thermotilt", "simulate", scenario, *options, *model_options, "--out", str(folder)],
            check=True,
            stdout=subprocess.DEVNULL,
        )

    return make


# The scatter terms off in the twin's own runs: hide_effect generates the
# sensor side again with the family's noise.
SCATTER_OFF = ("--disable", "drift_repeatability", "--disable", "bias_instability")
# The chamber's parameters no candidate varies, and the factors a world
# scales one of them by (chamber worlds, base kind "chamber").
CHAMBER_CHANGES = (
    ("chamber", "inner_heat_capacity_j_per_k"),
    ("heatsink", "heat_capacity_j_per_k"),
    ("heatsink", "inner_conductance_w_per_k"),
    ("peltier_pumping", "full_duty_w"),
)
CHAMBER_FACTORS = (0.5, 0.8, 1.2, 2.0, 4.0)


def chamber_change(index: int) -> tuple[str, str, float]:
    """The chamber world of base number `index`: the term or hardware
    section, the parameter and its factor."""
    section, parameter = CHAMBER_CHANGES[index % len(CHAMBER_CHANGES)]
    return section, parameter, CHAMBER_FACTORS[index // len(CHAMBER_CHANGES) % len(CHAMBER_FACTORS)]


def cycle_options(seed: str, ambient: str, incl: float) -> tuple[str, ...]:
    return ("--rest-seconds", "60", "--seed", seed, "--ambient", ambient, "--incl-x", f"{incl:g}", *SCATTER_OFF)


def _variant(kind: str, index: int) -> Base:
    """The kind's base number `index`: each kind's bases differ in their
    tilt, temperatures and (the twin's) seed and ambient, so that a rate
    counts histories, not only noise drawn on one."""
    tilt = 25.0 + 2.5 * (index % 5)
    shift = index // 5 % 4
    name = f"{kind}-{index:02d}"
    if kind == "staircase":
        low = -2.5 * shift
        return Base(
            name,
            f"{low:g}..{low + 40:g} degC in 5 degC steps held 40 s at X +{tilt:g}, X -{tilt:g} and Y +{tilt:g} deg "
            "(inputs only)",
            _inputs("staircase_inputs", positions=((tilt, 0.0), (-tilt, 0.0), (0.0, tilt)), low_c=low, high_c=low + 40),
        )
    if kind == "wave":
        middle = 22.5 + 1.5 * shift
        return Base(
            name,
            f"a temperature wave {middle - 10:g}..{middle + 10:g} degC, period 2000 s, 1.5 periods at X +{tilt:g} deg "
            "(inputs only)",
            _inputs("wave_inputs", middle_c=middle, incl_x_deg=tilt),
        )
    if kind == "ramp":
        low = 18.0 + 1.5 * shift
        return Base(
            name,
            f"one ramp {low:g}..{low + 10:g}..{low:g} degC at 0.01 degC/s at X +{tilt:g} deg (inputs only)",
            _inputs(
                "staircase_inputs",
                positions=((tilt, 0.0),),
                low_c=low,
                high_c=low + 10.0,
                step_c=10.0,
                hold_s=0.0,
                ramp_c_per_s=0.01,
            ),
        )
    # The twin's chamber is deterministic: its ambient is what makes one
    # history differ from another.
    seed, ambient = str(index + 1), f"{18.0 + 0.4 * index:.1f}"
    incl = (0.0, 15.0, 30.0, -15.0)[shift]
    if kind == "cycle":
        return Base(
            name,
            f"the twin's calibration cycle, -10..45 degC, seed {seed}, ambient {ambient} degC, X {incl:+g} deg "
            "(simulate cycle --rest-seconds 60)",
            twin("cycle", *cycle_options(seed, ambient, incl)),
        )
    if kind == "chamber":
        section, parameter, factor = chamber_change(index)
        return Base(
            name,
            f"the twin's calibration cycle from a chamber with {section}.{parameter} x{factor:g}, seed {seed}, "
            f"ambient {ambient} degC, X {incl:+g} deg (simulate cycle --rest-seconds 60 --model world.toml)",
            twin("cycle", *cycle_options(seed, ambient, incl), changed=(section, parameter, factor)),
        )
    if kind == "fig8":
        return Base(
            name,
            f"the twin's Figure 8 run, 342 s, seed {seed}, ambient {ambient} degC (simulate fig8)",
            twin("fig8", "--seed", seed, "--ambient", ambient, *SCATTER_OFF),
        )
    raise ValueError(f"unknown base kind {kind!r}")


BASE_KINDS = ("staircase", "wave", "ramp", "cycle", "fig8", "chamber")
# Every cell's runs spread over this many bases of its kind.
BASES_PER_KIND = 20
BASES = {base.name: base for base in (_variant(kind, index) for kind in BASE_KINDS for index in range(BASES_PER_KIND))}


# What making each base took, a row a base made (make_bases' `made`).
BASE_RECORD_COLUMNS = ("base", "seconds")


def read_base_seconds(path: Path) -> dict[str, float]:
    """What making each base took, by name; the last time a base was made
    counts."""
    if not path.exists():
        return {}
    with open(path, newline="", encoding="utf-8") as stream:
        return {row["base"]: float(row["seconds"]) for row in csv.DictReader(stream)}


def base_recorder(path: Path) -> Callable[[str, float], None]:
    """make_bases' `made`, appending each base's seconds to the CSV at path."""
    lock = threading.Lock()

    def made(name: str, seconds: float) -> None:
        with lock:
            new = not path.exists() or path.stat().st_size == 0
            path.parent.mkdir(parents=True, exist_ok=True)
            with open(path, "a", newline="", encoding="utf-8") as stream:
                writer = csv.writer(stream)
                if new:
                    writer.writerow(BASE_RECORD_COLUMNS)
                writer.writerow((name, f"{seconds:.1f}"))

    return made


def kind_of(base: str) -> str:
    """A base's kind from its name ("cycle-07": "cycle")."""
    return base.split("-")[0]


def index_of(base: str) -> int:
    """A base's number within its kind ("cycle-07": 7)."""
    return int(base.rsplit("-", 1)[1])


def make_bases(
    names: Iterable[str],
    folder: Path,
    say: Callable[[str], None],
    bases: Mapping[str, Base] = BASES,
    made: Callable[[str, float], None] | None = None,
) -> dict[str, bytes]:
    """Each base's run.csv, made once into folder/NAME (as many at a time
    as the machine has cores: a twin's base is a process of its own) and
    read from there after; made(name, seconds) is told as each is made."""
    missing = [name for name in names if not RunFolder.at(folder / name).log.exists()]

    def make(name: str) -> None:
        say(f"making the base run {name}: {bases[name].what}")
        (folder / name).mkdir(parents=True, exist_ok=True)
        started = time.perf_counter()
        bases[name].make(folder / name)
        if made is not None:
            made(name, time.perf_counter() - started)

    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        list(pool.map(make, missing))
    return {name: RunFolder.at(folder / name).log.read_bytes() for name in names}
