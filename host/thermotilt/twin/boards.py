"""The digital twin's boards: the real firmware images running in simavr.

Each :class:`Board` is one MCU from ``build/native/libthermotilt_twin.so``
(``sim/twin.h``), reached through ctypes. Python supplies what the sensors
would see (thermistor voltages, the LSM9DS0's raw outputs) and reads back
what the firmware does (serial bytes, the L298N drive), stepping the board to
a simulated time with :meth:`Board.run_until`. The same calls give the same
bytes; only the optional pseudo-terminal depends on who talks to it.
"""

from __future__ import annotations

import bisect
import ctypes
import math
import operator
import os
import re
import subprocess
from collections import Counter
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from types import TracebackType
from typing import NamedTuple

from ..build_tree import build_dir
from ..lsm9ds0 import ACCELERATION_RAW_RANGE, TEMPERATURE_RAW_RANGE

DEFAULT_FREQUENCY_HZ = 16_000_000
SUPPLY_MILLIVOLTS = 5000.0

_FIRMWARE_MCU = {"imu_reader": "atmega328p", "thermal_chamber": "atmega2560"}
# simavr 1.6 models ADC0..ADC7 only, also on the Mega.
ADC_CHANNELS = 8
_ADC_FAULTS = {"none": 0, "open": 1, "short": 2}
_SENSOR_FAULTS = {"none": 0, "absent": 1, "stuck": 2}
_RUNNING, _DONE, _CRASHED = 0, 1, 2
_ERROR_CAPACITY = 512
_MAX_SEED = 2**64


class TwinError(RuntimeError):
    """The twin cannot do what was asked: a missing build, a crashed firmware, a closed board."""


class Drive(NamedTuple):
    """What the L298N delivered to the Peltier since the previous read (read every step)."""

    duty: float  # mean fraction of the time current flowed, 0..1
    direction: int  # +1 heating, -1 cooling, 0 no current
    pwm: int  # the last analogWrite value the firmware gave ENA, 0..255


def firmware_elf(name: str) -> Path:
    """The built image of "imu_reader" or "thermal_chamber"."""
    if name not in _FIRMWARE_MCU:
        raise ValueError(f"unknown firmware {name!r}: expected one of {sorted(_FIRMWARE_MCU)}")
    return _existing(build_dir() / _FIRMWARE_MCU[name] / f"{name}.elf")


def library_path() -> Path:
    return build_dir() / "native" / "libthermotilt_twin.so"


def _existing(path: Path) -> Path:
    if not path.exists():
        raise TwinError(f"{path} is missing: run `make build` first")
    return path


