"""The set series the physics model steps one float at a time, computed
faster and kept: warming_shares in stretches of cumulative sums gives
SetBlend.update's floats, and the series memo keeps read-only series by
their inputs within its budget."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from thermotilt.physics.terms.lag import SeriesMemo
from thermotilt.set_blend import SetBlend, warming_shares

PROPERTY = settings(max_examples=200, deadline=None)


def stepped_shares(transition_c: float, start_c: float, temperature_c: np.ndarray, warming_share: float) -> np.ndarray:
    state = SetBlend(transition_c, warming_share)
    changes = np.diff(temperature_c, prepend=start_c)
    return np.array([state.update(change) for change in changes.tolist()], dtype=float)


@st.composite
def temperature_paths(draw) -> np.ndarray:
    """Ramps, holds and noise, as the die sees them, and now and then a NaN
    or a step larger than the transition."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    pieces = []
    for _ in range(draw(st.integers(1, 8))):
        count = draw(st.integers(0, 3000))
        rate = draw(st.sampled_from([0.0, 1e-3, -1e-3, 0.05, -0.05]))
        noise = draw(st.sampled_from([0.0, 1e-6, 1e-3, 0.3]))
        pieces.append(rate * np.arange(count) + rng.normal(0.0, noise, count) if noise else rate * np.arange(count))
    path = draw(st.floats(-20, 50)) + np.cumsum(np.concatenate([np.zeros(1), *pieces]))
    if draw(st.booleans()) and len(path) > 2:
        path[draw(st.integers(0, len(path) - 1))] = np.nan
    return path


@PROPERTY
@given(
    path=temperature_paths(),
    transition_c=st.sampled_from([1.5, 0.25, 1e-9, 40.0]),
    warming_share=st.sampled_from([1.0, 0.0, -0.0, 0.5, 0.999999]),
    start_offset_c=st.floats(-2.0, 2.0),
)
def test_warming_shares_are_the_updates_floats(path, transition_c, warming_share, start_offset_c):
    start_c = float(path[0]) + start_offset_c if math.isfinite(path[0]) else 0.0
    expected = stepped_shares(transition_c, start_c, path, warming_share)
    # Bytes: NaN where update gives NaN, and the sign of a zero, too.
    assert warming_shares(transition_c, start_c, path, warming_share).tobytes() == expected.tobytes()


def test_warming_shares_of_no_steps_are_empty():
    assert warming_shares(1.5, 20.0, np.array([])).shape == (0,)


def test_the_memo_keeps_read_only_series_by_their_inputs_within_its_budget():
    memo = SeriesMemo(budget_bytes=3 * 8 * 100)
    made = []

    def make(values: np.ndarray):
        made.append(values)
        return values * 2.0, values + 1.0

    first = np.arange(100.0)
    kept = memo.get((1.0, first), lambda: make(first))
    assert memo.get((1.0, first.copy()), lambda: make(first)) is kept
    assert not kept[0].flags.writeable and not kept[1].flags.writeable
    # Another number, another array of the same bytes: computed again.
    memo.get((2.0, first), lambda: make(first))
    memo.get((1.0, first[:50]), lambda: make(first[:50]))
    assert len(made) == 3
    # Over the budget, the oldest went.
    memo.get((1.0, first), lambda: make(first))
    assert len(made) == 4
