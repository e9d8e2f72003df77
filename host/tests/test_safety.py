"""The chamber reaches a safe state by itself: runaway in both directions,
absolute limits, latched faults, a control loop nothing can starve, the
watchdog and the host heartbeat, each shown in the digital twin with the
real thermal_chamber firmware (docs/reliability.md)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest
from firmware_helpers import chamber, of_type, start_program

from thermotilt.physics import Model, parse_fault
from thermotilt.twin import simulate
from thermotilt.twin.boards import Board, Drive
from thermotilt.twin.scenarios import Command, Scenario, TablePosition
from thermotilt.wire.protocol import FrameReader, build_frame

pytestmark = pytest.mark.twin

AMBIENT_C = 22.0
PROGRAM_STARTED_S = 1.5
# lib/ThermalGuard defaults, as the firmware reports them in GRD.
WINDOW_S = 90.0
INNER_MAX_C = 55.0
INNER_MIN_C = -20.0
CONTROL_PERIOD_S = 0.25
# The thermistors lag their faces by 2.5 s (models/default.toml) and a face
# moves at most ~0.25 degC/s under full drive, so a reading-based limit lets
# the face itself pass by at most ~0.6 degC.
THERMISTOR_LAG_MARGIN_C = 1.0


def program(start_c: float, max_c: float, duration_s: float, extra: tuple[Command, ...] = ()) -> Scenario:
    """The staircase from start_c held 600 s a step: its first target is start_c."""
    return Scenario(
        name="safety",
        description=f"chamber program from {start_c} degC",
        duration_s=duration_s,
        uses_chamber=True,
        ambient_c=lambda _t: AMBIENT_C,
        positions=(TablePosition(0.0, "table", 0.0, 0.0),),
        commands=extra
        + (
            Command(1.0, "SETPRG", (start_c, max_c, 2.0, 600, 60, 1, "T")),
            Command(PROGRAM_STARTED_S, "START"),
        ),
    )


def run(tmp_path: Path, scenario: Scenario, *faults: str):
    model = Model.load().with_faults([parse_fault(text) for text in faults])
    simulate.run(scenario, model, tmp_path, seed=1)
    frames = FrameReader().feed((tmp_path / "serial" / "thermal_chamber.txt").read_bytes())
    with open(tmp_path / "run.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    return frames, rows


def tripped(frames, rows):
    """The unsolicited ERR that stopped the chamber, the time the log first
    shows phase F, and the rows from then on."""
    errors = [frame for frame in of_type(frames, "ERR") if frame["cmd_seq"] == -1]
    first_fault = next(index for index, row in enumerate(rows) if row["phase"] == "F")
    return errors, float(rows[first_fault]["time_s"]), rows[first_fault:]


def assert_bridge_off_after(rows) -> None:
    # One twin step (10 ms) may still carry the duty of the tick that tripped.
    assert all(float(row["true_duty"]) == 0.0 for row in rows[1:])
    assert all(row["phase"] == "F" for row in rows)


def true_range(rows, column: str) -> tuple[float, float]:
    values = [float(row[column]) for row in rows]
    return min(values), max(values)


@pytest.mark.slow
@pytest.mark.parametrize("start_c, max_c", [(40.0, 45.0), (-10.0, 0.0)], ids=["heating", "cooling"])
def test_reversed_leads_trip_wrong_way_in_seconds(tmp_path, start_c, max_c):
    frames, rows = run(tmp_path, program(start_c, max_c, 40.0), "peltier_reversed")
    errors, at_s, after = tripped(frames, rows)
    assert [(e["code"], e["detail"]) for e in errors] == [("RUNAWAY", "WRONG_WAY")]
    # Full drive moves the face ~0.15 degC/s the wrong way: 2 degC in ~15 s,
    # plus the thermistor's 2.5 s lag.
    assert at_s - PROGRAM_STARTED_S < 25.0
    assert_bridge_off_after(after)
    low, high = true_range(rows, "true_inner_c")
    assert high - low < 3.0


@pytest.mark.slow
@pytest.mark.parametrize(
    "fault, start_c, max_c",
    [
        ("inner_detached", 40.0, 45.0),
        ("inner_detached", -10.0, 0.0),
        ("peltier_disconnected", 40.0, 45.0),
    ],
    ids=["detached-heating", "detached-cooling", "disconnected"],
)
def test_a_face_that_does_not_follow_trips_no_response(tmp_path, fault, start_c, max_c):
    frames, rows = run(tmp_path, program(start_c, max_c, 100.0), fault)
    errors, at_s, after = tripped(frames, rows)
    assert [(e["code"], e["detail"]) for e in errors] == [("RUNAWAY", "NO_RESPONSE")]
    # The window runs from the first full-drive tick after START.
    assert WINDOW_S <= at_s - PROGRAM_STARTED_S <= WINDOW_S + 2 * CONTROL_PERIOD_S + 0.1
    assert_bridge_off_after(after)
    low, high = true_range(rows, "true_inner_c")
    assert INNER_MIN_C < low and high < INNER_MAX_C


@pytest.mark.slow
def test_a_thermistor_coming_off_during_a_hold_trips_at_once(tmp_path):
    # The face reaches 40 degC in ~3 min; the detached thermistor then falls
    # towards the room while the drive heats at full power.
    frames, rows = run(tmp_path, program(40.0, 45.0, 280.0), "inner_detached@250")
    errors, at_s, after = tripped(frames, rows)
    assert [(e["code"], e["detail"]) for e in errors] == [("RUNAWAY", "WRONG_WAY")]
    assert 250.0 < at_s < 260.0
    assert_bridge_off_after(after)
    assert true_range(rows, "true_inner_c")[1] < 41.0


@pytest.mark.slow
def test_a_failed_heatsink_stops_at_the_outer_limit(tmp_path):
    # Cooling pumps the heat into the outer face; with its path to ambient
    # gone it heats by tenths of a degC a second. A 40 degC outer limit set
    # with SETGRD trips sooner than the default 70 degC (163 s,
    # docs/reliability.md) and shows that the limits are settable.
    limits = Command(0.5, "SETGRD", (1.0, 1.0, 90.0, 2.0, 120.0, -20.0, 55.0, -20.0, 40.0))
    frames, rows = run(tmp_path, program(-10.0, 0.0, 300.0, (limits,)), "heatsink_failed")
    assert [(f["cmd_seq"], f["cmd_type"]) for f in of_type(frames, "ACK")][:1] == [(0, "SETGRD")]
    errors, at_s, after = tripped(frames, rows)
    assert [(e["code"], e["detail"]) for e in errors] == [("LIMIT", "OUTER_HOT")]
    assert_bridge_off_after(after)
    assert true_range(rows, "true_outer_c")[1] < 40.0 + THERMISTOR_LAG_MARGIN_C


# ---- the firmware alone, without physics ------------------------------------


def drive_between(board: Board, start_s: float, end_s: float) -> Drive:
    """What reached the Peltier from start_s to end_s of simulated time."""
    board.run_until(start_s)
    board.read_l298n()
    board.run_until(end_s)
    return board.read_l298n()


def test_a_hung_loop_resets_into_the_safe_state_and_says_so():
    reader = FrameReader()
    with chamber(inner_c=18.0) as board:
        board.run_until(1.0)
        start_program(board, 20.0)
        board.run_until(2.0)
        assert board.read_l298n().pwm == 255
        board.hang()
        hung = drive_between(board, 2.0, 2.45)
        after = drive_between(board, 2.6, 4.0)
        frames = reader.feed(board.read_uart())
    # A hang leaves the hardware PWM running: only the watchdog (500 ms) stops it.
    assert hung.duty == pytest.approx(1.0)
    assert after.duty == 0.0
    versions = of_type(frames, "VER")
    assert [v["reset_cause"] for v in versions] == ["POWER_ON", "WATCHDOG"]
    assert [(e["code"], e["detail"]) for e in of_type(frames, "ERR")] == [("RESET", "WATCHDOG")]
    # After the reset no program runs until the host sends one again.
    assert all(f["phase"] == "I" for f in of_type(frames, "CHS") if f.seq > versions[1].seq)


def test_the_imu_reader_resets_from_a_hang_too():
    reader = FrameReader()
    with Board.imu_reader() as board:
        board.attach_lsm9ds0()
        board.set_lsm9ds0(-1700, -400, 16000, 32)
        board.run_until(1.0)
        board.hang()
        board.run_until(3.0)
        frames = reader.feed(board.read_uart())
    assert [v["reset_cause"] for v in of_type(frames, "VER")] == ["POWER_ON", "WATCHDOG"]
    # After the second VER in the stream: sequence numbers start again at 0.
    rebooted = frames.index(of_type(frames, "VER")[1])
    restarted = of_type(frames[rebooted:], "IMU")
    # Reset at ~1.5 s, sensor set up again, then 10 frames a second.
    assert len(restarted) >= 5
    assert all(b["t_ms"] - a["t_ms"] in (99, 100, 101) for a, b in zip(restarted, restarted[1:]))


def test_a_flood_of_bad_lines_does_not_starve_the_control_loop():
    # 10 s of "$\n" at the line rate: 57 600 malformed lines.
    reader = FrameReader()
    with chamber(inner_c=18.0) as board:
        board.run_until(1.0)
        start_program(board, 20.0)
        board.run_until(2.0)
        board.write_uart(b"$\n" * 57600)
        board.run_until(5.0)
        board.set_adc_fault(0, "open")
        cut = drive_between(board, 5.1, 5.4)
        board.run_until(12.0)
        frames = reader.feed(board.read_uart())
    # The open thermistor is seen on the next 250 ms tick, not seconds later.
    assert cut == Drive(duty=0.0, direction=0, pwm=0)
    statuses = of_type(frames, "CHS")
    periods = [b["t_ms"] - a["t_ms"] for a, b in zip(statuses, statuses[1:])]
    assert all(abs(period - 1000) <= 5 for period in periods)
    bad_frames = [e for e in of_type(frames, "ERR") if e["code"] == "BAD_FRAME"]
    # At most one BAD_FRAME a second over the ~10 s flood.
    assert 5 <= len(bad_frames) <= 11


def test_an_echo_of_the_boards_own_frames_is_not_answered():
    reader = FrameReader()
    with chamber(inner_c=18.0) as board:
        board.run_until(3.0)
        sent = board.read_uart()
        board.write_uart(sent * 3)
        board.run_until(6.0)
        frames = reader.feed(sent + board.read_uart())
    assert of_type(frames, "ERR") == []
    assert of_type(frames, "ACK") == []


def test_start_needs_an_accepted_program():
    reader = FrameReader()
    with chamber(inner_c=18.0) as board:
        board.run_until(1.0)
        board.write_uart(
            (
                build_frame("START", 1)
                + build_frame("SETPRG", 2, [20, 30, 2, 60, 1200, 1, "T"])
                + build_frame("SETPRG", 3, [20, 90, 2, 60, 1200, 1, "T"])
                + build_frame("START", 4)
                + build_frame("STATUS", 5)
            ).encode()
        )
        board.run_until(2.0)
        frames = reader.feed(board.read_uart())
        drive = board.read_l298n()
    errors = [(e["cmd_seq"], e["code"], e["detail"]) for e in of_type(frames, "ERR")]
    assert errors == [(1, "NO_PROGRAM", "SETPRG_FIRST"), (3, "BAD_ARG", "MAX_RANGE"), (4, "NO_PROGRAM", "SETPRG_FIRST")]
    assert of_type(frames, "PRG")[0]["accepted"] == 0
    assert drive.duty == 0.0


def test_guard_settings_are_reported_and_checked():
    reader = FrameReader()
    with chamber(inner_c=18.0) as board:
        board.run_until(1.0)
        board.write_uart(
            (
                build_frame("SETGRD", 1, [1, 1, 90, 2, 120, -20, 90, -20, 70])
                + build_frame("SETGRD", 2, [0.5, 1, 60, 2, 120, -20, 50, -20, 60])
                + build_frame("SETHB", 3, [3601])
                + build_frame("SETHB", 4, [30])
                + build_frame("STATUS", 5)
            ).encode()
        )
        board.run_until(2.0)
        frames = reader.feed(board.read_uart())
    errors = [(e["cmd_seq"], e["detail"]) for e in of_type(frames, "ERR")]
    assert errors == [(1, "LIMIT_RANGE"), (3, "HEARTBEAT_0_3600")]
    guard = of_type(frames, "GRD")[0]
    assert (guard["band_c"], guard["window_s"], guard["inner_max_c"], guard["outer_max_c"]) == (0.5, 60.0, 50.0, 60.0)
    assert guard["heartbeat_s"] == 30


def test_a_silent_host_stops_the_program_when_the_heartbeat_is_on():
    reader = FrameReader()
    with chamber(inner_c=18.0) as board:
        board.run_until(1.0)
        board.write_uart(build_frame("SETHB", 1, [3]).encode())
        start_program(board, 20.0, seq=2)
        board.run_until(3.5)
        board.write_uart(build_frame("STATUS", 4).encode())
        alive = drive_between(board, 5.0, 6.0)
        silent = drive_between(board, 8.0, 9.0)
        frames = reader.feed(board.read_uart())
    # The last host frame arrived at ~3.5 s: the heartbeat runs out at ~6.5 s.
    assert alive.duty == pytest.approx(1.0, abs=1e-3)
    assert silent.duty == 0.0
    assert [(e["code"], e["detail"]) for e in of_type(frames, "ERR")] == [("HEARTBEAT", "HOST_SILENT")]
    tripped_at = next(f["t_ms"] for f in of_type(frames, "CHS") if f["phase"] == "F")
    assert 6500 <= tripped_at <= 7500
    assert math.isnan(next(f for f in of_type(frames, "CHS") if f["phase"] == "F")["setpoint_c"])
