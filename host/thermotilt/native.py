"""The IMU reader's own per-sample processing, run on the host.

``build/native/libthermotilt_host.so`` (``host/native/imu_processing.h``) is
``lib/ImuProcessing`` - the class the Nano's firmware runs on every 100 Hz
sample: a Kalman filter per axis and for the temperature, the warming/cooling
trend on the filtered temperature, decimation, and the drift compensation
``filtered - f(T, filtered)`` with the surfaces of the set in force - compiled
for this machine from the same sources, and reached through ctypes. It is
the firmware's processing itself, not a second copy that could drift from it;
``host/tests/test_native_processing.py`` runs the firmware in the twin and
checks its frames against this.

A series starts as the firmware starts streaming once it has found the
sensor: filters unseeded, trend warming. ``reset[i]`` does what RESEED (or a
reconnected sensor) does before sample i: the filters forget their state and
the decimation count restarts; the trend keeps its state. Every sample counts
towards a frame (the firmware streaming; STOP/START and SETDEC are not
modelled). To replay a firmware run, start the series at the first sample
the firmware kept: once it has found the sensor it drops 40 ms of samples
(TEMPERATURE_SETTLE_MS in firmware/imu_reader/main.cpp) before filtering any.

Both functions return a dict of numpy arrays, one value per sample (or per
sample `at` chooses: the discovery replay keeps only its rows); the
names follow run.csv (docs/run-log.md), which has them for the frame rows:

- ``ax_filt``, ``ay_filt``, ``az_filt`` (float32, LSB): Kalman-filtered;
- ``temp_c`` (float32, degC): the filtered temperature (run.csv's imu_temp_c);
- ``set`` (uint8): the surface set, ``WARMING`` 0 or ``COOLING`` 1
  (run.csv's comp_set ``W``/``C``);
- ``ax_comp``, ``ay_comp``, ``az_comp`` (float32, LSB): filtered minus
  f(temp_c, filtered) of that set. The firmware evaluates them only for the
  samples it sends; here every sample has them, from the same function;
- ``frame_due`` (bool): the firmware sends this sample as an IMU frame (one
  in ``decimation``).

A frame prints the filtered and compensated values to 0.1 LSB and the
temperature to 0.001 degC; these are the float32 values before that rounding.

The library also holds single firmware algorithms the host keeps Python
copies of (``host/native/firmware_algorithms.h``: lib/Program's staircase,
lib/Compensation's trend detector, set blend, surface, coefficient block and sensor ID
rule); ``library()`` declares them,
and ``host/tests/test_firmware_differential.py`` checks each copy against them.
``chamber_drive`` is lib/ChamberControl's drive law, for whatever closes a
loop around the chamber's model without the firmware in simavr.
"""

from __future__ import annotations

import ctypes
import math
import numbers
import operator
from collections.abc import Iterable
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from .build_tree import build_dir
from .lsm9ds0 import ACCELERATION_RAW_RANGE, TEMPERATURE_RAW_RANGE
from .program import PAPER_PROPORTIONAL_GAIN
from .surfaces import CoefficientTable

WARMING = 0
COOLING = 1
SET_LETTERS = "WC"  # indexed by the set
DEFAULT_DECIMATION = 10
DEFAULT_HYSTERESIS_C = 0.5
COEFFICIENT_COUNT = 36
DECIMATION_RANGE = range(1, 256)  # SETDEC's
OUTPUTS = ("ax_filt", "ay_filt", "az_filt", "temp_c", "set", "ax_comp", "ay_comp", "az_comp", "frame_due")

_ABI_VERSION = 7  # THERMOTILT_HOST_ABI_VERSION
_OK = 0


class NativeLibraryError(RuntimeError):
    """libthermotilt_host.so is missing, older than this module, or refused a call; one readable line."""


def library_path() -> Path:
    """build/native/libthermotilt_host.so of the build tree build_dir() names."""
    return build_dir() / "native" / "libthermotilt_host.so"


