"""The digital twin: the real firmware images in simavr, coupled every 10 ms
of simulated time to the physics model (``thermotilt.physics``).

Per step: the chamber physics advances with the drive the L298N observer saw
during the last step, the thermistor voltages and the LSM9DS0 registers are
set from the new physical state, the boards run to the end of the step, and
every byte they sent is saved, parsed and logged. A run may carry several
IMU boards, as a tilt table carries a batch of sensors (``run_sensors``),
each with its own sensor physics and run folder. The host side is the same
code path as with real boards: commands go out as frames, and run.csv rows
come from IMU frames and the chamber's latest CHS frame through the recorder
``thermotilt log`` uses (``thermotilt.wire.recorder``), which also says when
a chamber program is over. Faults act through their registry
(``thermotilt.twin.faults``).

A run races (as fast as the host can step it) unless it is paced to the wall
clock (``realtime``), as a client of the ``pty`` ports expects of a board.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import BinaryIO

from ..physics import Chamber, Fault, Model, Sensor, SensorSample
from ..run.folder import CHAMBER_BOARD, IMU_BOARD, RunFolder
from ..run.log import RunLogWriter, format_number
from ..run.summary import INTERRUPTED, TWIN, BoardReport, RunSummary
from ..wire.coefficients import SENSOR_ID_RECORD_ADDRESS, encode_sensor_id_record
from ..wire.protocol import Frame, SequenceCounter, build_frame
from ..wire.recorder import BoardStream, FrameRecorder
from .boards import Board, Drive
from .faults import FAULTS, INNER_THERMISTOR_CHANNEL, OUTER_THERMISTOR_CHANNEL
from .scenarios import Command, Scenario, TablePosition

STEP_S = 0.01
IMU = IMU_BOARD
CHAMBER = CHAMBER_BOARD
IMU_EEPROM_BYTES = 1024  # the ATmega328P's


class SimulationError(RuntimeError):
    """A run that cannot start or continue; one readable line."""


@dataclass
class BoardLink:
    """One board with the host's end of its serial line: what the board
    sends goes through its stream (capture, frames, what it reported); the
    commands the host sent wait here for their ACK or ERR."""

    name: str
    board: Board
    capture: BinaryIO
    stream: BoardStream
    host_seq: SequenceCounter = field(default_factory=SequenceCounter)
    pending: dict[int, str] = field(default_factory=dict)
    refused: list[str] = field(default_factory=list)

    @classmethod
    def open(cls, name: str, board: Board, capture: BinaryIO) -> BoardLink:
        return cls(name, board, capture, BoardStream(name, capture, lambda: board.seconds))

    def receive(self) -> list[Frame]:
        frames = self.stream.feed(self.board.read_uart())
        for frame in frames:
            if frame.type in ("ACK", "ERR") and frame["cmd_seq"] != -1:
                command = self.pending.pop(frame["cmd_seq"], None)
                if frame.type == "ERR" and command is not None:
                    self.refused.append(f"{command}: {frame['code']} {frame['detail']}")
        return frames

    def send(self, frame_type: str, values: tuple) -> None:
        seq = self.host_seq.next()
        self.pending[seq] = frame_type
        self.board.write_uart(build_frame(frame_type, seq, values).encode("ascii"))

    def report(self) -> BoardReport:
        awake, asleep = self.board.cycle_counts()
        return self.stream.report(
            refused_commands=self.refused,
            unanswered_commands=sorted(self.pending.values()),
            cycles=self.board.cycles,
            awake_cycles=awake,
            sleep_cycles=asleep,
            corrupted_bytes=self.board.uart_corrupted_bytes,
        )


@dataclass(frozen=True)
class RunResult:
    out_dir: Path
    summary: RunSummary


class WallClockPacer:
    """Holds simulated time back to the wall clock. Its clock starts when it
    is made, right before the first step, and every wait is measured from
    there, so a late wake-up is not added to the next. A twin that falls
    behind runs flat out until it is level again; it never skips steps."""

    def __init__(
        self, clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep
    ) -> None:
        self._clock = clock
        self._sleep = sleep
        self._start = clock()

    def wait_until(self, simulated_s: float) -> None:
        """Returns once simulated_s wall seconds have passed since the start."""
        ahead = simulated_s - (self._clock() - self._start)
        if ahead > 0:
            self._sleep(ahead)


class StepTiming:
    """Wall seconds a run spends in each part of its steps, for `make bench`:
    pass one to run(). Each lap charges the time since the previous lap to
    a phase: physics (the chamber and sensor models), board_io (the ctypes
    calls that set inputs and read the drive), boards (run_until: simavr
    running both firmware images, and the ctypes call into it), frames
    (reading, saving and parsing what the boards sent), csv (run.csv rows)
    and other (the schedule of commands, faults and table moves, and the
    wait of a paced run). Without one, a run's laps are calls of a function
    that does nothing."""

    PHASES = ("physics", "board_io", "boards", "frames", "csv", "other")

    def __init__(self, clock: Callable[[], float] = time.perf_counter) -> None:
        self._clock = clock
        self.seconds = dict.fromkeys(self.PHASES, 0.0)
        self._last = clock()

    def start(self) -> None:
        """Laps count from now (run() starts it before the first step)."""
        self._last = self._clock()

    def lap(self, phase: str) -> None:
        now = self._clock()
        self.seconds[phase] += now - self._last
        self._last = now


def _no_lap(_phase: str) -> None:
    pass


class _FaultSchedule:
    """Switches each fault on and off at its times (the registry says how)."""

    def __init__(self, faults: tuple[Fault, ...], target: Lockstep):
        self._faults = faults
        self._target = target
        self._active = [False] * len(faults)

    def update(self, t: float) -> None:
        for index, fault in enumerate(self._faults):
            active = fault.active(t)
            if active != self._active[index]:
                self._active[index] = active
                FAULTS[fault.name].apply(self._target, active, fault.rate)


def check_faults(scenario: Scenario, model: Model, imu_boards: int = 1) -> None:
    """SimulationError for a fault the run cannot have: its board is not
    in the scenario, it would act on one of several IMU boards, or the
    physics term it acts through is off."""
    for fault in model.faults:
        kind = FAULTS[fault.name]
        if kind.board == CHAMBER and not scenario.uses_chamber:
            raise SimulationError(f"fault {fault.name} needs the chamber, but {scenario.name} runs the IMU alone")
        if kind.board == IMU and imu_boards > 1:
            raise SimulationError(
                f"fault {fault.name} acts on one IMU board, and this run has {imu_boards}; run that sensor alone"
            )
        if kind.needs_term is not None and not model.enabled(kind.needs_term):
            raise SimulationError(f"fault {fault.name} needs the {kind.needs_term} term enabled")


def _truth(sample: SensorSample, chamber: Chamber | None, drive: Drive | None) -> dict[str, str]:
    return {
        "true_inner_c": format_number(chamber.inner_c if chamber else None, 4),
        "true_outer_c": format_number(chamber.outer_c if chamber else None, 4),
        "true_die_c": format_number(sample.die_c, 4),
        "true_reported_c": format_number(sample.reported_c, 4),
        "true_rate_c_per_s": format_number(sample.rate_c_per_s, 5),
        "true_drift_set": sample.drift_set,
        "true_warming_share": format_number(sample.warming_share, 4),
        "true_ax": format_number(sample.ideal_ax, 2),
        "true_ay": format_number(sample.ideal_ay, 2),
        "true_az": format_number(sample.ideal_az, 2),
        "true_drift_x": format_number(sample.drift_x, 2),
        "true_drift_y": format_number(sample.drift_y, 2),
        "true_drift_z": format_number(sample.drift_z, 2),
        "true_duty": format_number(drive.duty if drive else None, 4),
        "true_direction": str(drive.direction) if drive else "",
    }


@dataclass(frozen=True)
class ImuRun:
    """One IMU board of a run: its sensor's model, the folder its run.csv,
    serial/ and summary.json go to, its noise seed, the bytes its EEPROM
    holds from address 0 when it starts (e.g. the coefficient block of
    `thermotilt fit`, coefficients.bin), and the sensor ID its EEPROM holds
    ("" none), as `thermotilt assign-id` leaves it on a real board."""

    model: Model
    out_dir: Path
    seed: int = 1
    eeprom: bytes | None = None
    sensor_id: str = ""


@dataclass(frozen=True)
class Playback:
    """How a run is played, beside what it simulates: each board's serial
    port also a pseudo-terminal (pty; on_pty is told each board's name and
    path), progress told the simulated seconds every simulated second, no
    step ending before its simulated time has passed on the wall clock, as
    on a board (realtime), and where the steps' wall time goes (timing)."""

    pty: bool = False
    on_pty: Callable[[str, str], None] | None = None
    progress: Callable[[float], None] | None = None
    realtime: bool = False
    timing: StepTiming | None = None


