"""`thermotilt log` against a pseudo-terminal fed by the test: it writes a
run folder (run.csv, serial/, summary.json) as the twin does, rows follow
the run.csv schema, chamber columns come from CHS frames, malformed lines
are counted and skipped, a chamber program ends the log when it is done or
faulted, and bad use ends with one readable line."""

import os
import signal
import subprocess
import termios
import threading
import time

import pytest
from child_process import THERMOTILT, popen

from thermotilt.cli import main
from thermotilt.run.log import COLUMNS, read_run_log
from thermotilt.run.summary import read_summary
from thermotilt.wire.logger import ProgramWatch, log_boards
from thermotilt.wire.protocol import SequenceCounter, build_frame


def imu_frame(seq, t_ms, ax=-1650):
    return build_frame(
        "IMU", seq, [t_ms, ax, 12, 16390, ax + 0.5, 12.25, 16389.9, ax - 3.5, 10.0, 16389.9, 24.125, "W", "D", "U"]
    )


def chs_frame(seq, t_ms, setpoint, inner, phase="W", fault="OK"):
    return build_frame("CHS", seq, [t_ms, phase, 3, setpoint, inner, 23.5, 175, "H", fault])


@pytest.fixture
def pty_pair():
    opened = []

    def make():
        master, slave = os.openpty()
        opened.extend((master, slave))
        return master, os.ttyname(slave)

    yield make
    for descriptor in opened:
        try:
            os.close(descriptor)
        except OSError:
            pass


def wait_for(condition, what, timeout_s=20.0):
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, f"waited in vain: {what}"
        time.sleep(0.02)


def wait_until_opened(master):
    """pyserial puts the port in raw mode when it opens it (the master sees
    the same settings), then discards pending input: write only after that."""
    wait_for(lambda: not termios.tcgetattr(master)[3] & termios.ICANON, "the port opened")
    time.sleep(0.3)


def rows_of(path):
    return read_run_log(str(path)) if path.exists() else []


def feed_when_opened(master, chunks, then_close=False, after=None):
    def feed():
        wait_until_opened(master)
        if after is not None:
            after.join()
            time.sleep(0.2)
        for chunk in chunks:
            os.write(master, chunk.encode("ascii") if isinstance(chunk, str) else chunk)
        if then_close:
            # Closing the master discards what the slave has not read yet.
            time.sleep(0.5)
            os.close(master)

    thread = threading.Thread(target=feed)
    thread.start()
    return thread


def test_log_writes_a_run_folder_one_row_per_imu_frame_with_chamber_state(pty_pair, tmp_path, capsys):
    imu_master, imu_port = pty_pair()
    chamber_master, chamber_port = pty_pair()
    out = tmp_path / "rig"
    chamber_timer = feed_when_opened(chamber_master, [chs_frame(0, 900, 18.0, 17.62)])
    imu_lines = [imu_frame(0, 1000), "$IMU,1,garbage*00\r\n", imu_frame(2, 1100), imu_frame(3, 1200)]
    timer = feed_when_opened(imu_master, imu_lines, after=chamber_timer)
    status = main(
        ["log", "--port", imu_port, "--chamber-port", chamber_port, "--out", str(out), "--rows", "3", "--incl-x", "30"]
    )
    timer.join()
    chamber_timer.join()
    assert status == 0
    rows = read_run_log(str(out / "run.csv"))
    assert list(rows[0]) == list(COLUMNS)
    assert [row["time_s"] for row in rows] == ["1.000", "1.100", "1.200"]
    assert rows[0]["ax_raw"] == "-1650" and rows[0]["ax_comp"] == "-1653.5"
    assert rows[0]["chamber_c"] == "17.62" and rows[0]["setpoint_c"] == "18"
    assert rows[0]["direction"] == "H" and rows[0]["pwm"] == "175"
    assert rows[0]["incl_x_deg"] == "30.00" and rows[0]["incl_y_deg"] == ""
    assert rows[0]["ambient_c"] == "" and rows[0]["since_move_s"] == ""
    printed = capsys.readouterr().out
    assert "rows: 3" in printed and "rejected: 1" in printed
    assert (out / "serial" / "imu_reader.txt").read_bytes().count(b"$IMU") == 4
    summary = read_summary(out)
    assert (summary.source, summary.rows, summary.end_reason) == ("boards", 3, "3 rows")
    assert not summary.interrupted
    assert summary.positions == [{"at_s": 0.0, "label": None, "incl_x_deg": 30.0, "incl_y_deg": None}]
    imu, chamber = summary.boards["imu_reader"], summary.boards["thermal_chamber"]
    assert (imu.port, imu.rejected, imu.frames_by_type) == (imu_port, 1, {"IMU": 3})
    assert (chamber.port, chamber.frames_by_type) == (chamber_port, {"CHS": 1})
    # What only the twin knows stays unknown.
    assert summary.seed is None and summary.sim_seconds is None and imu.cycles is None


def test_log_stops_after_board_time_and_takes_the_run_csv_for_its_folder(pty_pair, tmp_path):
    master, port = pty_pair()
    timer = feed_when_opened(master, [imu_frame(seq, 5000 + 100 * seq) for seq in range(40)])
    # --out named the log before it named the folder; the log's name still names its folder.
    assert main(["log", "--port", port, "--out", str(tmp_path / "run.csv"), "--duration", "2"]) == 0
    timer.join()
    rows = read_run_log(str(tmp_path / "run.csv"))
    # 5.0 s to 7.0 s of board time at 10 Hz: 21 frames.
    assert len(rows) == 21 and rows[-1]["time_s"] == "7.000"
    assert read_summary(tmp_path).end_reason == "2 s of board time"


