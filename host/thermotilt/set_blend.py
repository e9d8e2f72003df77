"""How far a sensor is between its warming and cooling sets after a
reversal: Prandtl's stop operator on a temperature (Krasnosel'skii and
Pokrovskii, Systems with Hysteresis, 1989). Each change of the temperature
moves the warming share by change / transition, held within 0..1: 1 is the
warming set, 0 the cooling set, and a reversal crosses from one to the other
over `transition` degC at any rate.

Two users, one operator: the physics model's sensor on its die temperature
(`[drift] set_transition_c`), and the host's copy of the firmware's
lib/Compensation SetBlend on the filtered temperature
(COMP_SET_TRANSITION_C, held to it by test_firmware_differential.py).
"""

from __future__ import annotations

from typing import Any

import numpy as np

# lib/Compensation's COMP_SET_TRANSITION_C and COMP_SET_POWER_UP_SHARE: a
# device does not know its sensor's history at power-up, so it starts halfway.
FIRMWARE_TRANSITION_C = 1.5
FIRMWARE_POWER_UP_SHARE = 0.5
# warming_shares' first window of steps: a stretch at a hold is a few dozen.
_FIRST_WINDOW = 64


class SetBlend:
    """The operator stepped one temperature change at a time. Starts
    warming unless told where it is, as the paper's cycles do."""

    __slots__ = ("_transition_c", "warming_share")

    def __init__(self, transition_c: float, warming_share: float = 1.0) -> None:
        self._transition_c = transition_c
        self.warming_share = warming_share

    def update(self, change_c: float) -> float:
        share = self.warming_share + change_c / self._transition_c
        self.warming_share = share = 1.0 if share > 1.0 else 0.0 if share < 0.0 else share
        return share


def warming_shares(
    transition_c: float, start_c: float, temperature_c: np.ndarray, warming_share: float = 1.0
) -> np.ndarray:
    """SetBlend(transition_c, warming_share) updated with each change of the
    temperature from start_c on, as an array: the same floats as
    SetBlend.update. A cumulative sum adds one step at a time as update
    does, but cannot clip, so the steps go in stretches: from the share,
    a cumulative sum up to the first step that leaves 0..1, clipped there;
    from a bound, up to the first step away from it (a step towards it, or
    none, clips back to it). Stretches are looked for in windows that grow
    while none ends in them."""
    steps = np.diff(np.asarray(temperature_c, dtype=float), prepend=start_c) / transition_c
    shares = np.empty(len(steps))
    share, index, window, at_bound = float(warming_share), 0, _FIRST_WINDOW, False
    while index < len(steps):
        ahead = steps[index : index + window]
        if at_bound:
            # Not "<" or ">": a NaN step leaves the bound, as it makes update's share NaN.
            leaving = np.flatnonzero(~(ahead >= 0.0) if share == 1.0 else ~(ahead <= 0.0))
            ended = len(leaving) > 0
            stop = int(leaving[0]) if ended else len(ahead)
            shares[index : index + stop] = share
            at_bound = not ended
        else:
            values = np.cumsum(np.concatenate(([share], ahead)))[1:]
            outside = np.flatnonzero((values > 1.0) | (values < 0.0))
            ended = len(outside) > 0
            stop = int(outside[0]) if ended else len(ahead)
            shares[index : index + stop] = values[:stop]
            if ended:
                share = shares[index + stop] = 1.0 if values[stop] > 1.0 else 0.0
                stop += 1
                at_bound = True
            else:
                share = float(values[-1])
        index += stop
        window = max(_FIRST_WINDOW, 2 * stop) if ended else 2 * window
    return shares


def blend(warming_share: Any, warming: Any, cooling: Any) -> Any:
    """The share of the way from the cooling set's value to the warming
    set's; at a share of 1 or 0 exactly that set's value (scalars or arrays)."""
    return warming_share * warming + (1.0 - warming_share) * cooling
