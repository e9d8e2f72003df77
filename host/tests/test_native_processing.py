"""thermotilt.native (build/native/libthermotilt_host.so, lib/ImuProcessing
compiled for the host) against the firmware itself: the IMU reader runs in the
twin, every sample the twin served it is recorded, and the native series over
those samples must give every IMU frame the firmware sent - its filtered
values, temperature, set, compensated values and which samples were frames.

Served and read samples: Python sets the LSM9DS0 model's outputs once per
10 ms step; the model latches them at its own 100 Hz clock (sim/lsm9ds0.c),
so each served sample is in the registers for one sensor period, and the
firmware reads each sensor sample at most once (data-ready). A frame carries
the raw sample it was computed from, which places it among the served
samples (the noise makes every raw triple unique within a few steps). The
firmware could still miss a sample (read too late, two ticks) or drop some
(the first 40 ms after it found the sensor). Nothing is assumed about that:
consecutive frames must lie exactly `decimation` served samples apart (a
missed sample would make it 11), the series starts `decimation - 1` samples
before the first frame, and a RESEED's first sample is `decimation - 1`
before the next frame; the filtered values then confirm the starts, since a
seed one sample off moves a young filter's mean by LSB, not by 0.05.

Printed precision: a frame has the filtered and compensated values at 0.1 LSB
and the temperature at 0.001 degC (avr-libc's dtostrf). The native float32,
rounded to as many decimals the way dtostrf rounds, must be the frame's
number. dtostrf rounds an exact tie away from zero (-1678.25 -> -1678.3)
where printf rounds it to even (-1678.2): 11 of the 8386 values of the
synthetic run below are such ties (x.25, x.75), so the emulation uses
Decimal's ROUND_HALF_UP. Within float32's resolution of a tie, where
dtostrf's 7-digit conversion could round either way, either neighbour is
accepted (a wrong replay misses by whole LSB, not by 1e-7 of a value).
"""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal

import numpy as np
import pytest

from thermotilt import native
from thermotilt.physics import Model
from thermotilt.set_blend import FIRMWARE_POWER_UP_SHARE, blend
from thermotilt.surfaces import PAPER_DEFAULTS, CoefficientTable, Surface
from thermotilt.twin import simulate
from thermotilt.twin.boards import Board
from thermotilt.twin.scenarios import ScenarioOptions, build
from thermotilt.wire.protocol import FRAMES, FrameReader, build_frame

STEP_S = simulate.STEP_S
DECIMATION = 10
# Z surfaces made of binary fractions, so that the SETCOE text, the AVR's
# strtod and numpy's float32 give the same bits; Z is uncorrected by default.
Z_WARMING = Surface(12.5, -0.75, 0.0625, 0.0078125, -0.00048828125, 0.0)
Z_COOLING = Surface(-8.25, 0.5, -0.03125, -0.00390625, 0.000244140625, 0.0)
COEFFICIENTS = CoefficientTable({**PAPER_DEFAULTS.surfaces, ("W", "Z"): Z_WARMING, ("C", "Z"): Z_COOLING})
# IMU frame fields and the decimals the firmware prints them with.
PRINTED = (
    ("ax_filt", 1),
    ("ay_filt", 1),
    ("az_filt", 1),
    ("ax_comp", 1),
    ("ay_comp", 1),
    ("az_comp", 1),
    ("temp_c", 3),
)
IMU_FIELDS = FRAMES["IMU"].field_names


def synthetic_samples(steps: int, seed: int = 5) -> np.ndarray:
    """steps x 4 int (ax, ay, az, temperature raw): the tilt with the model's
    17.4 LSB of noise, a Y step at 40 s, and a temperature swinging
    20..30 degC over a minute, so the trend turns both ways."""
    rng = np.random.default_rng(seed)
    t = np.arange(steps) * STEP_S
    ax = -1700 + rng.normal(0.0, 17.4, steps)
    ay = -400 + rng.normal(0.0, 17.4, steps) + np.where(t >= 40.0, 5000, 0)
    az = 16000 + rng.normal(0.0, 17.4, steps)
    temperature_c = 25.0 + 5.0 * np.sin(2 * math.pi * t / 60.0)
    temperature_raw = (temperature_c - 21.0) * 8.0 + rng.normal(0.0, 0.5, steps)
    return np.round(np.column_stack([ax, ay, az, temperature_raw])).astype(int)


