"""The host's Python copies of firmware algorithms against the firmware's
C++ compiled for the host (host/native/firmware_algorithms.h in
build/native/libthermotilt_host.so), input for input:

- scenarios.program_steps, lib/Program's staircase;
- the physics model's trend (physics.sensor.Trend), lib/Compensation's
  TrendDetector;
- set_blend (the physics model's set state and validate's compensation),
  lib/Compensation's SetBlend;
- Surface.evaluate and the drift term's _surface, lib/Compensation's
  surfaceCorrection;
- wire.coefficients' EEPROM block (encode_block, decode_block) and sensor
  ID rule (sensor_id_problem), lib/Compensation's encodeCoefficients,
  decodeCoefficients and isValidSensorId.

The firmware computes in float32 (the AVR's float and double; the host
library's SSE float, without fused multiply-adds). Both sides start from the
same float32 inputs: program_steps rounds to float32 as SETPRG's parser
does, and the trend and surface copies are given float32 values.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from thermotilt import native
from thermotilt.physics import Model
from thermotilt.physics.sensor import Trend
from thermotilt.physics.terms.sensor import INT16_MAX, INT16_MIN, OPERATING_C, SURFACE_TERM_BOUNDS, _surface
from thermotilt.program import CALIBRATION_MAX_C, CALIBRATION_MIN_C
from thermotilt.set_blend import FIRMWARE_POWER_UP_SHARE, FIRMWARE_TRANSITION_C, warming_shares
from thermotilt.surfaces import AXES, PAPER_DEFAULTS, SETS, Surface, table_from_values
from thermotilt.twin.scenarios import program_steps
from thermotilt.wire.coefficients import (
    BLOCK_SIZE,
    CoefficientBlockError,
    SetDomain,
    crc16_xmodem,
    decode_block,
    encode_block,
    sensor_id_problem,
)

pytestmark = pytest.mark.twin

PROPERTY = settings(max_examples=200, deadline=None)
PROGRAM_ACCEPTED = 0  # ProgramError::None


def _call(function_name: str, *arguments) -> None:
    status = getattr(native.library(), function_name)(*arguments)
    assert status == 0, f"{function_name} refused its arguments"


def _singles(*values) -> list[np.ndarray]:
    return [np.ascontiguousarray(value, np.float32) for value in np.broadcast_arrays(*values)]


def firmware_program_steps(start_c, max_c, step_c) -> tuple[np.ndarray, np.ndarray]:
    """(ProgramError, stepsPerCycle) of each staircase, as lib/Program configures it."""
    start, top, step = _singles(start_c, max_c, step_c)
    error = np.zeros(start.size, np.uint8)
    steps = np.zeros(start.size, np.uint16)
    _call(
        "thermotilt_program_steps",
        start.size,
        start.ctypes.data,
        top.ctypes.data,
        step.ctypes.data,
        error.ctypes.data,
        steps.ctypes.data,
    )
    return error, steps


def firmware_trend(temperatures_c: np.ndarray, band_c: float) -> list[str]:
    """The set letter after each update of one lib/Compensation TrendDetector."""
    (temperatures,) = _singles(temperatures_c)
    sets = np.zeros(temperatures.size, np.uint8)
    _call("thermotilt_trend_sets", temperatures.size, temperatures.ctypes.data, band_c, sets.ctypes.data)
    return [native.SET_LETTERS[value] for value in sets]


def firmware_surface(p: np.ndarray, temperature_c: np.ndarray, accel_lsb: np.ndarray) -> np.ndarray:
    (coefficients,) = _singles(p)
    temperature, accel = _singles(temperature_c, accel_lsb)
    correction = np.zeros(temperature.size, np.float32)
    _call(
        "thermotilt_surface_corrections",
        temperature.size,
        coefficients.ctypes.data,
        temperature.ctypes.data,
        accel.ctypes.data,
        correction.ctypes.data,
    )
    return correction


@pytest.fixture(scope="module")
def model():
    return Model.load()


# --- Staircase --------------------------------------------------------------


def test_program_steps_on_every_staircase_typed_in_tenths_of_a_degree():
    """Every start < max on the 0.1 degC grid of -10..45 with every step on
    that grid the firmware accepts: 27.8 million staircases."""
    tenths = np.arange(round(CALIBRATION_MIN_C * 10), round(CALIBRATION_MAX_C * 10) + 1)
    start, top = (grid.ravel() for grid in np.meshgrid(tenths, tenths, indexing="ij"))
    below = start < top
    start, top = start[below], top[below]
    compared = 0
    for step in range(1, tenths.size):
        fits = top - start >= step
        start_c, max_c, step_c = start[fits] / 10, top[fits] / 10, step / 10
        error, firmware = firmware_program_steps(start_c, max_c, step_c)
        accepted = error == PROGRAM_ACCEPTED
        np.testing.assert_array_equal(
            program_steps(start_c[accepted], max_c[accepted], step_c), firmware[accepted], err_msg=f"step {step_c} degC"
        )
        compared += int(accepted.sum())
    assert compared > 27_000_000


@st.composite
def staircases(draw) -> tuple[float, float, float]:
    """start < max in the firmware's -10..45 degC and a step: any share of
    the span, or the span over a whole number of steps to within +-3e-4 (the
    firmware lets a top step up to 1e-4 of a step past a multiple merge)."""
    start, top = sorted(
        draw(st.lists(st.floats(CALIBRATION_MIN_C, CALIBRATION_MAX_C), min_size=2, max_size=2, unique=True))
    )
    span = top - start
    if draw(st.booleans()):
        return start, top, span * draw(st.floats(1e-3, 1.0))
    intervals = draw(st.integers(1, 999))
    return start, top, span / intervals * (1.0 + draw(st.floats(-3e-4, 3e-4)))


@PROPERTY
@given(staircases())
@example((-10.0, 45.0, 18.3333))  # 3.0000055 steps: the old float64, 1e-6 copy gave 9, the firmware 7
@example((-10.0, 45.0, 54.999))  # 1.0000182 steps: the old copy gave 5, the firmware 3
def test_program_steps_agree_with_the_firmware_wherever_it_accepts_the_staircase(staircase):
    error, firmware = firmware_program_steps(*staircase)
    assume(error[0] == PROGRAM_ACCEPTED)
    assert program_steps(*staircase) == firmware[0]


# --- Trend ------------------------------------------------------------------
# The firmware's temperature comes from whole 1/8 degC register steps through
# a Kalman filter, the model's die temperature from its ODE: neither is ever
# NaN, so no series here holds one.


def python_trend(model: Model, temperatures_c: np.ndarray) -> tuple[list[str], list[float]]:
    """The physics model's set after each of temperatures_c[1:], the trend
    started at temperatures_c[0] (the firmware's first sample seeds its
    extreme the same way), and the extreme each update started from."""
    trend = Trend(model.terms["drift"]["schmitt_band_c"], float(temperatures_c[0]))
    sets, extremes = [], []
    for temperature in temperatures_c[1:]:
        extremes.append(trend.extreme_c)
        sets.append(trend.update(float(temperature)))
    return sets, extremes


GRID_C = 2.0**-10
GRID_RANGE = (round(OPERATING_C.low / GRID_C), round(OPERATING_C.high / GRID_C))


@st.composite
def grid_series(draw, band_c: float) -> np.ndarray:
    """A walk over -40..85 degC in steps of 2^-10 degC: plateaus, register
    steps of 1/8 degC, and moves of exactly the band and one grid step either
    side of it, so excursions land on the band. Every value and difference
    is exact in float32 and float64 alike."""
    band = round(band_c / GRID_C)
    eighth = round(0.125 / GRID_C)
    move = st.sampled_from([0, 1, eighth, band - 1, band, band + 1]) | st.integers(0, 3 * band)
    moves = draw(st.lists(st.tuples(move, st.sampled_from([-1, 1])), min_size=1, max_size=200))
    start = draw(st.integers(*GRID_RANGE))
    walk = start + np.cumsum([0, *(size * sign for size, sign in moves)])
    return np.clip(walk, *GRID_RANGE) * GRID_C


@PROPERTY
@given(data=st.data())
def test_trend_agrees_with_the_firmware_where_float32_is_exact(model, data):
    band = model.terms["drift"]["schmitt_band_c"]
    series = data.draw(grid_series(band))
    python, _ = python_trend(model, series)
    assert python == firmware_trend(series, band)[1:]


def test_trend_treats_an_excursion_of_exactly_the_band_as_no_turn(model):
    band = model.terms["drift"]["schmitt_band_c"]
    series = np.array([20.0, 21.0, 21.0 - band, 21.0 - band - GRID_C, 20.0, 20.0 + band, 20.0 + band + GRID_C])
    python, _ = python_trend(model, series)
    assert python == firmware_trend(series, band)[1:] == ["W", "W", "C", "C", "C", "W"]


@PROPERTY
@given(arrays(np.float32, st.integers(2, 200), elements=st.floats(OPERATING_C.low, OPERATING_C.high, width=32)))
# float32(0.3), then the value 0.5 + 2^-26 degC below it: float32 rounds that excursion to the band.
@example(np.array([0.3, -(0.5 + 2.0**-26 - float(np.float32(0.3)))], np.float32))
def test_trend_differs_from_the_firmware_only_where_float32_rounds_the_excursion(model, series):
    """The model compares its excursions in float64, the firmware in float32.
    Where the exact excursion lies within float32's rounding of the band
    (values of both signs, or of very different size), the two may choose
    differently, as the example does; anywhere else they must agree."""
    band = model.terms["drift"]["schmitt_band_c"]
    python, extremes = python_trend(model, series)
    firmware = firmware_trend(series, band)[1:]
    differing = [index for index, (ours, theirs) in enumerate(zip(python, firmware)) if ours != theirs]
    if not differing:
        return
    first = differing[0]
    state = python[first - 1] if first else "W"
    extreme, temperature = extremes[first], float(series[first + 1])
    exact = extreme - temperature if state == "W" else temperature - extreme
    single = np.float32(extreme) - series[first + 1] if state == "W" else series[first + 1] - np.float32(extreme)
    assert (exact > band) != (single > np.float32(band))


# --- Set blend --------------------------------------------------------------


def firmware_shares(temperatures_c, transition_c: float) -> np.ndarray:
    """The warming share after each update of one lib/Compensation SetBlend."""
    (temperatures,) = _singles(temperatures_c)
    shares = np.zeros(temperatures.size, np.float32)
    _call("thermotilt_set_blend_shares", temperatures.size, temperatures.ctypes.data, transition_c, shares.ctypes.data)
    return shares


def test_the_hosts_transition_and_power_up_share_are_the_firmwares():
    header = (Path(__file__).resolve().parents[2] / "lib/Compensation/src/Compensation.h").read_text()
    (transition,) = re.findall(r"const float COMP_SET_TRANSITION_C = ([0-9.]+)f;", header)
    (power_up,) = re.findall(r"const float COMP_SET_POWER_UP_SHARE = ([0-9.]+)f;", header)
    assert (float(transition), float(power_up)) == (FIRMWARE_TRANSITION_C, FIRMWARE_POWER_UP_SHARE)


@PROPERTY
@given(arrays(np.float32, st.integers(1, 400), elements=st.floats(OPERATING_C.low, OPERATING_C.high, width=32)))
def test_set_blend_agrees_with_the_firmware_within_float32_rounding(series):
    """The firmware steps in float32: each update rounds the change, the
    product with its rounded 1 / transition (two roundings) and the sum,
    each at most u = 2^-24 of its size (the share is at most 1), and the
    clamp to 0..1 never widens a difference; so after k updates the two
    differ by at most the sum of u (1 + 4 |change| / transition) over them."""
    python = warming_shares(FIRMWARE_TRANSITION_C, float(series[0]), series.astype(float), FIRMWARE_POWER_UP_SHARE)
    firmware = firmware_shares(series, FIRMWARE_TRANSITION_C)
    changes = np.abs(np.diff(series.astype(float), prepend=float(series[0])))
    bound = np.cumsum(2.0**-24 * (1.0 + 4.0 * changes / FIRMWARE_TRANSITION_C))
    assert np.all(np.abs(python - firmware) <= bound)


# --- Surface ----------------------------------------------------------------
# The firmware's f(T, a) = p00 + T (p10 + p20 T + p11 a) + a (p01 + p02 a) in
# float32: each of the six terms passes at most six rounded operations (p20 T
# T: p20*T, +p10, +p11*a, T*, +p00, +a-part), so with u = 2^-24 the result is
# within gamma_6 = 6u / (1 - 6u) of the sum of the terms' magnitudes M
# (Higham, Accuracy and Stability of Numerical Algorithms, lemma 3.1 and
# section 3.1). Surface.evaluate's and _surface's float64 sums have at most
# six too (u = 2^-53). A float32 product that underflows is off by up to
# 2^-150 more, which T or a multiply at most once: 2^-149 (2|T| + |a| + 2).
# For the paper's surfaces over -10..45 degC and +-16384 LSB that is ~6e-4 LSB.


def gamma_6(unit_roundoff: float) -> float:
    return 6 * unit_roundoff / (1 - 6 * unit_roundoff)


def rounding_bound(p: np.ndarray, temperature_c: np.ndarray, accel_lsb: np.ndarray) -> np.ndarray:
    p00, p10, p01, p20, p11, p02 = p.astype(np.float64)
    t, a = temperature_c.astype(np.float64), accel_lsb.astype(np.float64)
    magnitudes = abs(p00) + abs(p10 * t) + abs(p01 * a) + abs(p20 * t * t) + abs(p11 * t * a) + abs(p02 * a * a)
    underflow = 2.0**-149 * (2 * abs(t) + abs(a) + 2)
    return (gamma_6(2.0**-24) + gamma_6(2.0**-53)) * magnitudes + underflow


# Where the paper calibrated (temperature, a tilt's +-1 g at 16384 LSB/g) and
# where the firmware meets a surface (COMP_TEMPERATURE_*, COMP_ACCEL_*).
DOMAINS = {
    "calibrated": ((CALIBRATION_MIN_C, CALIBRATION_MAX_C), (-16384.0, 16384.0)),
    "operating": ((OPERATING_C.low, OPERATING_C.high), (float(INT16_MIN), float(INT16_MAX))),
}
PAPER_SURFACES = [PAPER_DEFAULTS.to_float32().surface(set_, axis) for set_ in SETS for axis in AXES]


def float32_surfaces() -> st.SearchStrategy[np.ndarray]:
    """Coefficients the model admits (each term alone within the int16 span
    over the operating domain), as the firmware holds them."""
    terms = [st.floats(bounds.low, bounds.high).map(np.float32) for bounds in SURFACE_TERM_BOUNDS]
    return st.tuples(*terms).map(lambda values: np.array(values, np.float32)) | st.sampled_from(
        [np.array(surface, np.float32) for surface in PAPER_SURFACES]
    )


def assert_within_rounding(p: np.ndarray, temperature_c: np.ndarray, accel_lsb: np.ndarray) -> None:
    firmware = firmware_surface(p, temperature_c, accel_lsb).astype(np.float64)
    bound = rounding_bound(p, temperature_c, accel_lsb)
    t, a = temperature_c.astype(np.float64), accel_lsb.astype(np.float64)
    for name, python in (
        ("Surface.evaluate", Surface(*p.astype(np.float64)).evaluate(t, a)),
        ("_surface", _surface(tuple(p.astype(np.float64)), t, a)),
    ):
        excess = np.abs(python - firmware) - bound
        worst = int(np.argmax(excess))
        assert excess[worst] <= 0, (
            f"{name} at T={t[worst]!r}, a={a[worst]!r}: {python[worst]!r}, "
            f"firmware {firmware[worst]!r}, bound {bound[worst]!r}"
        )


@pytest.mark.parametrize("domain", DOMAINS)
@PROPERTY
@given(data=st.data())
def test_surface_agrees_with_the_firmware_within_float32_rounding(domain, data):
    (t_low, t_high), (a_low, a_high) = DOMAINS[domain]
    p = data.draw(float32_surfaces())
    count = data.draw(st.integers(1, 64))
    temperature = data.draw(arrays(np.float32, count, elements=st.floats(t_low, t_high, width=32)))
    accel = data.draw(arrays(np.float32, count, elements=st.floats(a_low, a_high, width=32)))
    assert_within_rounding(p, temperature, accel)


@pytest.mark.parametrize("surface", PAPER_SURFACES)
def test_paper_surfaces_agree_with_the_firmware_over_the_calibrated_grid(surface):
    """0.1 degC by 1 LSB steps would be 90 million points; 0.25 degC by 64 LSB covers the corners and edges."""
    (t_low, t_high), (a_low, a_high) = DOMAINS["calibrated"]
    temperature, accel = np.meshgrid(
        np.arange(t_low, t_high + 0.125, 0.25, dtype=np.float32), np.arange(a_low, a_high + 1, 64, dtype=np.float32)
    )
    assert_within_rounding(np.array(surface, np.float32), temperature.ravel(), accel.ravel())


def test_chamber_drive_is_the_firmwares_p_law():
    # 350 * e to the nearest PWM step, saturating at 255 beyond 255/350 degC;
    # with the rounded error, e to whole degrees first (lib/ChamberControl).
    setpoint = [20.0, 20.0, 20.0, 20.0, 20.0]
    measured = [19.5, 20.0, 21.0, 19.999, 20.4]
    pwm, direction = native.chamber_drive(setpoint, measured, 0.25)
    assert pwm.tolist() == [175, 0, 255, 0, 140]
    assert direction.tolist() == [
        native.DRIVE_HEAT,
        native.DRIVE_OFF,
        native.DRIVE_COOL,
        native.DRIVE_OFF,
        native.DRIVE_COOL,
    ]
    pwm, direction = native.chamber_drive(setpoint, measured, 0.25, rounded_error=True)
    assert pwm.tolist() == [255, 0, 255, 0, 0]
    assert direction.tolist() == [
        native.DRIVE_HEAT,
        native.DRIVE_OFF,
        native.DRIVE_COOL,
        native.DRIVE_OFF,
        native.DRIVE_OFF,
    ]


# --- Coefficient block and sensor ID ----------------------------------------
# BlockStatus of lib/Compensation, in its order.
OK, BLANK, BAD_MAGIC, BAD_VERSION, BAD_CRC, BAD_VALUES, OTHER_SENSOR = range(7)
ID_CHARACTERS = "ABCXYZabcxyz0189_-"


def firmware_block(values: np.ndarray, domain: list[int], sensor_id: str) -> bytes:
    coefficients = np.ascontiguousarray(values, np.float32)
    bounds = np.ascontiguousarray(domain, np.int16)
    block = np.zeros(BLOCK_SIZE, np.uint8)
    _call(
        "thermotilt_coefficient_block_encode",
        coefficients.ctypes.data,
        bounds.ctypes.data,
        sensor_id.encode("ascii"),
        block.ctypes.data,
    )
    return block.tobytes()


def firmware_decode(block: bytes, board_id: str) -> tuple[int, np.ndarray, list[int]]:
    """BlockStatus, and the coefficients and domain decodeCoefficients left
    in a table of NaN and a domain of zeros."""
    data = np.frombuffer(block.ljust(BLOCK_SIZE, b"\xff"), np.uint8).copy()
    status = np.zeros(1, np.uint8)
    coefficients = np.full(36, np.nan, np.float32)
    domain = np.zeros(16, np.int16)
    _call(
        "thermotilt_coefficient_block_decode",
        data.ctypes.data,
        board_id.encode("ascii"),
        status.ctypes.data,
        coefficients.ctypes.data,
        domain.ctypes.data,
    )
    return int(status[0]), coefficients, domain.tolist()


def firmware_ids_valid(texts: list[bytes]) -> list[bool]:
    import ctypes

    array = (ctypes.c_char_p * len(texts))(*texts)
    valid = np.zeros(len(texts), np.uint8)
    _call("thermotilt_sensor_ids_valid", len(texts), ctypes.cast(array, ctypes.c_void_p), valid.ctypes.data)
    return [bool(value) for value in valid]


sensor_ids = st.text(ID_CHARACTERS, max_size=8)
int16s = st.integers(INT16_MIN, INT16_MAX)
# Coefficients whose output fits an IMU frame, so that the firmware loads them.
small_coefficients = arrays(np.float32, 36, elements=st.floats(-(2.0**-20), 2.0**-20, width=32))


# A range as the host writes one: ordered bounds, or none as (32767, -32768).
ranges = st.lists(int16s, min_size=2, max_size=2).map(sorted) | st.just([INT16_MAX, INT16_MIN])


@st.composite
def blocks(draw) -> tuple[np.ndarray, list[int], str]:
    values = draw(small_coefficients | arrays(np.float32, 36, elements=st.floats(width=32)))
    domain = [bound for _ in range(8) for bound in draw(ranges)]
    return values, domain, draw(sensor_ids)


def firmware_domain(domain: dict[str, SetDomain]) -> list[int]:
    return [bound for set_name in SETS for bound in domain[set_name].values()]


def python_domain(domain: list[int]) -> dict[str, SetDomain]:
    return {set_name: SetDomain.from_values(domain[8 * index : 8 * index + 8]) for index, set_name in enumerate(SETS)}


@PROPERTY
@given(blocks())
def test_block_encodes_to_the_firmwares_bytes(block):
    values, domain, sensor_id = block
    assume(np.all(np.isfinite(values)))
    python = encode_block(table_from_values(values.tolist()), sensor_id, python_domain(domain))
    assert python == firmware_block(values, domain, sensor_id)


def assert_decodes_alike(block: bytes, board_id: str) -> None:
    """Where the firmware loads the block (or would, on its own sensor), the
    host reads the same surfaces, domain and ID; where it refuses the block
    as damaged, so does the host, but for surfaces that are finite and
    whose output only the firmware bounds (OUTPUT_TOO_LARGE, which SETCOE
    reports to an upload)."""
    status, coefficients, domain = firmware_decode(block, board_id)
    try:
        decoded = decode_block(block)
    except CoefficientBlockError:
        assert status in (BLANK, BAD_MAGIC, BAD_VERSION, BAD_CRC, BAD_VALUES), status
        return
    if status == BAD_VALUES:
        assert all(np.isfinite(decoded.table.values()))
        return
    assert status in (OK, OTHER_SENSOR), status
    assert (status == OTHER_SENSOR) == (decoded.sensor_id not in ("", board_id))
    if status == OK:
        assert np.array_equal(np.array(decoded.table.values(), np.float32), coefficients)
        assert decoded.domain == python_domain(domain)


@PROPERTY
@given(blocks(), sensor_ids, st.data())
def test_block_decodes_as_the_firmware_decodes_it(block, board_id, data):
    values, domain, sensor_id = block
    encoded = bytearray(firmware_block(values, domain, sensor_id))
    if data.draw(st.booleans()):
        position = data.draw(st.integers(0, BLOCK_SIZE - 1))
        encoded[position] = data.draw(st.integers(0, 255))
    if data.draw(st.booleans()):
        # The ID field rewritten, the CRC made to hold: an ID the block cannot carry, or another one.
        field = data.draw(
            st.binary(min_size=8, max_size=8) | sensor_ids.map(lambda text: text.encode().ljust(8, b"\0"))
        )
        encoded[146:154] = field
        encoded[186:188] = crc16_xmodem(bytes(encoded[:186])).to_bytes(2, "little")
    assert_decodes_alike(bytes(encoded), board_id)


@PROPERTY
@given(small_coefficients, sensor_ids)
def test_version_1_blocks_decode_as_the_firmware_decodes_them(values, board_id):
    """Version 1: magic, version 1, the floats, the CRC; the firmware reads
    them with the erased EEPROM behind."""
    body = bytes((0x54, 1)) + values.astype("<f4").tobytes()
    block = body + crc16_xmodem(body).to_bytes(2, "little")
    assert_decodes_alike(block, board_id)
    assert firmware_decode(block, board_id)[0] == OK
    assert decode_block(block).sensor_id == "" and decode_block(block).domain["W"].temperature_centi_c is None


def test_an_erased_block_is_blank_to_the_firmware_and_refused_by_the_host():
    assert firmware_decode(b"\xff" * BLOCK_SIZE, "")[0] == BLANK
    with pytest.raises(CoefficientBlockError, match="magic is 0xFF"):
        decode_block(b"\xff" * BLOCK_SIZE)


@PROPERTY
@given(st.text(st.characters(min_codepoint=1, max_codepoint=127), max_size=10) | sensor_ids)
def test_sensor_id_rule_is_the_firmwares(text):
    assert (sensor_id_problem(text) is None) == firmware_ids_valid([text.encode("ascii")])[0]


def test_sensor_id_rule_edges():
    texts = ["", "N", "NODE-007", "NODE-0007", "a b", "a.b", "a,b", "a*b", "\u00e9"]
    firmware = firmware_ids_valid([text.encode("utf-8") for text in texts])
    assert firmware == [sensor_id_problem(text) is None for text in texts]
    assert firmware == [True, True, True, False, False, False, False, False, False]


@pytest.mark.parametrize("board_id, status", [("NODE-07", OK), ("NODE-08", OTHER_SENSOR), ("", OTHER_SENSOR)])
def test_a_fitted_block_loads_only_on_its_sensor_on_both_sides(board_id, status):
    table = PAPER_DEFAULTS.to_float32()
    domain = {
        "W": SetDomain.covering((-10.12, 44.98), {"X": (-16500.0, 16400.0), "Y": (-16450.0, 16420.0)}),
        "C": SetDomain.covering((-10.05, 45.01), {"X": (-16510.0, 16390.0), "Y": (-16440.0, 16410.0)}),
    }
    block = encode_block(table, "NODE-07", domain)
    assert block == firmware_block(np.array(table.values(), np.float32), firmware_domain(domain), "NODE-07")
    assert firmware_decode(block, board_id)[0] == status
    assert_decodes_alike(block, board_id)
    decoded = decode_block(block)
    assert (decoded.table, decoded.sensor_id, decoded.domain) == (table, "NODE-07", domain)
