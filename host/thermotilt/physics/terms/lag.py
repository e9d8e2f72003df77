"""A first-order lag's step fraction, shared by the thermistors and the die."""

from __future__ import annotations

import hashlib
import itertools
import math
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

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

    @property
    def tau_s(self) -> float:
        return self._tau_s

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


class SeriesMemo:
    """The last series computed, by their inputs (numbers and arrays of
    floats), the oldest dropped beyond budget_bytes: the die follows the
    same chamber in every replay of a run, whatever else the model changes,
    and its lag and what follows from it go one float at a time, so their
    values are worth keeping rather than recomputing. The arrays kept are
    read only."""

    def __init__(self, budget_bytes: int) -> None:
        self._budget_bytes = budget_bytes
        self._series: OrderedDict[bytes, Any] = OrderedDict()
        self._bytes = 0

    def get(self, inputs: tuple[float | np.ndarray, ...], make: Callable[[], Any]) -> Any:
        """make()'s array, or tuple of arrays, for these inputs."""
        digest = hashlib.blake2b(digest_size=16)
        for values in inputs:
            array = np.ascontiguousarray(values, dtype=float)
            digest.update(np.array([array.size], dtype=np.int64).tobytes())
            digest.update(array.tobytes())
        key = digest.digest()
        if key in self._series:
            self._series.move_to_end(key)
            return self._series[key]
        made = make()
        for array in _arrays(made):
            array.flags.writeable = False
        self._series[key] = made
        self._bytes += sum(array.nbytes for array in _arrays(made))
        while self._bytes > self._budget_bytes and len(self._series) > 1:
            _, dropped = self._series.popitem(last=False)
            self._bytes -= sum(array.nbytes for array in _arrays(dropped))
        return made


def _arrays(made: Any) -> tuple[np.ndarray, ...]:
    return made if isinstance(made, tuple) else (made,)


# A cycle's 100 Hz die is 3.5 MB; a replay's, 0.2 MB.
_MEMO = SeriesMemo(64 * 2**20)


def first_order_series(tau_s: float) -> Callable[[float, np.ndarray, np.ndarray], np.ndarray]:
    """(start, targets, dt s) -> the values first_order's steps reach from
    start, each towards its target: the same floats, in one loop (read
    only: the series are kept for the same inputs, SeriesMemo)."""

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
        return _MEMO.get((tau_s, start, targets, dt_s), lambda: series(start, targets, dt_s))

    return follow