def run(
    scenario: Scenario,
    model: Model,
    out_dir: Path,
    seed: int = 1,
    *,
    eeprom: bytes | None = None,
    sensor_id: str = "",
    timing: StepTiming | None = None,
) -> RunResult:
    """Plays a scenario; writes run.csv, serial/ and summary.json in out_dir.
    eeprom, sensor_id: what the IMU's EEPROM holds when it starts (ImuRun).
    timing: where the steps' wall time goes. For pseudo-terminals, progress
    or pacing to the wall clock: run_imu."""
    return run_imu(scenario, ImuRun(model, out_dir, seed, eeprom, sensor_id), Playback(timing=timing))


def run_imu(scenario: Scenario, imu: ImuRun, playback: Playback = Playback()) -> RunResult:
    """Plays a scenario with one IMU board, the chamber's physics its
    model's, as playback says; writes its run folder (run)."""
    return _play(scenario, imu.model, [imu], playback)[0]


def run_sensors(
    scenario: Scenario,
    chamber_model: Model,
    imus: Sequence[ImuRun],
    progress: Callable[[float], None] | None = None,
) -> list[RunResult]:
    """One chamber run carrying several IMU boards, as a tilt table carries
    several sensors: the chamber's face temperature drives every sensor, and
    no sensor acts on the chamber, so each IMU's run folder holds what a run
    of that sensor alone with its seed gives (the chamber's capture copied
    into each). The chamber's physics is chamber_model's."""
    return _play(scenario, chamber_model, imus, Playback(progress=progress))