def frame_steps(frames: list, served: np.ndarray) -> list[int]:
    """The served step of each frame's raw sample: near its t_ms, unique."""
    steps = []
    for frame in frames:
        raw = (frame["ax_raw"], frame["ay_raw"], frame["az_raw"])
        near = round(frame["t_ms"] / 1000 / STEP_S)
        candidates = [k for k in range(max(near - 4, 0), min(near + 2, len(served))) if tuple(served[k, :3]) == raw]
        assert len(candidates) == 1, f"frame {frame.line} matches served steps {candidates}"
        steps.append(candidates[0])
    return steps


def replay_starts(steps: list[int], reseeds: list[int]) -> tuple[int, list[int]]:
    """The first sample the firmware filtered and the first after each RESEED
    (sent in the step given), from the frames' places; checks their spacing."""
    first = steps[0] - (DECIMATION - 1)
    starts = []
    pending = list(reseeds)
    for previous, step in zip(steps, steps[1:]):
        if pending and step - (DECIMATION - 1) >= pending[0]:
            start = step - (DECIMATION - 1)
            # Handled at the firmware's next loop pass: within the 10 ms step it arrived in or the next.
            assert pending[0] <= start <= pending[0] + 2, (pending[0], start)
            assert previous < start
            starts.append(start)
            pending.pop(0)
        else:
            assert step - previous == DECIMATION, f"frames {DECIMATION} samples apart, not {step - previous}"
    assert not pending, "a RESEED without a frame after it"
    return first, starts


def printed_equal(value: np.float32, text: str, decimals: int) -> bool:
    """value as the firmware prints it with this many decimals is text."""
    unit = Decimal(1).scaleb(-decimals)
    if float(Decimal(float(value)).quantize(unit, rounding=ROUND_HALF_UP)) == float(text):
        return True
    scaled = float(value) * 10**decimals
    near_tie = abs(scaled - math.floor(scaled) - 0.5) <= abs(scaled) * 2.0**-22
    return near_tie and abs(float(text) - float(value)) <= 0.5 * 10**-decimals * (1 + 1e-6)


def assert_frames_match(frames: list, steps: list[int], first: int, result: dict[str, np.ndarray]) -> None:
    indices = [step - first for step in steps]
    # The series has no frame the firmware did not send, up to its last one.
    assert np.flatnonzero(result["frame_due"][: indices[-1] + 1]).tolist() == indices
    mismatches = []
    for frame, index in zip(frames, indices, strict=True):
        for name, decimals in PRINTED:
            text = frame.raw_fields[IMU_FIELDS.index(name)]
            if not printed_equal(result[name][index], text, decimals):
                mismatches.append(f"{name} {text} vs {float(result[name][index])!r} at {frame.line}")
        if frame["comp_set"] != native.SET_LETTERS[result["set"][index]]:
            mismatches.append(f"set {frame['comp_set']} vs {result['set'][index]} at {frame.line}")
    assert not mismatches, f"{len(mismatches)} differences, first: {mismatches[:5]}"


