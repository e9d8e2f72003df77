"""The twin's measuring instruments (sim/board.c): the cycles each board's
CPU executed and slept, and the sampling profiler. Deterministic facts
only; how fast anything runs is `make bench`'s to print, not a test's."""

import pytest
from firmware_helpers import chamber

from thermotilt.physics import Model
from thermotilt.twin import simulate
from thermotilt.twin.boards import Board, FirmwareSymbols, is_runtime_routine
from thermotilt.twin.scenarios import ScenarioOptions, build

pytestmark = pytest.mark.twin

SENSOR = (-1700, -400, 16000, 32)
# Past the IMU's start-up (version frame, sensor set-up): it streams.
STREAMING_S = 1.0
PERIOD_CYCLES = 97


def streaming_imu() -> Board:
    board = Board.imu_reader()
    board.attach_lsm9ds0()
    board.set_lsm9ds0(*SENSOR)
    board.run_until(STREAMING_S)
    return board


def test_awake_and_asleep_cycles_add_up_to_the_cycles_simulated():
    with streaming_imu() as board:
        board.run_until(3.0)
        awake, asleep = board.cycle_counts()
        assert awake > 0 and asleep > 0
        assert awake + asleep == board.cycles


def test_a_chamber_without_a_program_sleeps_most_of_the_time():
    """Every loop pass ends in idle sleep (idleUntilInterrupt) until the
    next interrupt, mostly Timer0's tick every 16384 cycles. A pass without
    a control tick is a few hundred cycles; a control tick every 250 ms
    reads two ADC channels (busy waits of about 1700 cycles each), and a
    status frame a second formats a few floats: far below half the cycles."""
    with chamber(inner_c=22.0, outer_c=22.0) as board:
        board.run_until(5.0)
        awake, asleep = board.cycle_counts()
    assert asleep / (awake + asleep) > 0.5


def test_the_profiler_samples_every_period_of_awake_cycles_in_the_images_functions():
    with streaming_imu() as board:
        awake_before, _ = board.cycle_counts()
        board.start_profile(PERIOD_CYCLES)
        board.run_until(STREAMING_S + 2.0)
        board.stop_profile()
        awake_after, _ = board.cycle_counts()
        # Stopped, it takes no more samples.
        board.run_until(STREAMING_S + 2.5)
        profile = board.profile()
        symbols = FirmwareSymbols(board.elf)
    assert profile.period_cycles == PERIOD_CYCLES
    assert profile.taken == (awake_after - awake_before) // PERIOD_CYCLES
    assert len(profile.samples) == profile.taken
    by_function = profile.by_function(symbols)
    assert sum(by_function.values()) == profile.taken
    stacks = profile.stacks(symbols)
    known = symbols.names()
    assert {name for names in stacks for name in names} <= known
    # The Kalman filters, inlined into ImuProcessing::update under LTO, run
    # at 100 Hz; the TWI interrupt moves every byte of each sensor read.
    assert by_function["ImuProcessing::update(int const*, int, Coefficients const&, ImuOutput&, bool)"] > 0
    assert any(names[0] == "__vector_24" for names in stacks)
    # Soft float and division are charged to their callers: the shadow call
    # stack knows one for all but the samples of a call under way when the
    # profiler started.
    left_with_routines = sum(samples for name, samples in by_function.items() if is_runtime_routine(name))
    assert left_with_routines < 0.01 * profile.taken


def test_profiling_leaves_the_firmware_running_as_it_would():
    with streaming_imu() as plain, streaming_imu() as profiled:
        profiled.start_profile(PERIOD_CYCLES)
        for board in (plain, profiled):
            board.run_until(STREAMING_S + 2.0)
        assert profiled.read_uart() == plain.read_uart()
        assert profiled.cycle_counts() == plain.cycle_counts()


def test_the_profile_capacity_keeps_the_first_samples_and_counts_all():
    with streaming_imu() as board:
        board.start_profile(PERIOD_CYCLES, capacity=10)
        board.run_until(STREAMING_S + 0.5)
        profile = board.profile()
    assert len(profile.samples) == 10
    assert profile.taken > 10


def test_summary_records_each_boards_awake_and_sleeping_cycles(tmp_path):
    timing = simulate.StepTiming()
    summary = simulate.run(
        build("idle", ScenarioOptions(duration_s=3.0)), Model.load(), tmp_path, timing=timing
    ).summary
    for report in summary.boards.values():
        assert report.awake_cycles > 0
        assert report.awake_cycles + report.sleep_cycles == report.cycles
    assert set(timing.seconds) == set(simulate.StepTiming.PHASES)
    assert sum(timing.seconds.values()) <= summary.wall_seconds
