"""Faults injected into the twin: which a model file or the command line
may name, when each is active, their command-line syntax and their
[[faults]] tables in a model file. What each does is the twin's registry
(``thermotilt.twin.faults``), which implements exactly these."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from .parameters import ModelError, finite_number

# Each fault's name and whether it takes a rate (a probability per byte), in
# the order the twin registers them and the error messages list them.
FAULT_TAKES_RATE: dict[str, bool] = {
    "sensor_absent": False,
    "sensor_stuck": False,
    "data_ready_cut": False,
    "inner_open": False,
    "inner_short": False,
    "outer_open": False,
    "outer_short": False,
    "peltier_disconnected": False,
    "peltier_reversed": False,
    "inner_detached": False,
    "heatsink_failed": False,
    "chamber_hang": False,
    "imu_hang": False,
    "imu_uart_corrupt": True,
    "chamber_uart_corrupt": True,
}
FAULT_NAMES: tuple[str, ...] = tuple(FAULT_TAKES_RATE)

# What is left of the heatsink's conductance to ambient when its fan stops or
# its thermal joint dries: free convection from fins sized for forced air is
# of the order of a tenth of it or less (assumed; the cell overheats either way).
FAILED_HEATSINK_FRACTION = 0.05


@dataclass(frozen=True)
class Fault:
    """A fault injected into the twin between start_s and end_s (None: to the
    end). rate is the probability per byte of the *_uart_corrupt faults."""

    name: str
    start_s: float = 0.0
    end_s: float | None = None
    rate: float | None = None

    def __post_init__(self) -> None:
        if self.name not in FAULT_NAMES:
            raise ModelError(f"unknown fault '{self.name}' (known: {', '.join(FAULT_NAMES)})")
        if not (math.isfinite(self.start_s) and self.start_s >= 0.0):
            raise ModelError(f"fault '{self.name}': start {self.start_s} s must be >= 0")
        if self.end_s is not None and not (math.isfinite(self.end_s) and self.end_s > self.start_s):
            raise ModelError(f"fault '{self.name}': end {self.end_s} s must be after start {self.start_s} s")
        if FAULT_TAKES_RATE[self.name]:
            if self.rate is None or not (0.0 < self.rate <= 1.0):
                raise ModelError(f"fault '{self.name}' needs a rate, a probability per byte in (0, 1]")
        elif self.rate is not None:
            raise ModelError(f"fault '{self.name}' takes no rate")

    def active(self, time_s: float) -> bool:
        return self.start_s <= time_s and (self.end_s is None or time_s < self.end_s)


_FAULT_TEXT = re.compile(
    r"(?P<name>[a-z_]+)"
    r"(?:=(?P<rate>[^@]+))?"
    r"(?:@(?P<start>[0-9.eE+]+)(?:-(?P<end>[0-9.eE+]+))?)?"
)


def parse_fault(text: str) -> Fault:
    """A fault from the command-line syntax NAME[=RATE][@START[-END]] (seconds),
    e.g. "inner_open@120-180" or "imu_uart_corrupt=0.001"."""
    match = _FAULT_TEXT.fullmatch(text.strip())
    if match is None:
        raise ModelError(f"fault '{text}': expected NAME[=RATE][@START[-END]]")
    try:
        rate = None if match["rate"] is None else float(match["rate"])
        start = 0.0 if match["start"] is None else float(match["start"])
        end = None if match["end"] is None else float(match["end"])
    except ValueError:
        raise ModelError(f"fault '{text}': rate, start and end must be numbers") from None
    return Fault(match["name"], start, end, rate)


def shown(name: str) -> str:
    """A key from the file as one line of text: control characters escaped."""
    return name if name.isprintable() else name.encode("unicode_escape").decode("ascii")


def read_faults(entries: Any, source: str) -> tuple[Fault, ...]:
    if not isinstance(entries, list):
        raise ModelError(f"{source}: faults must be an array of tables [[faults]]")
    faults = []
    for index, entry in enumerate(entries):
        where = f"{source}: [[faults]] #{index + 1}"
        if not isinstance(entry, dict):
            raise ModelError(f"{where}: expected a table")
        unknown = set(entry) - {"name", "start_s", "end_s", "rate"}
        if unknown:
            raise ModelError(f"{where}: unknown key '{shown(sorted(unknown)[0])}'")
        name = entry.get("name")
        if not isinstance(name, str):
            raise ModelError(f"{where}: missing name")
        numbers = {
            key: finite_number(entry[key], f"{where} {key}") for key in ("start_s", "end_s", "rate") if key in entry
        }
        try:
            fault = Fault(
                shown(name),
                numbers.get("start_s", 0.0),
                numbers.get("end_s"),
                numbers.get("rate"),
            )
        except ModelError as error:
            raise ModelError(f"{where}: {error}") from None
        faults.append(fault)
    return tuple(faults)