@dataclass(frozen=True)
class _Played:
    """How the play of a run went, the same in each of its IMUs' summaries."""

    end_reason: str
    realtime: bool
    simulated_s: float
    wall_s: float


def _play(scenario: Scenario, chamber_model: Model, imus: Sequence[ImuRun], playback: Playback) -> list[RunResult]:
    _check_run(scenario, chamber_model, imus, playback)
    folders = [RunFolder.at(imu.out_dir) for imu in imus]
    for folder in folders:
        folder.serial_dir.mkdir(parents=True, exist_ok=True)
    wall_start = time.perf_counter()
    units: list[ImuUnit] = []
    chamber_link: BoardLink | None = None
    with ExitStack() as open_files:
        try:
            for imu, folder in zip(imus, folders):
                units.append(_imu_unit(scenario, imu, folder, open_files))
                _load_eeprom(units[-1].link.board, imu)
            if scenario.uses_chamber:
                chamber_link = BoardLink.open(CHAMBER, Board.thermal_chamber(), open(folders[0].capture(CHAMBER), "wb"))
            end_reason = _played(Lockstep(scenario, chamber_model, imus[0].seed, units, chamber_link), playback)
            simulated = units[0].link.board.seconds
            chamber_report = chamber_link.report() if chamber_link is not None else None
            imu_reports = [unit.link.report() for unit in units]
            # What each IMU saved (SAVECOE), as a real board would keep it: the
            # next run can start from it with eeprom=.
            for unit, folder in zip(units, folders):
                folder.imu_eeprom.write_bytes(unit.link.board.read_eeprom())
        finally:
            for link in [unit.link for unit in units] + ([chamber_link] if chamber_link else []):
                link.capture.close()
                link.board.close()
    for folder in folders[1:] if chamber_link is not None else ():
        shutil.copyfile(folders[0].capture(CHAMBER), folder.capture(CHAMBER))
    played = _Played(end_reason, playback.realtime, simulated, time.perf_counter() - wall_start)
    results = []
    for imu, unit, imu_report in zip(imus, units, imu_reports):
        boards = {IMU: imu_report, **({CHAMBER: chamber_report} if chamber_report else {})}
        summary = _summary(scenario, imu, played, unit.recorder.rows, boards)
        summary.write(imu.out_dir)
        results.append(RunResult(imu.out_dir, summary))
    return results


def _check_run(scenario: Scenario, chamber_model: Model, imus: Sequence[ImuRun], playback: Playback) -> None:
    if not imus:
        raise SimulationError("a run needs at least one IMU board")
    if playback.pty and len(imus) > 1:
        raise SimulationError("the pty ports serve one IMU board; run one sensor")
    check_faults(scenario, chamber_model, len(imus))