@cache
def _load_library(path: Path) -> ctypes.CDLL:
    try:
        library = ctypes.CDLL(str(path), use_errno=True)
    except OSError as error:
        # The loader's reason, e.g. a libsimavr without a symbol the build linked against.
        raise TwinError(f"cannot load {path}: {error}; run `make build` again") from None
    handle = ctypes.c_void_p
    prototypes: dict[str, tuple[type | None, list[type]]] = {
        "twin_create": (
            handle,
            [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32, ctypes.c_char_p, ctypes.c_size_t],
        ),
        "twin_free": (None, [handle]),
        "twin_run_until": (ctypes.c_int, [handle, ctypes.c_uint64]),
        "twin_cycles": (ctypes.c_uint64, [handle]),
        "twin_uart_pending": (ctypes.c_size_t, [handle]),
        "twin_uart_read": (ctypes.c_size_t, [handle, ctypes.c_char_p, ctypes.c_size_t]),
        "twin_uart_write": (ctypes.c_int, [handle, ctypes.c_char_p, ctypes.c_size_t]),
        "twin_uart_open_pty": (ctypes.c_char_p, [handle]),
        "twin_uart_set_corruption": (None, [handle, ctypes.c_double, ctypes.c_uint64]),
        "twin_uart_corrupted_bytes": (ctypes.c_uint64, [handle]),
        "twin_pty_dropped_bytes": (ctypes.c_uint64, [handle]),
        "twin_hang": (ctypes.c_int, [handle]),
        "twin_eeprom_size": (ctypes.c_size_t, [handle]),
        "twin_eeprom_read": (ctypes.c_int, [handle, ctypes.c_size_t, ctypes.c_char_p, ctypes.c_size_t]),
        "twin_eeprom_write": (ctypes.c_int, [handle, ctypes.c_size_t, ctypes.c_char_p, ctypes.c_size_t]),
        "twin_stack_untouched": (ctypes.c_size_t, [handle, ctypes.POINTER(ctypes.c_size_t)]),
        "twin_cycle_counts": (None, [handle, ctypes.POINTER(ctypes.c_uint64), ctypes.POINTER(ctypes.c_uint64)]),
        "twin_run_one_instruction_per_call": (None, [handle, ctypes.c_int]),
        "twin_profile_start": (ctypes.c_int, [handle, ctypes.c_uint64, ctypes.c_size_t]),
        "twin_profile_stop": (None, [handle]),
        "twin_profile_frames": (ctypes.c_size_t, []),
        "twin_profile_counts": (None, [handle, ctypes.POINTER(ctypes.c_uint64), ctypes.POINTER(ctypes.c_size_t)]),
        "twin_profile_read": (ctypes.c_size_t, [handle, ctypes.POINTER(ctypes.c_uint32), ctypes.c_size_t]),
        "twin_adc_set_millivolts": (ctypes.c_int, [handle, ctypes.c_uint, ctypes.c_double]),
        "twin_adc_set_fault": (ctypes.c_int, [handle, ctypes.c_uint, ctypes.c_int]),
        "twin_lsm9ds0_attach": (None, [handle]),
        "twin_lsm9ds0_set": (
            ctypes.c_int,
            [handle, ctypes.c_int16, ctypes.c_int16, ctypes.c_int16, ctypes.c_int16],
        ),
        "twin_lsm9ds0_set_fault": (ctypes.c_int, [handle, ctypes.c_int]),
        "twin_lsm9ds0_wire_data_ready": (ctypes.c_int, [handle, ctypes.c_int]),
        "twin_l298n_attach": (ctypes.c_int, [handle]),
        "twin_l298n_read": (
            ctypes.c_int,
            [handle, ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int)],
        ),
        "twin_l298n_set_disconnected": (ctypes.c_int, [handle, ctypes.c_int]),
    }
    for name, (result, arguments) in prototypes.items():
        try:
            function = getattr(library, name)
        except AttributeError:
            raise TwinError(f"{path} has no {name}: it is older than the host; run `make build`") from None
        function.restype = result
        function.argtypes = arguments
    return library


def _library() -> ctypes.CDLL:
    return _load_library(_existing(library_path()))


def _choice(value: str, choices: dict[str, int], what: str) -> int:
    if value not in choices:
        raise ValueError(f"{what} must be one of {list(choices)}, not {value!r}")
    return choices[value]


def _integer_in(value: int, allowed: range, what: str) -> int:
    """value as an int (numpy integers too) if it lies in allowed."""
    if type(value) is int and value in allowed:
        return value
    try:
        number = None if isinstance(value, bool) else operator.index(value)
    except TypeError:
        number = None
    if number is None or number not in allowed:
        raise ValueError(f"{what} must be an integer in {allowed.start}..{allowed.stop - 1}, not {value!r}")
    return number


_NO_FRAME = 2**32 - 1
# avr-nm's lines: address, size (for symbols that have one), type, demangled name.
_NM_LINE = re.compile(r"^([0-9a-f]+) (?:([0-9a-f]+) )?([A-Za-z]) (.+)$")
_CODE_SYMBOL_TYPES = frozenset("TtWw")
# Data-space symbols carry avr-gcc's 0x800000 offset; code lies below.
_DATA_SPACE = 0x800000
_CLONE_SUFFIX = re.compile(r" \[clone [^]]+\]")
_RUNTIME_ROUTINE = re.compile(r"^__(?!vector_)")