@pytest.mark.slow
@pytest.mark.twin
def test_native_series_gives_every_frame_the_firmware_sent():
    duration_s = 120.0
    steps_total = round(duration_s / STEP_S)
    served = synthetic_samples(steps_total)
    reseed_steps = [round(40.0 / STEP_S), round(80.0 / STEP_S) + 3]
    reader = FrameReader()
    frames = []
    with Board.imu_reader() as board:
        board.attach_lsm9ds0()
        board.write_uart(
            "".join(
                build_frame("SETCOE", seq, [s, "Z", *COEFFICIENTS.surface(s, "Z")]) for seq, s in ((1, "W"), (2, "C"))
            ).encode()
        )
        for step in range(steps_total):
            if step in reseed_steps:
                board.write_uart(build_frame("RESEED", 10 + step).encode())
            board.set_lsm9ds0(*(int(value) for value in served[step]))
            board.run_until((step + 1) * STEP_S)
            frames += reader.feed(board.read_uart())
    assert reader.malformed == 0
    acks = [frame["cmd_type"] for frame in frames if frame.type == "ACK"]
    assert acks == ["SETCOE", "SETCOE", "RESEED", "RESEED"]
    imu = [frame for frame in frames if frame.type == "IMU"]
    assert len(imu) > 1150 and {frame["coef_source"] for frame in imu} == {"U"}
    # The series turned the trend both ways; the frames show it.
    assert {frame["comp_set"] for frame in imu} == {"W", "C"}

    steps = frame_steps(imu, served)
    first, starts = replay_starts(steps, reseed_steps)
    replay = served[first:]
    reset = np.zeros(len(replay), bool)
    reset[[start - first for start in starts]] = True
    result = native.imu_process(
        replay[:, 0], replay[:, 1], replay[:, 2], replay[:, 3], reset, decimation=DECIMATION, coefficients=COEFFICIENTS
    )
    assert_frames_match(imu, steps, first, result)


@pytest.mark.slow
@pytest.mark.twin
def test_native_series_replays_a_twin_run_of_the_model(tmp_path, monkeypatch):
    """The twin's own loop (simulate.run) with the physics model: what it
    served the IMU, recorded at Board.set_lsm9ds0, replayed natively."""
    served = []
    original = Board.set_lsm9ds0

    def recording(board, ax, ay, az, temperature_raw):
        served.append((ax, ay, az, temperature_raw))
        original(board, ax, ay, az, temperature_raw)

    monkeypatch.setattr(Board, "set_lsm9ds0", recording)
    scenario = build("field-alternating", ScenarioOptions(duration_s=90.0, incl_x_deg=30.0))
    simulate.run(scenario, Model.load(), tmp_path / "run", seed=3)
    served_array = np.array(served, dtype=int)
    imu = [
        frame
        for frame in FrameReader().feed((tmp_path / "run" / "serial" / "imu_reader.txt").read_bytes())
        if frame.type == "IMU"
    ]
    assert len(imu) > 850

    steps = frame_steps(imu, served_array)
    first, _ = replay_starts(steps, [])
    replay = served_array[first:]
    result = native.imu_process(replay[:, 0], replay[:, 1], replay[:, 2], replay[:, 3])
    assert_frames_match(imu, steps, first, result)


# ---- the library on its own ----------------------------------------------


def decimated(reset: np.ndarray, decimation: int) -> list[bool]:
    """lib/Kalman's Decimator, restarted where reset is set."""
    due, count = [], 0
    for flag in reset:
        count = 0 if flag else count
        count += 1
        due.append(count == decimation)
        count = 0 if count == decimation else count
    return due


@pytest.mark.twin
def test_unrounded_equals_the_firmware_path_on_integer_inputs():
    samples = synthetic_samples(3000, seed=9)
    reset = np.zeros(3000, bool)
    reset[[700, 701, 2222]] = True
    for decimation, hysteresis in ((10, 0.5), (1, 0.0), (7, 0.25)):
        rounded = native.imu_process(
            samples[:, 0],
            samples[:, 1],
            samples[:, 2],
            samples[:, 3],
            reset,
            decimation=decimation,
            hysteresis_c=hysteresis,
            coefficients=COEFFICIENTS,
        )
        unrounded = native.imu_process_unrounded(
            samples[:, 0].astype(float),
            samples[:, 1],
            samples[:, 2],
            samples[:, 3] / 8.0 + 21.0,
            reset,
            decimation=decimation,
            hysteresis_c=hysteresis,
            coefficients=COEFFICIENTS,
        )
        assert set(rounded) == set(unrounded) == set(native.OUTPUTS)
        for name in native.OUTPUTS:
            assert rounded[name].dtype == unrounded[name].dtype
            np.testing.assert_array_equal(rounded[name], unrounded[name], err_msg=name, strict=True)
        assert rounded["frame_due"].tolist() == decimated(reset, decimation)