def _imu_unit(scenario: Scenario, imu: ImuRun, folder: RunFolder, open_files: ExitStack) -> ImuUnit:
    """The IMU board of imu, its capture and run.csv open in folder."""
    link = BoardLink.open(IMU, Board.imu_reader(), open(folder.capture(IMU), "wb"))
    csv_stream = open_files.enter_context(open(folder.log, "w", newline=""))
    recorder = FrameRecorder(
        RunLogWriter(csv_stream, with_truth=True, flush_each_row=False),
        watch_program=scenario.ends_with_program,
    )
    sensor = Sensor(imu.model, imu.seed, scenario.ambient_c(0.0), scenario.sensor_warming_share)
    return ImuUnit(link, sensor, recorder)


def _load_eeprom(board: Board, imu: ImuRun) -> None:
    """What imu says its board's EEPROM holds at the start."""
    if imu.eeprom is not None:
        _preload_eeprom(board, imu.eeprom)
    if imu.sensor_id:
        board.write_eeprom(encode_sensor_id_record(imu.sensor_id), SENSOR_ID_RECORD_ADDRESS)


def _preload_eeprom(board: Board, eeprom: bytes) -> None:
    if len(eeprom) > board.eeprom_size:
        raise SimulationError(f"{len(eeprom)} bytes do not fit the IMU's EEPROM of {board.eeprom_size} bytes")
    board.write_eeprom(eeprom)


def _played(lockstep: Lockstep, playback: Playback) -> str:
    """Plays the lockstep as playback says; returns why it stopped."""
    try:
        if playback.pty:
            lockstep.open_ptys(playback.on_pty)
        return lockstep.play(playback.progress, playback.realtime, playback.timing)
    except KeyboardInterrupt:
        # Ctrl-C keeps what was simulated so far, summary included.
        return INTERRUPTED


def _summary(scenario: Scenario, imu: ImuRun, played: _Played, rows: int, boards: dict[str, BoardReport]) -> RunSummary:
    """The summary.json of imu's run folder."""
    return RunSummary(
        source=TWIN,
        scenario=scenario.name,
        description=scenario.description,
        options=asdict(scenario.options) if scenario.options is not None else None,
        seed=imu.seed,
        model=imu.model.source,
        terms={name: imu.model.enabled(name) for name in imu.model.terms},
        faults=[vars(fault) for fault in imu.model.faults],
        imu_eeprom_preloaded_bytes=len(imu.eeprom) if imu.eeprom is not None else 0,
        end_reason=played.end_reason,
        realtime=played.realtime,
        sim_seconds=round(played.simulated_s, 3),
        wall_seconds=round(played.wall_s, 3),
        speed_x_real_time=round(played.simulated_s / played.wall_s, 2) if played.wall_s > 0 else None,
        rows=rows,
        marks=scenario.marks,
        positions=[vars(position) for position in scenario.positions],
        boards=boards,
    )


@dataclass
class ImuUnit:
    """An IMU board in the loop: its serial line, its sensor's physics, its
    run.csv, and the sample the sensor gave in the current step."""

    link: BoardLink
    sensor: Sensor
    recorder: FrameRecorder
    sample: SensorSample | None = None


class _Schedule:
    """A scenario's table positions and commands, each handed out once its
    time has come."""

    def __init__(self, scenario: Scenario) -> None:
        self._positions = list(scenario.positions)
        self._commands = list(scenario.commands)
        # The table starts at the first position, whatever that one's time.
        self.position = self._positions.pop(0)

    def moves(self, t: float) -> list[TablePosition]:
        """The positions due by t, in order; the table is then at the last."""
        moved = []
        while self._positions and self._positions[0].at_s <= t:
            self.position = self._positions.pop(0)
            moved.append(self.position)
        return moved

    def commands(self, t: float) -> list[Command]:
        """The commands due by t, in order."""
        due = []
        while self._commands and self._commands[0].at_s <= t:
            due.append(self._commands.pop(0))
        return due


