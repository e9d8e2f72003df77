"""A first-order lag's step fraction, shared by the thermistors and the die."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np


class LagFraction:
    """How far a first-order lag moves towards its input in one step,
    1 - exp(-dt/tau), recomputed only when the step length changes (the twin
    always steps 10 ms)."""

    __slots__ = ("_tau_s", "_dt_s", "_fraction")

    def __init__(self, tau_s: float) -> None:
        self._tau_s = tau_s
        self._dt_s = -1.0
        self._fraction = 1.0

    def of_step(self, dt_s: float) -> float:
        if dt_s != self._dt_s:
            self._dt_s = dt_s
            self._fraction = -math.expm1(-dt_s / self._tau_s)
        return self._fraction


def first_order(tau_s: float) -> Callable[[float, float, float], float]:
    """(previous value, target, dt s) -> the value a first-order lag of
    time constant tau_s reaches after dt towards the target."""
    fraction = LagFraction(tau_s).of_step

    def follow(previous: float, target: float, dt_s: float) -> float:
        return previous + fraction(dt_s) * (target - previous)

    return follow


def first_order_series(tau_s: float) -> Callable[[float, np.ndarray, np.ndarray], np.ndarray]:
    """(start, targets, dt s) -> the values first_order's steps reach from
    start, each towards its target: the same floats, in one loop."""

    def follow(start: float, targets: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
        lengths, which = np.unique(dt_s, return_inverse=True)
        fractions = np.array([-math.expm1(-length / tau_s) for length in lengths.tolist()])[which]
        values = []
        value = start
        for target, fraction in zip(targets.tolist(), fractions.tolist()):
            value = value + fraction * (target - value)
            values.append(value)
        return np.array(values)

    return follow