class FirmwareSymbols:
    """A firmware image's functions by flash address, from its symbol table
    (avr-nm), demangled and without GCC's clone suffixes. Only functions that
    stay out of line have a symbol: code that LTO inlined is part of its
    caller."""

    def __init__(self, elf: Path | str) -> None:
        listing = subprocess.run(
            ["avr-nm", "--numeric-sort", "--print-size", "--demangle", "--defined-only", str(_existing(Path(elf)))],
            check=True,
            capture_output=True,
            text=True,
        ).stdout
        self._sized: list[tuple[int, int, str]] = []
        self._labels: list[tuple[int, str]] = []
        for line in listing.splitlines():
            match = _NM_LINE.match(line)
            if not match or match[3] not in _CODE_SYMBOL_TYPES or int(match[1], 16) >= _DATA_SPACE:
                continue
            address, name = int(match[1], 16), _CLONE_SUFFIX.sub("", match[4])
            if match[2]:
                self._sized.append((address, address + int(match[2], 16), name))
            else:
                self._labels.append((address, name))
        self._sized_starts = [start for start, _, _ in self._sized]
        self._label_starts = [start for start, _ in self._labels]
        self._found: dict[int, str] = {}

    def name_at(self, address: int) -> str:
        """The function holding this flash byte address: the sized symbol
        around it, else the assembly label before it, else "?"."""
        name = self._found.get(address)
        if name is None:
            name = self._found[address] = self._look_up(address)
        return name

    def _look_up(self, address: int) -> str:
        index = bisect.bisect_right(self._sized_starts, address) - 1
        if index >= 0 and address < self._sized[index][1]:
            return self._sized[index][2]
        index = bisect.bisect_right(self._label_starts, address) - 1
        return self._labels[index][1] if index >= 0 else "?"

    def names(self) -> set[str]:
        return {name for _, _, name in self._sized} | {name for _, name in self._labels}


def is_runtime_routine(name: str) -> bool:
    """libgcc's and avr-libc's assembly routines: soft float, integer
    division, prologues and epilogues (their names begin with __; the
    interrupt handlers' __vector_N do not count)."""
    return _RUNTIME_ROUTINE.match(name) is not None


@dataclass(frozen=True)
class Profile:
    """What the profiler saw: each sample is the PC of the running
    instruction, then the call sites above it, innermost first (an
    interrupt's entry counts as a call from the instruction it interrupted),
    as flash byte addresses. taken counts every sample, also those the
    buffer had no room for."""

    period_cycles: int
    taken: int
    samples: tuple[tuple[int, ...], ...]

    def stacks(self, symbols: FirmwareSymbols) -> Counter[tuple[str, ...]]:
        """Samples per call stack, as function names innermost first."""
        return Counter(tuple(symbols.name_at(address) for address in frames) for frames in self.samples)

    def by_function(self, symbols: FirmwareSymbols) -> Counter[str]:
        """Samples per function. A runtime routine's (soft float, integer
        division, prologues: libgcc's and avr-libc's __ names) go to the
        first function up the stack that is not one; a sample whose stack
        holds none stays with the routine."""
        counts: Counter[str] = Counter()
        for names, samples in self.stacks(symbols).items():
            counts[next((name for name in names if not is_runtime_routine(name)), names[0])] += samples
        return counts


