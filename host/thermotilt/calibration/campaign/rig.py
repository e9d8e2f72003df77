"""A campaign on real boards: the IMU readers the tilt table carries and the
chamber on their serial ports, one position after another, the table moved
by hand between them. Several IMU readers are a batch: each must have its
own sensor ID (``assign-id``), which names its campaign folder."""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from ...program import CALIBRATION_MAX_C, CALIBRATION_MIN_C
from ...run.summary import INTERRUPTED as RUN_INTERRUPTED
from ...run.summary import PROGRAM_DONE
from ...twin.scenarios import ScenarioOptions
from .folder import DONE, FAILED, INTERRUPTED, CampaignError, CampaignFolder, Position, PositionRecord
from .plan import Campaign, CampaignOutcome, Finished, Progress, RunEnd, Task, Unit, campaign_header

# A Nano resets when its port opens and its bootloader waits ~1-2 s; a Mega the same.
BOOT_WAIT_S = 10.0
DEFAULT_HEARTBEAT_S = 60
SERIAL_TIMEOUT_S = 0.05


@dataclass(frozen=True)
class BoardsSetup:
    """Real boards: the IMU readers the tilt table carries and the chamber,
    on their serial ports; the table is moved by hand, so ``confirm`` asks
    the user at each position (False stops the campaign, keeping what is
    done)."""

    imu_ports: tuple[str, ...]
    chamber_port: str
    options: ScenarioOptions
    confirm: Callable[[Position], bool]
    baud: int = 115200
    heartbeat_s: int = DEFAULT_HEARTBEAT_S


class BoardsCampaign(Campaign):
    """A campaign on real boards, one position after another."""

    def __init__(
        self, out_dir: Path, positions: list[Position], setup: BoardsSetup, resume: bool = False, force: bool = False
    ):
        folder = CampaignFolder(out_dir)
        self.setup = setup
        # The port each unit's IMU reader is on.
        self.ports = {Unit(None, ""): setup.imu_ports[0]}
        if len(setup.imu_ports) > 1:
            ids = identify_sensors(setup.imu_ports, setup.baud)
            self.ports = {Unit(sensor_id, sensor_id): port for sensor_id, port in sorted(ids.items())}
        if len(self.ports) > 1 and resume:
            folder.check_batch(unit.sensor for unit in self.ports)
        headers = {
            unit: campaign_header(
                "boards", setup.options, unit, ports={"imu_reader": port, "thermal_chamber": setup.chamber_port}
            )
            for unit, port in self.ports.items()
        }
        super().__init__(folder, positions, headers, resume, force)
        if self.batch:
            folder.write_batch((unit.sensor for unit in self.ports), {"rig": "boards"})

    def describe(self) -> str:
        lines = []
        if self.batch:
            lines.append(
                f"a batch of {len(self.ports)} sensors on one tilt table, each its own campaign in "
                f"{self.folder.path}/<ID>: "
                + ", ".join(f"{unit.sensor} on {port}" for unit, port in self.ports.items())
            )
        lines.append(
            f"campaign of {len(self.positions)} positions on {', '.join(self.setup.imu_ports)} and "
            f"{self.setup.chamber_port} -> {self.folder.path}"
            + (f" ({self.done} already done)" if self.done else "")
            + f": {len(self.todo)} to run"
        )
        return "\n".join(lines)

    def run(self, on_position: Finished | None = None) -> CampaignOutcome:
        return self.run_with(RigRunner(self), on_position=on_position)


class RigRunner:
    """One position after another, each once the user has set the table;
    a failure stops the campaign, for a person to look before --resume."""

    def __init__(self, campaign: BoardsCampaign) -> None:
        self.campaign = campaign

    def run(self, tasks: list[Task], folder: CampaignFolder, progress: Progress | None, finished: Finished) -> RunEnd:
        setup = self.campaign.setup
        for position, units in tasks:
            if not setup.confirm(position):
                return RunEnd.STOPPED
            imus = [
                (unit, self.campaign.ports[unit], unit.sensor if self.campaign.batch else self._logged_id(unit))
                for unit in units
            ]
            records = run_boards_position(setup, position, folder, imus)
            for record in records:
                finished(record)
            if any(record.status == INTERRUPTED for record in records):
                return RunEnd.INTERRUPTED
            if any(record.status != DONE for record in records):
                return RunEnd.STOPPED
        return RunEnd.FINISHED

    def _logged_id(self, unit: Unit) -> str | None:
        return self.campaign.files[unit].sensor_id()