class Lockstep:
    """The twin's loop over its 10 ms steps, and what a fault acts on
    (``thermotilt.twin.faults.FaultTarget``): the boards by name (the first
    IMU's, the only one a run with IMU faults has), the chamber physics,
    the Peltier's leads and the seed."""

    def __init__(
        self,
        scenario: Scenario,
        model: Model,
        seed: int,
        imus: list[ImuUnit],
        chamber_link: BoardLink | None,
    ) -> None:
        self.scenario = scenario
        self.seed = seed
        self.imus = imus
        self.chamber_link = chamber_link
        self.links = {IMU: imus[0].link, **({CHAMBER: chamber_link} if chamber_link else {})}
        self.boards = {name: link.board for name, link in self.links.items()}
        self.peltier_reversed = False
        for unit in imus:
            unit.link.board.attach_lsm9ds0()
        self.chamber: Chamber | None = None
        if chamber_link is not None:
            chamber_link.board.attach_l298n()
            self.chamber = Chamber(model, scenario.ambient_c(0.0))
        self._faults = _FaultSchedule(model.faults, self)

    def open_ptys(self, on_pty: Callable[[str, str], None] | None) -> None:
        for link in self.links.values():
            path = link.board.open_pty()
            if on_pty:
                on_pty(link.name, path)

    def play(
        self, progress: Callable[[float], None] | None = None, realtime: bool = False, timing: StepTiming | None = None
    ) -> str:
        """Steps to the scenario's end, or to the end of its chamber program
        (ends_with_program); returns why it stopped (the summary's end_reason)."""
        schedule = _Schedule(self.scenario)
        self._move_table(schedule.position)
        boards = [unit.link.board for unit in self.imus] + ([self.chamber_link.board] if self.chamber_link else [])
        first_recorder = self.imus[0].recorder
        pacer = WallClockPacer() if realtime else None
        lap = _no_lap
        if timing is not None:
            lap = timing.lap
            timing.start()
        for step in range(round(self.scenario.duration_s / STEP_S)):
            t = step * STEP_S
            self._apply_schedule(t, schedule)
            ambient = self.scenario.ambient_c(t)
            lap("other")
            drive = self._step_chamber(ambient, lap)
            environment = ambient if self.chamber is None else self.chamber.inner_c
            self._step_sensors(environment, schedule.position, lap)
            end = (step + 1) * STEP_S
            for board in boards:
                board.run_until(end)
            lap("boards")
            if pacer is not None:
                pacer.wait_until(end)
                lap("other")
            self._record(end, ambient, drive, lap)
            if progress is not None and step % 100 == 99:
                progress(end)
            if first_recorder.end_reason:
                return first_recorder.end_reason
        return f"{self.scenario.duration_s:g} s simulated"

    def _apply_schedule(self, t: float, schedule: _Schedule) -> None:
        """The faults, table moves and commands due at t."""
        self._faults.update(t)
        for position in schedule.moves(t):
            self._move_table(position)
        for command in schedule.commands(t):
            if command.board == IMU:
                for unit in self.imus:
                    unit.link.send(command.frame_type, command.values)
            else:
                self.links[command.board].send(command.frame_type, command.values)

    def _move_table(self, position: TablePosition) -> None:
        for unit in self.imus:
            unit.recorder.move_table(position.incl_x_deg, position.incl_y_deg, position.at_s)

    def _step_chamber(self, ambient_c: float, lap: Callable[[str], None]) -> Drive | None:
        """The chamber's physics over the step, driven as the board drove the
        Peltier during the last; the board then reads the new thermistor
        voltages. Returns that drive (None: no chamber)."""
        if self.chamber is None:
            return None
        board = self.chamber_link.board
        drive = board.read_l298n()
        lap("board_io")
        current = -drive.direction if self.peltier_reversed else drive.direction
        self.chamber.step(STEP_S, drive.duty, current, ambient_c)
        inner_mv, outer_mv = self.chamber.thermistor_millivolts()
        lap("physics")
        board.set_adc_millivolts(INNER_THERMISTOR_CHANNEL, inner_mv)
        board.set_adc_millivolts(OUTER_THERMISTOR_CHANNEL, outer_mv)
        lap("board_io")
        return drive

    def _step_sensors(self, environment_c: float, position: TablePosition, lap: Callable[[str], None]) -> None:
        """Each sensor's physics over the step; its board's registers then hold the new sample."""
        for unit in self.imus:
            sample = unit.sensor.step(STEP_S, environment_c, position.incl_x_deg, position.incl_y_deg)
            lap("physics")
            unit.sample = sample
            unit.link.board.set_lsm9ds0(sample.ax, sample.ay, sample.az, sample.temperature_raw)
            lap("board_io")

    def _record(self, end: float, ambient_c: float, drive: Drive | None, lap: Callable[[str], None]) -> None:
        """What the boards sent during the step that ends at end, into each IMU's run.csv."""
        chamber_frames = self.chamber_link.receive() if self.chamber_link is not None else []
        for unit in self.imus:
            unit.recorder.record_chamber(chamber_frames)
            imu_frames = [frame for frame in unit.link.receive() if frame.type == "IMU"]
            lap("frames")
            if imu_frames:
                unit.recorder.set_ambient(ambient_c)
                truth = _truth(unit.sample, self.chamber, drive)
                for frame in imu_frames:
                    unit.recorder.record_imu(frame, end, truth)
            lap("csv")