@cache
def _load_library(path: Path) -> ctypes.CDLL:
    try:
        library = ctypes.CDLL(str(path))
    except OSError as error:
        raise NativeLibraryError(f"cannot load {path}: {error}") from None
    pointer, size, single = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_float
    arguments = [
        size,
        pointer,
        pointer,
        pointer,
        ctypes.c_uint,
        single,
        pointer,
        pointer,
        size,
        pointer,
        pointer,
        pointer,
        pointer,
        pointer,
    ]
    prototypes: dict[str, tuple[type, list[type]]] = {
        "thermotilt_host_abi_version": (ctypes.c_int, []),
        "thermotilt_imu_process": (ctypes.c_int, arguments),
        "thermotilt_imu_process_unrounded": (ctypes.c_int, arguments),
        "thermotilt_kalman_estimates": (ctypes.c_int, [size, pointer, pointer, pointer, size, pointer]),
        "thermotilt_program_steps": (ctypes.c_int, [size, pointer, pointer, pointer, pointer, pointer]),
        "thermotilt_trend_sets": (ctypes.c_int, [size, pointer, single, pointer]),
        "thermotilt_set_blend_shares": (ctypes.c_int, [size, pointer, single, pointer]),
        "thermotilt_surface_corrections": (ctypes.c_int, [size, pointer, pointer, pointer, pointer]),
        "thermotilt_coefficient_block_encode": (ctypes.c_int, [pointer, pointer, ctypes.c_char_p, pointer]),
        "thermotilt_coefficient_block_decode": (
            ctypes.c_int,
            [pointer, ctypes.c_char_p, pointer, pointer, pointer],
        ),
        "thermotilt_sensor_ids_valid": (ctypes.c_int, [size, pointer, pointer]),
        "thermotilt_chamber_drive": (
            ctypes.c_int,
            [size, pointer, pointer, single, single, single, ctypes.c_uint8, pointer, pointer],
        ),
    }
    for name, (result, argument_types) in prototypes.items():
        try:
            function = getattr(library, name)
        except AttributeError:
            raise NativeLibraryError(f"{path} has no {name}: it is older than the host; run `make build`") from None
        function.restype = result
        function.argtypes = argument_types
    version = library.thermotilt_host_abi_version()
    if version != _ABI_VERSION:
        raise NativeLibraryError(
            f"{path} has interface version {version}, this host needs {_ABI_VERSION}: run `make build`"
        )
    return library


def library() -> ctypes.CDLL:
    """The loaded library, its version checked and every entry point of
    host/native/*.h declared; the firmware_algorithms.h ones serve the
    differential tests of the host's Python copies."""
    path = library_path()
    if not path.exists():
        raise NativeLibraryError(f"{path} is missing: run `make build` first (or set THERMOTILT_BUILD_DIR)")
    return _load_library(path)


def _series(values: Any, what: str) -> np.ndarray:
    array = np.asarray(values)
    if array.ndim != 1:
        raise ValueError(f"{what} must be a one-dimensional series, not of shape {array.shape}")
    return array


def _integers(values: Any, allowed: range, what: str) -> np.ndarray:
    """values as int16, if every one is an integer in allowed."""
    array = _series(values, what)
    if array.size == 0:
        return np.zeros(0, np.int16)
    if array.dtype.kind == "b" or array.dtype.kind not in "iuf":
        raise ValueError(f"{what} must hold integers, not {array.dtype}")
    if array.dtype.kind == "f" and not (np.all(np.isfinite(array)) and np.all(array == np.round(array))):
        raise ValueError(f"{what} must hold integers (the sensor's registers); imu_process_unrounded takes fractions")
    low, high = array.min(), array.max()
    if low < allowed.start or high >= allowed.stop:
        raise ValueError(f"{what} must lie in {allowed.start}..{allowed.stop - 1}, not {low}..{high}")
    return np.ascontiguousarray(array, dtype=np.int16)


def _floats(values: Any, what: str) -> np.ndarray:
    """values as float32, the firmware's float, if every one is finite there."""
    array = _series(values, what)
    if array.size and (array.dtype.kind == "b" or array.dtype.kind not in "iuf"):
        raise ValueError(f"{what} must hold numbers, not {array.dtype}")
    with np.errstate(over="ignore"):
        single = np.ascontiguousarray(array, dtype=np.float32)
    if not np.all(np.isfinite(single)):
        raise ValueError(f"{what} must be finite in float32 (|x| < 3.4e38)")
    return single


def _flags(values: Any, count: int) -> np.ndarray:
    if values is None:
        return np.zeros(count, np.uint8)
    array = _series(values, "reset")
    if array.size and array.dtype.kind not in "biu":
        raise ValueError(f"reset must hold booleans, not {array.dtype}")
    if array.size != count:
        raise ValueError(f"reset has {array.size} values for {count} samples")
    return np.ascontiguousarray(array != 0, dtype=np.uint8)


def _samples_at(at: Any, count: int) -> np.ndarray | None:
    """at as size_t sample indices in order, or None for every sample."""
    if at is None:
        return None
    array = _series(at, "at")
    if array.size and array.dtype.kind not in "iu":
        raise ValueError(f"at must hold sample indices, not {array.dtype}")
    if array.size and (array.min() < 0 or array.max() >= count or np.any(np.diff(array) < 0)):
        raise ValueError(f"at must hold sample indices 0..{count - 1} in order")
    return np.ascontiguousarray(array, dtype=np.uintp)