def _open(ports: ExitStack, port: str, setup: BoardsSetup) -> Any:
    import serial

    return ports.enter_context(serial.serial_for_url(port, baudrate=setup.baud, timeout=SERIAL_TIMEOUT_S))


def identify_sensors(ports: tuple[str, ...], baud: int) -> dict[str, str]:
    """The sensor ID of the IMU reader on each port, by ID; CampaignError
    for a board without one or two with the same."""
    import serial

    from ...wire.client import CommandClient, CommandError

    ids: dict[str, str] = {}
    for port in ports:
        try:
            with serial.serial_for_url(port, baudrate=baud, timeout=SERIAL_TIMEOUT_S) as imu:
                client = CommandClient(imu)
                _board_version(client, port)
                sensor_id = _board_sensor_id(client, port)
        except (serial.SerialException, OSError) as error:
            raise CampaignError(f"serial port {port}: {error}") from None
        except CommandError as error:
            raise CampaignError(f"{port}: {error}") from None
        if not sensor_id:
            raise CampaignError(
                f"the IMU reader on {port} has no sensor ID; a batch needs one per board: "
                f"thermotilt assign-id ID --port {port}"
            )
        if sensor_id in ids:
            raise CampaignError(f"the IMU readers on {ids[sensor_id]} and {port} are both sensor {sensor_id}")
        ids[sensor_id] = port
    return ids


def _board_version(client: Any, port: str) -> str:
    """VERSION until the board, maybe still in its bootloader, answers."""
    from ...wire.client import CommandTimeout

    deadline = time.monotonic() + BOOT_WAIT_S
    while True:
        try:
            answer = client.command("VERSION")
        except CommandTimeout:
            if time.monotonic() > deadline:
                raise CampaignError(f"no board answers on {port} (VERSION, {BOOT_WAIT_S:g} s)") from None
            continue
        frame = next((frame for frame in answer.data if frame.type == "VER"), None)
        if frame is None:
            raise CampaignError(f"the board on {port} answered VERSION without a VER frame")
        return f"{frame['device']} {frame['firmware_version']} protocol {frame['protocol_version']}"


def _board_sensor_id(client: Any, port: str) -> str:
    """The IMU's sensor ID from its ICF ("" for none)."""
    answer = client.command("STATUS")
    frame = next((frame for frame in answer.data if frame.type == "ICF"), None)
    if frame is None:
        raise CampaignError(
            f"the IMU reader on {port} answered STATUS without an ICF frame that has a sensor_id "
            "(firmware before imu_reader 0.3.0? update it)"
        )
    return frame["sensor_id"]


# An IMU reader of a position: its unit, its port and the sensor ID it must
# report (None: any, the campaign's first position).
Imu = tuple[Unit, str, str | None]


