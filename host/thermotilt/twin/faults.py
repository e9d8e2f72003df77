"""The faults the twin injects, one small class each: its name, the board
a run needs for it, whether it takes a rate (a probability per byte), and
what it does to the twin's boards or physics as it starts and ends
(docs/twin.md, "How the twin works"). Which faults exist, their times and
syntax (NAME[=RATE][@START[-END]], the model file's [[faults]]) are
``thermotilt.physics.faults``'s: this registry implements exactly the faults
it declares, each with the rate it declares, in its order.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar, Protocol

from ..physics.faults import FAULT_NAMES, FAULT_TAKES_RATE
from ..run.folder import CHAMBER_BOARD, IMU_BOARD

if TYPE_CHECKING:
    from ..physics.chamber import Chamber
    from .boards import Board

# The chamber's analog inputs: A0 reads the inner face's thermistor, A1 the outer's.
INNER_THERMISTOR_CHANNEL = 0
OUTER_THERMISTOR_CHANNEL = 1


class FaultTarget(Protocol):
    """What a fault acts on: the twin's boards by name, its chamber physics
    (None without a chamber board), the Peltier's leads and the run's seed."""

    boards: Mapping[str, Board]
    chamber: Chamber | None
    peltier_reversed: bool
    seed: int


class TwinFault:
    name: ClassVar[str]
    board: ClassVar[str]  # IMU_BOARD or CHAMBER_BOARD: a run without it cannot have the fault
    takes_rate: ClassVar[bool] = False
    # A physics term the fault acts through, which must be enabled.
    needs_term: ClassVar[str | None] = None

    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        """The fault starts (active) or ends; rate only for takes_rate."""
        raise NotImplementedError


FAULTS: dict[str, TwinFault] = {}


def register(cls: type[TwinFault]) -> type[TwinFault]:
    if cls.name in FAULTS:
        raise ValueError(f"fault {cls.name} registered twice")
    if FAULT_TAKES_RATE.get(cls.name) != cls.takes_rate:
        raise ValueError(
            f"fault {cls.name}: not declared in thermotilt.physics.faults with takes_rate={cls.takes_rate}"
        )
    FAULTS[cls.name] = cls()
    return cls


class _SensorFault(TwinFault):
    board = IMU_BOARD
    mode: ClassVar[str]  # the LSM9DS0 model's fault (sim/lsm9ds0.c)

    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        twin.boards[IMU_BOARD].set_lsm9ds0_fault(self.mode if active else "none")


@register
class SensorAbsent(_SensorFault):
    """The LSM9DS0 answers no address (NACK)."""

    name = "sensor_absent"
    mode = "absent"


@register
class SensorStuck(_SensorFault):
    """The LSM9DS0 answers but has no new data."""

    name = "sensor_stuck"
    mode = "stuck"


@register
class DataReadyCut(TwinFault):
    """INT2_XM's wire to D2 broken: the pin reads its pull-up."""

    name = "data_ready_cut"
    board = IMU_BOARD

    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        twin.boards[IMU_BOARD].wire_lsm9ds0_data_ready(not active)


class _ThermistorFault(TwinFault):
    board = CHAMBER_BOARD
    channel: ClassVar[int]
    kind: ClassVar[str]  # "open": the pin at 5 V; "short": at 0 V

    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        twin.boards[CHAMBER_BOARD].set_adc_fault(self.channel, self.kind if active else "none")


@register
class InnerOpen(_ThermistorFault):
    name = "inner_open"
    channel = INNER_THERMISTOR_CHANNEL
    kind = "open"


@register
class InnerShort(_ThermistorFault):
    name = "inner_short"
    channel = INNER_THERMISTOR_CHANNEL
    kind = "short"


@register
class OuterOpen(_ThermistorFault):
    name = "outer_open"
    channel = OUTER_THERMISTOR_CHANNEL
    kind = "open"


@register
class OuterShort(_ThermistorFault):
    name = "outer_short"
    channel = OUTER_THERMISTOR_CHANNEL
    kind = "short"


@register
class PeltierDisconnected(TwinFault):
    """The pins still switch; no current reaches the cell."""

    name = "peltier_disconnected"
    board = CHAMBER_BOARD

    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        twin.boards[CHAMBER_BOARD].set_l298n_disconnected(active)


@register
class PeltierReversed(TwinFault):
    """The leads swapped: the current the firmware means to heat cools."""

    name = "peltier_reversed"
    board = CHAMBER_BOARD

    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        twin.peltier_reversed = active


@register
class InnerDetached(TwinFault):
    """The inner thermistor reads the room, not its face."""

    name = "inner_detached"
    board = CHAMBER_BOARD

    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        twin.chamber.inner_thermistor_detached = active


@register
class HeatsinkFailed(TwinFault):
    """The heatsink keeps FAILED_HEATSINK_FRACTION of its conductance to ambient."""

    name = "heatsink_failed"
    board = CHAMBER_BOARD
    needs_term = "heatsink"

    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        twin.chamber.heatsink_failed = active


class _Hang(TwinFault):
    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        # A deadlock cannot be undone from outside: only the watchdog ends it.
        if active:
            twin.boards[self.board].hang()


@register
class ChamberHang(_Hang):
    name = "chamber_hang"
    board = CHAMBER_BOARD


@register
class ImuHang(_Hang):
    name = "imu_hang"
    board = IMU_BOARD


class _UartCorrupt(TwinFault):
    """One bit flipped with the rate's probability per byte, both directions."""

    takes_rate = True

    def apply(self, twin: FaultTarget, active: bool, rate: float | None) -> None:
        twin.boards[self.board].set_uart_corruption(rate if active else 0.0, twin.seed)


@register
class ImuUartCorrupt(_UartCorrupt):
    name = "imu_uart_corrupt"
    board = IMU_BOARD


@register
class ChamberUartCorrupt(_UartCorrupt):
    name = "chamber_uart_corrupt"
    board = CHAMBER_BOARD


if tuple(FAULTS) != FAULT_NAMES:
    raise ValueError(
        f"the twin implements the faults {tuple(FAULTS)}, thermotilt.physics.faults declares {FAULT_NAMES}"
    )
