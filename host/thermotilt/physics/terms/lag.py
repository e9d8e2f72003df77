"""A first-order lag's step fraction, shared by the thermistors and the die."""

from __future__ import annotations

import hashlib
import itertools
import math
from collections import OrderedDict
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


class _SeriesMemo:
    """The last series first_order_series computed, by their inputs: the
    die follows the same chamber in every replay of a run, whatever else
    the model changes, and the loop is the step's own arithmetic, one float
    at a time, so its value is worth keeping rather than recomputing."""

    SIZE = 8

    def __init__(self) -> None:
        self._series: OrderedDict[bytes, np.ndarray] = OrderedDict()

    def get(
        self, tau_s: float, start: float, targets: np.ndarray, dt_s: np.ndarray, make: Callable[[], np.ndarray]
    ) -> np.ndarray:
        digest = hashlib.blake2b(digest_size=16)
        digest.update(np.array([tau_s, start], dtype=float).tobytes())
        for values in (targets, dt_s):
            digest.update(np.ascontiguousarray(values, dtype=float).tobytes())
        key = digest.digest()
        if key in self._series:
            self._series.move_to_end(key)
        else:
            self._series[key] = make()
            self._series[key].flags.writeable = False
            if len(self._series) > self.SIZE:
                self._series.popitem(last=False)
        return self._series[key]


_MEMO = _SeriesMemo()


def first_order_series(tau_s: float) -> Callable[[float, np.ndarray, np.ndarray], np.ndarray]:
    """(start, targets, dt s) -> the values first_order's steps reach from
    start, each towards its target: the same floats, in one loop (read
    only: the series are kept for the same inputs, _SeriesMemo)."""

    def series(start: float, targets: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
        lengths, which = np.unique(dt_s, return_inverse=True)
        fractions = [-math.expm1(-length / tau_s) for length in lengths.tolist()]
        if len(fractions) == 1:
            # Equal steps (a 100 Hz grid): one fraction, and accumulate's
            # loop in C calling the step is faster than a loop in Python.
            (fraction,) = fractions
            steps = itertools.accumulate(
                targets.tolist(), lambda value, target: value + fraction * (target - value), initial=start
            )
            return np.fromiter(steps, dtype=float, count=len(targets) + 1)[1:]
        values = []
        append = values.append
        value = start
        for target, fraction in zip(targets.tolist(), np.array(fractions)[which].tolist()):
            value = value + fraction * (target - value)
            append(value)
        return np.array(values)

    def follow(start: float, targets: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
        return _MEMO.get(tau_s, start, targets, dt_s, lambda: series(start, targets, dt_s))

    return follow
