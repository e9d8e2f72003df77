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
    SetBlend.update, whose clipping a cumulative sum cannot follow, so a
    loop over the steps."""
    state = SetBlend(transition_c, warming_share)
    changes = np.diff(np.asarray(temperature_c, dtype=float), prepend=start_c)
    return np.array([state.update(change) for change in changes.tolist()])


def blend(warming_share: Any, warming: Any, cooling: Any) -> Any:
    """The share of the way from the cooling set's value to the warming
    set's; at a share of 1 or 0 exactly that set's value (scalars or arrays)."""
    return warming_share * warming + (1.0 - warming_share) * cooling