def _coefficients(coefficients: CoefficientTable | Iterable[float] | None) -> np.ndarray | None:
    """36 float32 in block order, as the firmware holds them; None: its defaults."""
    if coefficients is None:
        return None
    if isinstance(coefficients, CoefficientTable):
        coefficients = coefficients.values()
    array = np.asarray(coefficients, dtype=np.float64).reshape(-1)
    if array.size != COEFFICIENT_COUNT:
        raise ValueError(
            f"need {COEFFICIENT_COUNT} coefficients (set W, C x axis X, Y, Z x p00..p02), got {array.size}"
        )
    return _floats(array, "coefficients")


def _settings(decimation: int, hysteresis_c: float) -> tuple[int, float]:
    try:
        factor = None if isinstance(decimation, bool) else operator.index(decimation)
    except TypeError:
        factor = None
    if factor is None or factor not in DECIMATION_RANGE:
        raise ValueError(f"decimation must be an integer in 1..255 (SETDEC), not {decimation!r}")
    if not isinstance(hysteresis_c, numbers.Real) or not math.isfinite(hysteresis_c) or hysteresis_c < 0:
        raise ValueError(f"hysteresis_c must be a finite number of degC >= 0, not {hysteresis_c!r}")
    return factor, float(hysteresis_c)


def _run(  # noqa: PLR0913 - thermotilt_imu_process*'s inputs, as imu_process takes them
    function_name: str,
    axes: tuple[np.ndarray, ...],
    temperature: np.ndarray,
    reset: Any,
    decimation: int,
    hysteresis_c: float,
    coefficients: Any,
    at: Any,
) -> dict[str, np.ndarray]:
    count = temperature.size
    for name, axis in zip(("ax", "ay", "az"), axes, strict=True):
        if axis.size != count:
            raise ValueError(f"{name} has {axis.size} samples, the temperature {count}")
    factor, hysteresis = _settings(decimation, hysteresis_c)
    flags = _flags(reset, count)
    table = _coefficients(coefficients)
    samples = _samples_at(at, count)
    rows = count if samples is None else samples.size
    loaded = library()
    accel = np.ascontiguousarray(np.stack(axes, axis=1))
    filtered = np.zeros((rows, 3), np.float32)
    compensated = np.zeros((rows, 3), np.float32)
    temperature_c = np.zeros(rows, np.float32)
    sets = np.zeros(rows, np.uint8)
    due = np.zeros(rows, np.uint8)

    def address(array: np.ndarray | None) -> int | None:
        return None if array is None else array.ctypes.data

    status = getattr(loaded, function_name)(
        count,
        address(accel),
        address(temperature),
        address(flags),
        factor,
        hysteresis,
        address(table),
        address(samples),
        rows,
        address(filtered),
        address(temperature_c),
        address(sets),
        address(compensated),
        address(due),
    )
    if status != _OK:
        raise NativeLibraryError(f"{function_name} refused its arguments (status {status})")
    return {
        "ax_filt": filtered[:, 0].copy(),
        "ay_filt": filtered[:, 1].copy(),
        "az_filt": filtered[:, 2].copy(),
        "temp_c": temperature_c,
        "set": sets,
        "ax_comp": compensated[:, 0].copy(),
        "ay_comp": compensated[:, 1].copy(),
        "az_comp": compensated[:, 2].copy(),
        "frame_due": due.astype(bool),
    }


def imu_process(  # noqa: PLR0913 - the inputs of the C entry point it wraps, each by name
    ax: Any,
    ay: Any,
    az: Any,
    temperature_raw: Any,
    reset: Any = None,
    decimation: int = DEFAULT_DECIMATION,
    hysteresis_c: float = DEFAULT_HYSTERESIS_C,
    coefficients: CoefficientTable | Iterable[float] | None = None,
    at: Any = None,
) -> dict[str, np.ndarray]:
    """The firmware's processing of a series of 100 Hz samples as the LSM9DS0
    gives them: ax, ay, az raw LSB (int16) and temperature_raw OUT_TEMP_XM
    (12-bit, 8 LSB/degC; the firmware adds 21 degC). reset: a flag per sample
    (RESEED before it), or None. decimation: SETDEC's factor; hysteresis_c: the
    trend detector's (the firmware's 0.5). coefficients: a CoefficientTable or
    36 numbers in block order (set W, C x axis X, Y, Z x p00, p10, p01, p20,
    p11, p02), rounded to float32 as the firmware holds them; None for the
    firmware's defaults (the paper's, Z uncorrected). Returns the arrays the
    module docstring lists, for every sample or, given at (sample indices in
    order), for those samples only."""
    temperature = _integers(temperature_raw, TEMPERATURE_RAW_RANGE, "temperature_raw")
    axes = tuple(
        _integers(values, ACCELERATION_RAW_RANGE, name) for name, values in (("ax", ax), ("ay", ay), ("az", az))
    )
    return _run("thermotilt_imu_process", axes, temperature, reset, decimation, hysteresis_c, coefficients, at)


