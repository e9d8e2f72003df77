"""`simulate --realtime`: the twin paced to the wall clock (the default with
--pty), so that a serial program sees a board's pace; without --pty it races.
The pacer is checked on a fake clock, the CLI on short idle runs."""

import json
import time

import pytest
from test_bad_input import assert_one_line_error

from thermotilt.cli import main
from thermotilt.twin import simulate
from thermotilt.twin.simulate import STEP_S, WallClockPacer

SIMULATED_S = 2.0


class FakeClock:
    """A monotonic clock that only moves when the twin works or sleeps;
    every sleep overshoots by `late` seconds, as a loaded machine's do."""

    def __init__(self, late: float = 0.0):
        self.now = 100.0
        self.late = late
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.now += seconds + self.late


def test_each_step_ends_when_the_wall_clock_reaches_it():
    clock = FakeClock()
    pacer = WallClockPacer(clock, clock.sleep)
    clock.now += 0.003  # the boards stepping 10 ms
    pacer.wait_until(STEP_S)
    assert clock.sleeps == [pytest.approx(0.007)]
    assert clock.now == pytest.approx(100.0 + STEP_S)


def test_late_wake_ups_do_not_add_up():
    clock = FakeClock(late=0.002)
    pacer = WallClockPacer(clock, clock.sleep)
    for step in range(1, 101):
        clock.now += 0.001
        pacer.wait_until(step * STEP_S)
    # One second simulated: the wall clock is one overshoot past it, not a hundred.
    assert clock.now - 100.0 == pytest.approx(1.0 + 0.002)


def test_a_twin_behind_the_wall_clock_runs_flat_out_until_it_is_level():
    clock = FakeClock()
    pacer = WallClockPacer(clock, clock.sleep)
    clock.now += 0.045  # one slow step: 35 ms behind
    for step in range(1, 5):
        pacer.wait_until(step * STEP_S)
    assert clock.sleeps == []
    pacer.wait_until(5 * STEP_S)
    assert clock.sleeps == [pytest.approx(0.005)]


@pytest.fixture
def waits_for_the_wall_clock(monkeypatch):
    """The simulated times at which a run's steps waited for the wall clock."""
    waited = []

    class RecordingPacer(WallClockPacer):
        def wait_until(self, simulated_s):
            waited.append(simulated_s)
            super().wait_until(simulated_s)

    monkeypatch.setattr(simulate, "WallClockPacer", RecordingPacer)
    return waited


def simulate_idle(tmp_path, *options):
    """(summary.json, wall seconds) of an idle run of SIMULATED_S."""
    out = tmp_path / "run"
    begin = time.monotonic()
    status = main(["simulate", "idle", "--duration", str(SIMULATED_S), "--out", str(out), *options])
    wall_s = time.monotonic() - begin
    assert status == 0
    return json.loads((out / "summary.json").read_text()), wall_s


@pytest.mark.slow
@pytest.mark.twin
@pytest.mark.parametrize(
    "options, paced",
    [
        (["--pty"], True),
        ([], False),
        (["--pty", "--realtime", "off"], False),
        (["--realtime", "on"], True),
    ],
)
def test_pty_runs_paced_by_default_and_other_runs_race(tmp_path, capsys, waits_for_the_wall_clock, options, paced):
    summary, wall_s = simulate_idle(tmp_path, *options)
    assert summary["realtime"] is paced
    assert summary["sim_seconds"] == SIMULATED_S
    if paced:
        # Every step waits for its end on the wall clock, however fast the machine.
        steps = round(SIMULATED_S / STEP_S)
        assert waits_for_the_wall_clock == pytest.approx([step * STEP_S for step in range(1, steps + 1)])
        assert wall_s >= SIMULATED_S
        assert "s simulated in real time ->" in capsys.readouterr().out
    else:
        # No step waits for the wall clock, however busy the machine.
        assert waits_for_the_wall_clock == []


def test_a_bad_realtime_value_is_one_line(cli_in_process, tmp_path):
    out = tmp_path / "run"
    result = cli_in_process("simulate", "idle", "--pty", "--realtime", "yes", "--out", out)
    assert_one_line_error(result, 2, "--realtime")
    assert result.stdout == "" and not out.exists()
