"""What the chamber's replay leaves on a run whose chamber the model fits:
the noise discovery declares on the chamber's channels.

The replay (replay.py) drives the model's chamber open loop with the drive
logged once per status frame, where the twin's bridge changes it within
the frame; the readings are rounded and carry ADC noise. On the twin's own
runs, with the model the twin ran, this leaves about 0.06 degC RMS of slow
error per thermistor. Discovery declares it as one Gauss-Markov process per
channel, measured on twin runs by `fit_floor` (host/tools/chamber_floor.py
writes FLOOR_FILE), so that a gap beyond it is `unexplained`, not `none`.
"""

from __future__ import annotations

import functools
import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from scipy.optimize import minimize_scalar

from .reml import restricted_parts

FLOOR_FILE = Path(__file__).with_name("chamber_floor.toml")
# The time constants searched: from a few frames to longer than a cycle.
TIME_CONSTANT_RANGE_S = (2.0, 20000.0)
# White noise of this share of the process's variance keeps the block
# covariance positive definite when the time constant is long.
JITTER = 1e-6


@dataclass(frozen=True)
class Floor:
    """One Gauss-Markov process: RMS and time constant."""

    sigma_c: float
    time_constant_s: float


class BlockSeries(Protocol):
    """A channel's residual blocks as Channel holds them."""

    y: np.ndarray
    nuisance: np.ndarray

    def unit_covariance(self, time_constant_s: float) -> np.ndarray: ...


@functools.cache
def floors() -> Mapping[str, Floor]:
    """The declared floor per chamber channel ({} before one is measured)."""
    if not FLOOR_FILE.exists():
        return {}
    with open(FLOOR_FILE, "rb") as stream:
        document = tomllib.load(stream)
    return {
        channel: Floor(float(table["sigma_c"]), float(table["time_constant_s"]))
        for channel, table in document.get("channels", {}).items()
    }


def _restricted_deviance(series: Sequence[BlockSeries], time_constant_s: float) -> tuple[float, float]:
    """-2 log restricted likelihood with the variance profiled out, and that
    variance, for one process across runs, each with its own nuisance
    columns (REML: the nuisance integrated out, Harville, JASA 72, 1977)."""
    quadratic, dof, log_det = 0.0, 0, 0.0
    for run in series:
        unit = run.unit_covariance(time_constant_s)
        unit[np.diag_indices_from(unit)] += JITTER
        run_log_det, run_quadratic = restricted_parts(unit, run.nuisance, run.y)
        quadratic += run_quadratic
        log_det += run_log_det
        dof += len(run.y) - run.nuisance.shape[1]
    variance = quadratic / dof
    return dof * math.log(variance) + log_det, variance


def fit_floor(series: Sequence[BlockSeries]) -> Floor:
    """The Gauss-Markov process that explains the runs' residual blocks
    best, by REML over all of them."""
    low, high = (math.log(value) for value in TIME_CONSTANT_RANGE_S)
    best = minimize_scalar(
        lambda log_tau: _restricted_deviance(series, math.exp(log_tau))[0], bounds=(low, high), method="bounded"
    )
    time_constant_s = math.exp(float(best.x))
    _, variance = _restricted_deviance(series, time_constant_s)
    return Floor(math.sqrt(variance), time_constant_s)