@pytest.mark.twin
def test_outputs_are_the_firmware_arithmetic():
    """The first sample seeds the filters (output = input), the temperature is
    raw / 8 + 21, and the compensated values are filtered - f(T, filtered),
    the sets' surfaces blended halfway at power-up (set_blend)."""
    result = native.imu_process([-1700, -1600], [400, 400], [16000, 16000], [32, 40], decimation=2)
    assert result["ax_filt"][0] == -1700.0 and result["temp_c"][0] == 25.0
    # The second sample gets a gain of (R + Q) / (2R + Q), about 1/2.
    assert result["ax_filt"][1] == pytest.approx(-1650.0, abs=1e-3)
    assert result["frame_due"].tolist() == [False, True]
    assert result["set"].tolist() == [native.WARMING, native.WARMING]
    surfaces = [PAPER_DEFAULTS.surface(set_name, "Y").evaluate(25.0, 400.0) for set_name in ("W", "C")]
    expected = 400.0 - blend(FIRMWARE_POWER_UP_SHARE, *surfaces)
    assert result["ay_comp"][0] == pytest.approx(expected, abs=1e-3)
    assert result["az_comp"][0] == 16000.0  # Z uncorrected


@pytest.mark.twin
def test_default_coefficients_are_the_paper_table_in_float32():
    samples = synthetic_samples(6000, seed=2)
    columns = samples[:, 0], samples[:, 1], samples[:, 2], samples[:, 3]
    defaults = native.imu_process(*columns)
    table = native.imu_process(*columns, coefficients=PAPER_DEFAULTS)
    listed = native.imu_process(*columns, coefficients=np.array(PAPER_DEFAULTS.values()).reshape(2, 3, 6))
    assert set(defaults["set"]) == {native.WARMING, native.COOLING}
    for name in native.OUTPUTS:
        np.testing.assert_array_equal(defaults[name], table[name], err_msg=name)
        np.testing.assert_array_equal(defaults[name], listed[name], err_msg=name)


@pytest.mark.twin
def test_unrounded_takes_fractions():
    result = native.imu_process_unrounded([-1700.25, -1699.75], [0.5, 0.5], [1e-3, 1e-3], [24.3, 24.3])
    assert result["ax_filt"][0] == np.float32(-1700.25)
    # The filters hold 2^-15 of a unit (lib/Kalman): within half of that.
    assert result["temp_c"][0] == pytest.approx(24.3, abs=2**-16)
    assert result["ax_filt"][1] == pytest.approx(-1700.0, abs=1e-3)
    assert result["az_filt"][1] == pytest.approx(1e-3, abs=2**-16)
    assert result["az_filt"][1] != 0


@pytest.mark.twin
def test_outputs_at_chosen_samples_are_those_of_the_whole_series():
    """at: only those samples' outputs (a repeat twice), every sample still
    processed, so each row is the whole series' at its sample."""
    samples = synthetic_samples(6000, seed=3)
    columns = samples[:, 0], samples[:, 1], samples[:, 2], samples[:, 3]
    reset = np.zeros(6000, dtype=bool)
    reset[[0, 2500]] = True
    at = np.array([0, 7, 7, 2499, 2500, 2501, 5999])
    whole = native.imu_process(*columns, reset)
    chosen = native.imu_process(*columns, reset, at=at)
    unrounded = native.imu_process_unrounded(*columns[:3], samples[:, 3] / 8.0 + 21.0, reset, at=at)
    for name in native.OUTPUTS:
        np.testing.assert_array_equal(chosen[name], whole[name][at], err_msg=name)
        np.testing.assert_array_equal(unrounded[name], whole[name][at], err_msg=name)
    assert all(native.imu_process(*columns, at=[])[name].size == 0 for name in native.OUTPUTS)


