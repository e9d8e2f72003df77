"""format_numbers, the run log's numbers, against Python's own format as the
oracle: fixed decimals of the exact binary value, correctly rounded (half to
even on an exact tie); NaN and None are empty cells, and a number that rounds
to zero is written without a sign. The fast path rounds in numpy, so the
cases are where float64 arithmetic could round otherwise: numbers within a
few ulps of a .5 boundary, exact ties, and the extremes of float64."""

import math
import struct
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermotilt.run.log import format_number, format_numbers

PROPERTY = settings(max_examples=300, deadline=None)
LONG = 300  # numbers, enough for format_numbers' numpy path


def expected(value, decimals):
    """The oracle: Python's format, then the log's two rules."""
    if value is None or math.isnan(value):
        return ""
    text = format(value, f".{decimals}f")
    return text.removeprefix("-") if float(text) == 0 else text


def written_as_format_writes(values, decimals):
    """Short lists are formatted one by one and long ones in numpy: both."""
    want = [expected(value, decimals) for value in values]
    assert format_numbers(values, decimals) == want
    repeat = 1 + LONG // max(len(values), 1)
    assert format_numbers(values * repeat, decimals) == want * repeat


def neighbours(value, ulps=3):
    """value and the floats up to `ulps` steps either side of it."""
    below, above = [value], [value]
    for _ in range(ulps):
        below.append(float(np.nextafter(below[-1], -math.inf)))
        above.append(float(np.nextafter(above[-1], math.inf)))
    return below[::-1] + above[1:]


@st.composite
def near_ties(draw):
    """A list of numbers on or beside a .5 boundary of their last decimal, and the decimals."""
    decimals = draw(st.integers(0, 12))
    bound = draw(st.sampled_from([10**3, 10**7, 10**12]))
    values = []
    for k in draw(st.lists(st.integers(-bound, bound), min_size=1, max_size=10)):
        tie = draw(st.sampled_from([(k + 0.5) / 10**decimals, k / 10**decimals + 0.5 / 10**decimals]))
        values.extend(neighbours(tie, draw(st.integers(0, 4))))
    return values, decimals


numbers = st.one_of(
    st.floats(),  # subnormals, huge, inf, NaN and -0.0 among them
    st.floats(-1e6, 1e6),
    st.integers(-(10**9), 10**9).map(lambda k: k / 1000),  # a board's decimals
    st.integers(-(10**6), 10**6).map(lambda k: k / 256),  # a sensor's binary steps: exact ties
    st.none(),
)


@PROPERTY
@given(st.lists(numbers, max_size=40), st.integers(0, 12))
def test_any_numbers_are_written_as_format_writes_them(values, decimals):
    written_as_format_writes(values, decimals)


@PROPERTY
@given(near_ties())
def test_numbers_at_a_half_of_the_last_decimal_are_written_as_format_writes_them(ties):
    written_as_format_writes(*ties)


KNOWN_HARD = [0.0005, 0.0625, 2.675, 1.0005, -0.0005, -1e-4, 0.125, 0.375, 0.5, 1.5, 2.5, -2.5, 1e15 + 0.5]
EXTREMES = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, -1e300, 2.0**50, -(2.0**53)]


@pytest.mark.parametrize("decimals", range(13))
def test_known_hard_numbers_their_neighbours_and_extremes(decimals):
    values = [near for value in KNOWN_HARD for near in neighbours(value, 4)]
    # Where the scaled number outgrows the fast path: 2**50 / 10**decimals.
    values += neighbours(2.0**50 / 10**decimals) + neighbours(-(2.0**50) / 10**decimals)
    values += [(k + 0.5) / 10**decimals for k in range(-2000, 2000)]
    written_as_format_writes(values + EXTREMES + [math.inf, -math.inf, math.nan], decimals)


@pytest.mark.parametrize("decimals", range(7))
def test_a_long_column_as_a_log_has_it(decimals):
    rng = np.random.default_rng(decimals)
    column = rng.normal(20, 10, 20000)
    column[::7] = np.round(column[::7] * 16) / 16  # a 1/16 degree sensor
    column[::11] = math.nan
    written_as_format_writes(column.tolist(), decimals)


def test_unknowns_infinities_and_zeros_read_as_before():
    values = [1.0, None, -0.0004, None, math.nan, 2.5, -0.0, math.inf, -math.inf, -2.5e-7]
    texts = ["1.000", "", "0.000", "", "", "2.500", "0.000", "inf", "-inf", "0.000"]
    for repeat in (1, LONG):
        assert format_numbers(values * repeat, 3) == texts * repeat
        assert format_numbers([-0.4, 0.5, 1.5, -2.5] * repeat, 0) == ["0", "0", "2", "-2"] * repeat
        assert format_numbers([None, math.nan] * repeat, 2) == ["", ""] * repeat
    assert format_number(None, 3) == "" and format_number(-0.0001, 3) == "0.000"
    signalling_nan = struct.unpack("<d", struct.pack("<Q", 0x7FF0000000000001))[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no floating-point warning either
        texts = format_numbers([signalling_nan, 1e308, -math.inf, 0.5] * LONG, 6)
    assert texts == ["", expected(1e308, 6), "-inf", "0.500000"] * LONG


def test_any_iterable_and_plain_numbers_of_other_types():
    assert format_numbers([], 3) == []
    assert format_numbers(iter([]), 3) == []
    eighths = range(-LONG, LONG)
    assert format_numbers((k / 8 for k in eighths), 2) == [expected(k / 8, 2) for k in eighths]
    written_as_format_writes([3, True, 10**20, 2**63, -(2**70), 1.5], 3)
    single = np.tile(np.array([0.0005, 2.675, -1e-4], dtype=np.float32), LONG)
    assert format_numbers(single, 3) == [expected(value, 3) for value in single]


def test_what_is_not_a_number_fails_as_before():
    for repeat in (1, LONG):
        with pytest.raises(TypeError):
            format_numbers(["1.5"] * repeat, 3)
        with pytest.raises(ValueError):
            format_numbers([1.5] * repeat, -1)