class Board:
    """One MCU running a firmware image. Use as a context manager, or close()."""

    def __init__(self, elf: Path | str, mcu: str, frequency_hz: int = DEFAULT_FREQUENCY_HZ) -> None:
        self._handle: int | None = None
        self._profile_period = 0
        # read_l298n's out-parameters, made once: it runs every step.
        self._drive_out = (ctypes.c_double(), ctypes.c_int(), ctypes.c_int())
        self._drive_refs = tuple(ctypes.byref(value) for value in self._drive_out)
        frequency_hz = _integer_in(frequency_hz, range(1, 2**32), "frequency_hz")
        elf = _existing(Path(elf))
        self._lib = _library()
        error = ctypes.create_string_buffer(_ERROR_CAPACITY)
        handle = self._lib.twin_create(str(elf).encode(), mcu.encode(), frequency_hz, error, _ERROR_CAPACITY)
        if not handle:
            raise TwinError(error.value.decode(errors="replace"))
        self._handle = handle
        self.elf = elf
        self.mcu = mcu
        self.frequency_hz = frequency_hz

    @classmethod
    def imu_reader(cls) -> Board:
        """The Nano's image with the LSM9DS0 reader (attach_lsm9ds0 to give it a sensor)."""
        return cls(firmware_elf("imu_reader"), _FIRMWARE_MCU["imu_reader"])

    @classmethod
    def thermal_chamber(cls) -> Board:
        """The Mega's image driving the Peltier (attach_l298n to watch it)."""
        return cls(firmware_elf("thermal_chamber"), _FIRMWARE_MCU["thermal_chamber"])

    def close(self) -> None:
        if self._handle is not None:
            self._lib.twin_free(self._handle)
            self._handle = None

    def __enter__(self) -> Board:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()

    def _live(self) -> int:
        if self._handle is None:
            raise TwinError("the board is closed")
        return self._handle

    @property
    def cycles(self) -> int:
        return int(self._lib.twin_cycles(self._live()))

    @property
    def seconds(self) -> float:
        return self.cycles / self.frequency_hz

    def run_until(self, seconds: float) -> None:
        """Runs the firmware until at least this much simulated time has
        passed since start (self.seconds >= seconds after it: a caller that
        waits for a deadline must reach it, not stop a cycle short)."""
        if not math.isfinite(seconds) or seconds < 0:
            raise ValueError(f"seconds must be a finite time >= 0, not {seconds!r}")
        until = math.ceil(seconds * self.frequency_hz)
        if until / self.frequency_hz < seconds:  # the product rounded down
            until += 1
        state = self._lib.twin_run_until(self._live(), until)
        if state == _CRASHED:
            raise TwinError(f"{self.elf.name} crashed at {self.seconds:.6f} s simulated")
        if state == _DONE:
            raise TwinError(f"{self.elf.name} stopped (slept with interrupts off) at {self.seconds:.6f} s simulated")

    def read_uart(self) -> bytes:
        """Every byte the firmware sent on USART0 since the previous read."""
        handle = self._live()
        pending = self._lib.twin_uart_pending(handle)
        if pending == 0:
            return b""
        buffer = ctypes.create_string_buffer(pending)
        count = self._lib.twin_uart_read(handle, buffer, pending)
        return buffer.raw[:count]

    def write_uart(self, data: bytes | bytearray | memoryview) -> None:
        """Queues bytes for the firmware's USART0; they arrive at 115200 baud."""
        if not isinstance(data, bytes | bytearray | memoryview):
            raise TypeError(f"write_uart takes bytes, not {type(data).__name__}")
        payload = bytes(data)
        if self._lib.twin_uart_write(self._live(), payload, len(payload)) != 0:
            raise MemoryError("the twin could not queue the bytes")

    def open_pty(self) -> str:
        """A pseudo-terminal wired to USART0 (raw mode); returns its path, e.g. /dev/pts/3."""
        path = self._lib.twin_uart_open_pty(self._live())
        if path is None:
            raise TwinError(f"cannot open a pseudo-terminal: {os.strerror(ctypes.get_errno())}")
        return path.decode()

    def set_uart_corruption(self, probability: float, seed: int) -> None:
        """Flips one random bit of a byte with this probability, both directions."""
        if not math.isfinite(probability) or not 0.0 <= probability <= 1.0:
            raise ValueError(f"probability must be in 0..1, not {probability!r}")
        seed = _integer_in(seed, range(_MAX_SEED), "seed")
        self._lib.twin_uart_set_corruption(self._live(), float(probability), seed)

    @property
    def uart_corrupted_bytes(self) -> int:
        return int(self._lib.twin_uart_corrupted_bytes(self._live()))

    @property
    def pty_dropped_bytes(self) -> int:
        return int(self._lib.twin_pty_dropped_bytes(self._live()))

    def stack_headroom(self) -> tuple[int, int]:
        """(bytes of SRAM above the static data the stack has never
        reached, bytes there in all): the stack's high-water mark, measured
        by painting that SRAM at load."""
        capacity = ctypes.c_size_t(0)
        untouched = self._lib.twin_stack_untouched(self._live(), ctypes.byref(capacity))
        return int(untouched), int(capacity.value)

    def cycle_counts(self) -> tuple[int, int]:
        """(cycles the CPU executed, cycles it slept) since the board was
        made; they add up to cycles. The firmware sleeps in idle mode until
        its next interrupt, and simavr skips the slept cycles."""
        awake = ctypes.c_uint64(0)
        asleep = ctypes.c_uint64(0)
        self._lib.twin_cycle_counts(self._live(), ctypes.byref(awake), ctypes.byref(asleep))
        return int(awake.value), int(asleep.value)

    def run_one_instruction_per_call(self, on: bool = True) -> None:
        """simavr's default pace: one instruction per call of its run
        function, where the board otherwise lets it execute until its next
        cycle timer or interrupt. Both simulate the same cycles; this is for
        tests that show it."""
        self._lib.twin_run_one_instruction_per_call(self._live(), int(on))

    def start_profile(self, period_cycles: int = 997, capacity: int = 1 << 18) -> None:
        """Samples the awake CPU every period_cycles executed cycles (the
        running instruction and its callers), keeping up to capacity
        samples; starting again discards them. While it runs, every
        instruction passes through the sampler; a board never profiled, or
        stopped, runs at full speed. The default period is a prime, so it
        keeps no step with the firmware's periodic work (the IMU's clock
        ticks every 64000 cycles, the chamber's Timer0 every 16384)."""
        period_cycles = _integer_in(period_cycles, range(1, 2**32), "period_cycles")
        capacity = _integer_in(capacity, range(1, 2**32), "capacity")
        if self._lib.twin_profile_start(self._live(), period_cycles, capacity) != 0:
            raise MemoryError(f"no room for {capacity} profile samples")
        self._profile_period = period_cycles

    def stop_profile(self) -> None:
        self._lib.twin_profile_stop(self._live())

    def profile(self) -> Profile:
        """The samples since start_profile (while it runs, or after stop_profile)."""
        handle = self._live()
        taken = ctypes.c_uint64(0)
        kept = ctypes.c_size_t(0)
        self._lib.twin_profile_counts(handle, ctypes.byref(taken), ctypes.byref(kept))
        width = self._lib.twin_profile_frames()
        buffer = (ctypes.c_uint32 * (kept.value * width))()
        count = self._lib.twin_profile_read(handle, buffer, kept.value)
        addresses = buffer[: count * width]
        samples = tuple(
            tuple(address for address in addresses[i : i + width] if address != _NO_FRAME)
            for i in range(0, len(addresses), width)
        )
        return Profile(self._profile_period, int(taken.value), samples)

    @property
    def eeprom_size(self) -> int:
        """Bytes of EEPROM: 1024 on the ATmega328P, 4096 on the ATmega2560."""
        return int(self._lib.twin_eeprom_size(self._live()))

    def _eeprom_span(self, offset: int, length: int) -> tuple[int, int]:
        size = self.eeprom_size
        offset = _integer_in(offset, range(size + 1), "EEPROM offset")
        length = _integer_in(length, range(size - offset + 1), f"EEPROM length from {offset}")
        return offset, length

    def read_eeprom(self, offset: int = 0, length: int | None = None) -> bytes:
        """EEPROM bytes from offset (all of the rest without a length). The
        EEPROM keeps them across resets; the firmware's writes land at once."""
        handle = self._live()
        offset, length = self._eeprom_span(offset, self.eeprom_size - offset if length is None else length)
        buffer = ctypes.create_string_buffer(length)
        if self._lib.twin_eeprom_read(handle, offset, buffer, length) != 0:
            raise TwinError(f"cannot read {length} EEPROM bytes from {offset}")
        return buffer.raw[:length]

    def write_eeprom(self, data: bytes | bytearray | memoryview, offset: int = 0) -> None:
        """Stores bytes in the EEPROM from offset, as a programmer would: before
        the first run_until, the firmware finds them at boot."""
        if not isinstance(data, bytes | bytearray | memoryview):
            raise TypeError(f"write_eeprom takes bytes, not {type(data).__name__}")
        payload = bytes(data)
        handle = self._live()
        offset, length = self._eeprom_span(offset, len(payload))
        if self._lib.twin_eeprom_write(handle, offset, payload, length) != 0:
            raise TwinError(f"cannot write {length} EEPROM bytes at {offset}")

    def hang(self) -> None:
        """Deadlocks the firmware: interrupts off, the CPU in an endless
        loop. Only the firmware's watchdog can bring the board back."""
        if self._lib.twin_hang(self._live()) != 0:
            raise TwinError("this firmware image has no _exit loop to hang in")

    def _adc_channel(self, channel: int) -> int:
        return _integer_in(channel, range(ADC_CHANNELS), "ADC channel")

    def set_adc_millivolts(self, channel: int, millivolts: float) -> None:
        """Holds analog input A0..A7 at a voltage; the firmware reads the
        datasheet's ideal code, millivolts * 1024 / 5000 rounded to 0..1023."""
        channel = self._adc_channel(channel)
        if not math.isfinite(millivolts) or not 0.0 <= millivolts <= SUPPLY_MILLIVOLTS:
            raise ValueError(f"millivolts must be in 0..{SUPPLY_MILLIVOLTS:g}, not {millivolts!r}")
        self._lib.twin_adc_set_millivolts(self._live(), channel, float(millivolts))

    def set_adc_fault(self, channel: int, fault: str) -> None:
        """Fault "open" (pin pulled to 5 V), "short" (0 V) or "none" (the set voltage again)."""
        channel = self._adc_channel(channel)
        self._lib.twin_adc_set_fault(self._live(), channel, _choice(fault, _ADC_FAULTS, "ADC fault"))

    def attach_lsm9ds0(self) -> None:
        """Puts the LSM9DS0 model on the TWI bus at 0x1D; once is enough."""
        self._lib.twin_lsm9ds0_attach(self._live())

    def set_lsm9ds0(self, ax: int, ay: int, az: int, temperature_raw: int) -> None:
        """The sensor's next samples: accelerations in LSB, OUT_TEMP_XM raw (8 LSB/degC)."""
        ax = _integer_in(ax, ACCELERATION_RAW_RANGE, "ax")
        ay = _integer_in(ay, ACCELERATION_RAW_RANGE, "ay")
        az = _integer_in(az, ACCELERATION_RAW_RANGE, "az")
        temperature_raw = _integer_in(temperature_raw, TEMPERATURE_RAW_RANGE, "temperature_raw")
        if self._lib.twin_lsm9ds0_set(self._live(), ax, ay, az, temperature_raw) != 0:
            raise TwinError("attach_lsm9ds0() first")

    def set_lsm9ds0_fault(self, fault: str) -> None:
        """Fault "absent" (no ACK), "stuck" (answers, no new data) or "none"."""
        code = _choice(fault, _SENSOR_FAULTS, "LSM9DS0 fault")
        if self._lib.twin_lsm9ds0_set_fault(self._live(), code) != 0:
            raise TwinError("attach_lsm9ds0() first")

    def wire_lsm9ds0_data_ready(self, wired: bool) -> None:
        """Connects the sensor's INT2_XM (data-ready) to D2, as attach_lsm9ds0
        does, or cuts that wire: D2 then reads its pull-up, high."""
        if self._lib.twin_lsm9ds0_wire_data_ready(self._live(), int(bool(wired))) != 0:
            raise TwinError("attach_lsm9ds0() first")

    def attach_l298n(self) -> None:
        """Starts watching the L298N pins (ENA = D9, IN1 = D7, IN2 = D6 of a Mega)."""
        if self._lib.twin_l298n_attach(self._live()) != 0:
            raise TwinError(f"the L298N observer watches ATmega2560 pins; this board is {self.mcu}")

    def read_l298n(self) -> Drive:
        duty, direction, pwm = self._drive_out
        if self._lib.twin_l298n_read(self._live(), *self._drive_refs) != 0:
            raise TwinError("attach_l298n() first")
        return Drive(duty.value, direction.value, pwm.value)

    def set_l298n_disconnected(self, disconnected: bool) -> None:
        """A cut Peltier wire: the firmware still commands a PWM, nothing reaches the cell."""
        if self._lib.twin_l298n_set_disconnected(self._live(), int(bool(disconnected))) != 0:
            raise TwinError("attach_l298n() first")