def run_boards_position(
    setup: BoardsSetup, position: Position, folder: CampaignFolder, imus: list[Imu]
) -> list[PositionRecord]:
    """The table is set: check each IMU, restart its filters, run the
    chamber's program and log every board until it ends, each IMU into its
    unit's campaign folder."""
    import serial

    from ...wire.client import CommandError
    from ...wire.logger import LogError

    # Until its board reports one: the ID of the batch sensor the unit is.
    records = [PositionRecord.started(position, unit.sensor) for unit, _, _ in imus]
    partials = [folder.sensor(unit.folder).partial(position.label) for unit, _, _ in imus]
    begin = time.monotonic()
    chamber: list[Any] = []

    def failed(status: str, error: str | None = None) -> list[PositionRecord]:
        if chamber:
            _stop_chamber(chamber[0])
        for record in records:
            record.status, record.error = status, error
        return records

    try:
        with ExitStack() as ports:
            summaries = _log_position(setup, position, imus, records, partials, ports, chamber)
    except (serial.SerialException, OSError) as error:
        chamber.clear()
        return failed(FAILED, f"serial port: {error}")
    except (CampaignError, CommandError, LogError) as error:
        return failed(FAILED, str(error))
    except KeyboardInterrupt:
        return failed(INTERRUPTED)
    for (unit, _, _), record, summary in zip(imus, records, summaries):
        record.wall_seconds = round(time.monotonic() - begin, 3)
        record.reported_errors = [
            f"{board}: {error}" for board, report in summary.boards.items() for error in report.reported_errors
        ]
        if summary.end_reason == RUN_INTERRUPTED:
            record.status = INTERRUPTED
        elif summary.end_reason != PROGRAM_DONE:
            record.status, record.error = FAILED, f"the log ended early: {summary.end_reason}"
        else:
            folder.sensor(unit.folder).keep(position.label)
            record.status = DONE
    return records


def _log_position(
    setup: BoardsSetup,
    position: Position,
    imus: list[Imu],
    records: list[PositionRecord],
    partials: list[Path],
    ports: ExitStack,
    chamber_opened: list[Any],
) -> list[Any]:
    """The boards' part of a position: the chamber opened (and noted in
    chamber_opened, to be stopped on a failure), each IMU checked and
    reseeded, the program started and every board logged until it ends."""
    from ...twin.scenarios import chamber_program
    from ...wire.client import CommandClient
    from ...wire.logger import ProgramWatch, Rig, log_imus
    from ...wire.protocol import SequenceCounter

    chamber = _open(ports, setup.chamber_port, setup)
    chamber_opened.append(chamber)
    chamber_seq = SequenceCounter()
    chamber_client = CommandClient(chamber, seq=chamber_seq)
    chamber_version = _board_version(chamber_client, setup.chamber_port)
    logs = []
    for (_, port, expected_id), record, partial in zip(imus, records, partials):
        imu = _open(ports, port, setup)
        imu_client = CommandClient(imu)
        record.firmware = {"imu_reader": _board_version(imu_client, port), "thermal_chamber": chamber_version}
        record.sensor_id = _board_sensor_id(imu_client, port)
        if expected_id is not None and record.sensor_id != expected_id:
            raise CampaignError(
                f"the IMU reader on {port} is sensor {record.sensor_id or '(no ID)'}, "
                f"this campaign's positions so far were logged with {expected_id or '(no ID)'}"
            )
        imu_client.command("RESEED")
        logs.append((imu, partial, record.firmware))
    for command in chamber_program(CALIBRATION_MIN_C, CALIBRATION_MAX_C, setup.options, 1):
        chamber_client.command(command.frame_type, command.values)
    chamber_client.command("SETHB", (setup.heartbeat_s,))
    chamber_client.command("START")
    rig = Rig(setup.options.ambient_c, position.incl_x_deg, position.incl_y_deg, position.label)
    watch = ProgramWatch(setup.heartbeat_s / 4 if setup.heartbeat_s else None, chamber_seq)
    options = replace(setup.options, incl_x_deg=position.incl_x_deg, incl_y_deg=position.incl_y_deg)
    summaries = log_imus(
        logs,
        chamber,
        rig=rig,
        program=watch,
        description=f"campaign position {position.label} on real boards",
        scenario="cycle",
        options=asdict(options),
    )
    if summaries[0].end_reason != PROGRAM_DONE:
        _stop_chamber(chamber)
    return summaries


def _stop_chamber(chamber: Any) -> None:
    """Best effort: the chamber's own heartbeat stops it anyway."""
    import serial

    from ...wire.protocol import build_frame

    try:
        if chamber.is_open:
            chamber.write(build_frame("STOP", 0, ()).encode("ascii"))
    except (serial.SerialException, OSError):
        pass  # the port may be what failed; the chamber's heartbeat is the real safeguard