def imu_process_unrounded(  # noqa: PLR0913 - imu_process's signature, for unquantised inputs
    ax: Any,
    ay: Any,
    az: Any,
    temperature_c: Any,
    reset: Any = None,
    decimation: int = DEFAULT_DECIMATION,
    hysteresis_c: float = DEFAULT_HYSTERESIS_C,
    coefficients: CoefficientTable | Iterable[float] | None = None,
    at: Any = None,
) -> dict[str, np.ndarray]:
    """imu_process from inputs the sensor never quantised, e.g. a model's
    predictions: ax, ay, az in LSB and temperature_c the sensor's temperature
    in degC (what the firmware computes as raw / 8 + 21, before the filter).

    What differs from the firmware path is only the inputs' quantisation: the
    sensor gives whole LSB (int16) and whole 1/8 degC, while these go into the
    same filters, trend, decimation and compensation as they are, rounded to
    float32 and, in the Kalman filters, to 2^-15 of a unit (lib/Kalman).
    On whole LSB and temperatures raw / 8 + 21 it returns exactly what
    imu_process returns."""
    temperature = _floats(temperature_c, "temperature_c")
    axes = tuple(_floats(values, name) for name, values in (("ax", ax), ("ay", ay), ("az", az)))
    return _run(
        "thermotilt_imu_process_unrounded", axes, temperature, reset, decimation, hysteresis_c, coefficients, at
    )


def kalman_estimates(measurements: Any, reset: Any = None, at: Any = None) -> np.ndarray:
    """One channel of imu_process_unrounded: the Kalman filter lib/ImuProcessing
    runs for each axis and for the temperature, over a series with the same
    resets, its estimate after each sample (or each sample `at` chooses) as
    float32 - the same values as that function's ``ax_filt``, ``ay_filt``,
    ``az_filt`` or ``temp_c`` for the channel (test_native_processing), for
    a caller that has changed one channel and kept the others' outputs."""
    values = _floats(measurements, "measurements")
    flags = _flags(reset, values.size)
    samples = _samples_at(at, values.size)
    estimates = np.zeros(values.size if samples is None else samples.size, np.float32)
    status = library().thermotilt_kalman_estimates(
        values.size,
        values.ctypes.data,
        flags.ctypes.data,
        None if samples is None else samples.ctypes.data,
        0 if samples is None else samples.size,
        estimates.ctypes.data,
    )
    if status != _OK:
        raise NativeLibraryError(f"thermotilt_kalman_estimates refused its arguments (status {status})")
    return estimates


DRIVE_OFF, DRIVE_HEAT, DRIVE_COOL = 0, 1, 2  # lib/ChamberControl's Direction


def chamber_drive(
    setpoint_c: Any,
    measured_c: Any,
    dt_s: float,
    proportional_gain: float = PAPER_PROPORTIONAL_GAIN,
    integral_gain: float = 0.0,
    rounded_error: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """(pwm 0..255, direction DRIVE_*) per sample: one lib/ChamberControl
    controller updated with each setpoint and measured temperature in order,
    dt_s apart (float32, as on the Mega)."""
    setpoint = _floats(setpoint_c, "setpoint_c")
    measured = _floats(measured_c, "measured_c")
    if setpoint.size != measured.size:
        raise ValueError(f"setpoint_c has {setpoint.size} values and measured_c {measured.size}")
    pwm = np.zeros(setpoint.size, np.uint8)
    direction = np.zeros(setpoint.size, np.uint8)
    status = library().thermotilt_chamber_drive(
        setpoint.size,
        setpoint.ctypes.data,
        measured.ctypes.data,
        dt_s,
        proportional_gain,
        integral_gain,
        rounded_error,
        pwm.ctypes.data,
        direction.ctypes.data,
    )
    if status != _OK:
        raise NativeLibraryError("thermotilt_chamber_drive refused its arguments")
    return pwm, direction