@pytest.mark.twin
@pytest.mark.parametrize("at", [None, np.array([0, 7, 7, 2499, 2500, 2501, 4000])])
def test_one_channel_is_that_channel_of_the_whole_processing(at):
    """kalman_estimates runs one channel's filter alone; with fractional
    inputs and resets it gives imu_process_unrounded's floats exactly."""
    rng = np.random.default_rng(5)
    series = rng.standard_normal((4, 6000)).cumsum(axis=1) * 3.0 + np.array([[16000.0], [-200.0], [5.0], [25.0]])
    reset = np.zeros(6000, dtype=bool)
    reset[[0, 2500, 2501]] = True
    whole = native.imu_process_unrounded(*series, reset, at=at)
    for values, name in zip(series, ("ax_filt", "ay_filt", "az_filt", "temp_c")):
        alone = native.kalman_estimates(values, reset, at=at)
        assert alone.dtype == np.float32
        np.testing.assert_array_equal(alone.view(np.uint32), whole[name].view(np.uint32), err_msg=name)
    assert native.kalman_estimates([], at=[]).size == 0


@pytest.mark.twin
def test_empty_series():
    result = native.imu_process([], [], [], [])
    assert all(result[name].size == 0 for name in native.OUTPUTS)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: native.imu_process([1.5], [0], [0], [0]), "ax must hold integers"),
        (lambda: native.imu_process([0], [40000], [0], [0]), "ay must lie in -32768..32767"),
        (lambda: native.imu_process([0], [0], [0], [2048]), "temperature_raw must lie in -2048..2047"),
        (lambda: native.imu_process([0, 0], [0], [0], [0, 0]), "ay has 1 samples, the temperature 2"),
        (lambda: native.imu_process([0], [0], [0], [0], decimation=0), "decimation must be an integer in 1..255"),
        (lambda: native.imu_process([0], [0], [0], [0], hysteresis_c=math.nan), "hysteresis_c must be"),
        (lambda: native.imu_process([0], [0], [0], [0], reset=[True, False]), "reset has 2 values for 1"),
        (lambda: native.imu_process([0], [0], [0], [0], coefficients=[0.0] * 35), "need 36 coefficients"),
        (lambda: native.imu_process_unrounded([math.inf], [0], [0], [0]), "ax must be finite"),
        (lambda: native.imu_process_unrounded([[0.0]], [0], [0], [0]), "ax must be a one-dimensional series"),
        (lambda: native.imu_process([0, 0], [0, 0], [0, 0], [0, 0], at=[1, 0]), r"at must hold sample indices 0\.\.1"),
        (lambda: native.imu_process([0], [0], [0], [0], at=[1]), r"at must hold sample indices 0\.\.0 in order"),
        (lambda: native.imu_process([0], [0], [0], [0], at=[0.0]), "at must hold sample indices, not float64"),
        (lambda: native.kalman_estimates([math.nan]), "measurements must be finite"),
        (lambda: native.kalman_estimates([0.0, 1.0], at=[2]), r"at must hold sample indices 0\.\.1 in order"),
    ],
)
def test_bad_input_is_one_readable_error(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_a_missing_library_is_one_readable_error(tmp_path, monkeypatch):
    monkeypatch.setenv("THERMOTILT_BUILD_DIR", str(tmp_path))
    with pytest.raises(native.NativeLibraryError) as error:
        native.imu_process([0], [0], [0], [0])
    message = str(error.value)
    assert "\n" not in message
    assert (
        message == f"{tmp_path}/native/libthermotilt_host.so is missing: run `make build` first "
        f"(or set THERMOTILT_BUILD_DIR)"
    )