def test_log_ends_cleanly_when_the_port_closes(pty_pair, tmp_path, capsys):
    master, port = pty_pair()
    out = tmp_path / "run"

    timer = feed_when_opened(master, [imu_frame(0, 0) + imu_frame(1, 100)], then_close=True)
    assert main(["log", "--port", port, "--out", str(out)]) == 0
    timer.join()
    assert len(read_run_log(str(out / "run.csv"))) == 2
    assert "port closed" in capsys.readouterr().out
    assert read_summary(out).end_reason == "port closed"


def test_log_refuses_a_missing_port_and_an_existing_run(tmp_path, capsys):
    assert main(["log", "--port", str(tmp_path / "ttyNONE"), "--out", str(tmp_path / "a")]) == 1
    error = capsys.readouterr().err.strip()
    assert error.startswith("thermotilt: error: cannot open") and "\n" not in error
    assert not (tmp_path / "a").exists()
    existing = tmp_path / "b"
    existing.mkdir()
    (existing / "run.csv").write_text("keep me\n")
    for out in (existing, existing / "run.csv"):
        assert main(["log", "--port", "loop://", "--out", str(out)]) == 1
        assert f"{existing / 'run.csv'} exists" in capsys.readouterr().err
    assert (existing / "run.csv").read_text() == "keep me\n"


def test_log_without_any_frame_fails(pty_pair, tmp_path, capsys):
    master, port = pty_pair()

    timer = feed_when_opened(master, [b"hello\r\n$IMU,0*00\r\n"], then_close=True)
    assert main(["log", "--port", port, "--out", str(tmp_path / "run")]) == 1
    timer.join()
    assert "no IMU frames received" in capsys.readouterr().err
    # The folder still says what arrived.
    assert read_summary(tmp_path / "run").boards["imu_reader"].rejected_by_reason == {"NO_CHECKSUM": 1}


@pytest.mark.parametrize(
    "phase, fault, end_reason",
    [
        ("I", "OK", "program done"),
        ("F", "WRONG_WAY", "chamber fault WRONG_WAY"),
    ],
)
def test_a_program_ends_the_log_when_done_or_faulted(pty_pair, tmp_path, phase, fault, end_reason):
    """The rule the twin follows too (thermotilt.wire.recorder.ProgramEnd):
    idle or done after running, or a fault at any time, which latches until
    CLEAR. The IMU streams on; without the rule the log would run to its
    30 s of board time."""
    imu_master, imu_port = pty_pair()
    chamber_master, chamber_port = pty_pair()
    logged = threading.Event()

    def boards():
        wait_until_opened(imu_master)
        wait_until_opened(chamber_master)
        os.write(
            chamber_master,
            (chs_frame(0, 900, 18.0, 17.5, phase="W") + chs_frame(1, 1900, 18.0, 17.8, phase="R")).encode(),
        )
        for seq in range(600):
            if logged.is_set():
                return
            os.write(imu_master, imu_frame(seq, 1000 + 100 * seq).encode())
            if seq == 20:
                os.write(chamber_master, chs_frame(2, 3000, float("nan"), 18.0, phase, fault).encode())
            time.sleep(0.01)

    feeder = threading.Thread(target=boards)
    feeder.start()
    try:
        summary = log_boards(
            imu_port, tmp_path / "position", chamber_port, duration_s=30, program=ProgramWatch(None, SequenceCounter())
        )
    finally:
        logged.set()
        feeder.join()
    assert summary.end_reason == end_reason
    rows = read_run_log(str(tmp_path / "position" / "run.csv"))
    assert 20 <= len(rows) == summary.rows < 100
    assert {row["phase"] for row in rows} <= {"W", "R", phase}


def test_a_killed_log_keeps_every_byte_it_received(pty_pair, tmp_path):
    """Rows and raw bytes are flushed as they arrive: SIGKILL, which no
    handler sees, loses nothing the logger had read."""
    imu_master, imu_port = pty_pair()
    chamber_master, chamber_port = pty_pair()
    out = tmp_path / "run"
    imu_bytes = b"boot noise\r\n" + "".join(imu_frame(seq, 1000 + 100 * seq) for seq in range(40)).encode()
    chamber_bytes = "".join(chs_frame(seq, 900 + 1000 * seq, 18.0 + seq, 17.5) for seq in range(5))
    logger = popen(
        [*THERMOTILT, "log", "--port", imu_port, "--chamber-port", chamber_port, "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_until_opened(chamber_master)
        os.write(chamber_master, chamber_bytes.encode())
        wait_until_opened(imu_master)
        time.sleep(0.3)
        os.write(imu_master, imu_bytes)
        # The last row carries the last CHS frame: the logger has read both ports to the end.
        wait_for(lambda: [row["setpoint_c"] for row in rows_of(out / "run.csv")][39:] == ["22"], "every row written")
    finally:
        logger.kill()
        logger.wait(timeout=10)
    assert logger.returncode == -signal.SIGKILL
    assert (out / "serial" / "imu_reader.txt").read_bytes() == imu_bytes
    assert (out / "serial" / "thermal_chamber.txt").read_bytes() == chamber_bytes.encode()
