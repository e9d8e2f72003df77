"""`thermotilt log` against a pseudo-terminal fed by the test: rows follow the
run.csv schema, chamber columns come from CHS frames, malformed lines are
counted and skipped, and bad use ends with one readable line."""

import os
import signal
import subprocess
import termios
import threading
import time

import pytest

from thermotilt.cli import main
from thermotilt.protocol import build_frame
from thermotilt.runlog import COLUMNS, read_run_log

from child_process import THERMOTILT, popen


def imu_frame(seq, t_ms, ax=-1650):
    return build_frame("IMU", seq, [t_ms, ax, 12, 16390, ax + 0.5, 12.25, 16389.9,
                                    ax - 3.5, 10.0, 16389.9, 24.125, "W", "D"])


def chs_frame(seq, t_ms, setpoint, inner):
    return build_frame("CHS", seq, [t_ms, "W", 3, setpoint, inner, 23.5, 175, "H", "OK"])


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


def test_log_writes_one_row_per_imu_frame_with_chamber_state(pty_pair, tmp_path, capsys):
    imu_master, imu_port = pty_pair()
    chamber_master, chamber_port = pty_pair()
    out = tmp_path / "run.csv"
    chamber_timer = feed_when_opened(chamber_master, [chs_frame(0, 900, 18.0, 17.62)])
    imu_lines = [imu_frame(0, 1000), "$IMU,1,garbage*00\r\n", imu_frame(2, 1100), imu_frame(3, 1200)]
    timer = feed_when_opened(imu_master, imu_lines, after=chamber_timer)
    status = main(["log", "--port", imu_port, "--chamber-port", chamber_port, "--out", str(out),
                   "--rows", "3", "--incl-x", "30", "--raw-dir", str(tmp_path / "raw")])
    timer.join()
    chamber_timer.join()
    assert status == 0
    rows = read_run_log(str(out))
    assert list(rows[0]) == list(COLUMNS)
    assert [row["time_s"] for row in rows] == ["1.000", "1.100", "1.200"]
    assert rows[0]["ax_raw"] == "-1650" and rows[0]["ax_comp"] == "-1653.5"
    assert rows[0]["chamber_c"] == "17.62" and rows[0]["setpoint_c"] == "18"
    assert rows[0]["direction"] == "H" and rows[0]["pwm"] == "175"
    assert rows[0]["incl_x_deg"] == "30.00" and rows[0]["incl_y_deg"] == ""
    assert rows[0]["ambient_c"] == ""
    summary = capsys.readouterr().out
    assert "rows: 3" in summary and "rejected: 1" in summary
    assert (tmp_path / "raw" / "imu_reader.txt").read_bytes().count(b"$IMU") == 4


def test_log_stops_after_board_time(pty_pair, tmp_path):
    master, port = pty_pair()
    timer = feed_when_opened(master, [imu_frame(seq, 5000 + 100 * seq) for seq in range(40)])
    out = tmp_path / "run.csv"
    assert main(["log", "--port", port, "--out", str(out), "--duration", "2"]) == 0
    timer.join()
    rows = read_run_log(str(out))
    # 5.0 s to 7.0 s of board time at 10 Hz: 21 frames.
    assert len(rows) == 21 and rows[-1]["time_s"] == "7.000"


def test_log_ends_cleanly_when_the_port_closes(pty_pair, tmp_path, capsys):
    master, port = pty_pair()
    out = tmp_path / "run.csv"

    timer = feed_when_opened(master, [imu_frame(0, 0) + imu_frame(1, 100)], then_close=True)
    assert main(["log", "--port", port, "--out", str(out)]) == 0
    timer.join()
    assert len(read_run_log(str(out))) == 2
    assert "port closed" in capsys.readouterr().out


def test_log_refuses_a_missing_port_and_an_existing_output(tmp_path, capsys):
    assert main(["log", "--port", str(tmp_path / "ttyNONE"), "--out", str(tmp_path / "a.csv")]) == 1
    error = capsys.readouterr().err.strip()
    assert error.startswith("thermotilt: error: cannot open") and "\n" not in error
    existing = tmp_path / "b.csv"
    existing.write_text("keep me\n")
    assert main(["log", "--port", "loop://", "--out", str(existing)]) == 1
    assert "exists" in capsys.readouterr().err
    assert existing.read_text() == "keep me\n"


def test_log_without_any_frame_fails(pty_pair, tmp_path, capsys):
    master, port = pty_pair()

    timer = feed_when_opened(master, [b"hello\r\n$IMU,0*00\r\n"], then_close=True)
    assert main(["log", "--port", port, "--out", str(tmp_path / "run.csv")]) == 1
    timer.join()
    assert "no IMU frames received" in capsys.readouterr().err


def test_a_killed_log_keeps_every_byte_it_received(pty_pair, tmp_path):
    """Rows and raw bytes are flushed as they arrive: SIGKILL, which no
    handler sees, loses nothing the logger had read."""
    imu_master, imu_port = pty_pair()
    chamber_master, chamber_port = pty_pair()
    out, raw = tmp_path / "run.csv", tmp_path / "raw"
    imu_bytes = b"boot noise\r\n" + "".join(
        imu_frame(seq, 1000 + 100 * seq) for seq in range(40)).encode()
    chamber_bytes = "".join(chs_frame(seq, 900 + 1000 * seq, 18.0 + seq, 17.5) for seq in range(5))
    logger = popen(
        [*THERMOTILT, "log", "--port", imu_port, "--chamber-port",
         chamber_port, "--out", str(out), "--raw-dir", str(raw)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        wait_until_opened(chamber_master)
        os.write(chamber_master, chamber_bytes.encode())
        wait_until_opened(imu_master)
        time.sleep(0.3)
        os.write(imu_master, imu_bytes)
        # The last row carries the last CHS frame: the logger has read both ports to the end.
        wait_for(lambda: [row["setpoint_c"] for row in rows_of(out)][39:] == ["22"],
                 "every row written")
    finally:
        logger.kill()
        logger.wait(timeout=10)
    assert logger.returncode == -signal.SIGKILL
    assert (raw / "imu_reader.txt").read_bytes() == imu_bytes
    assert (raw / "thermal_chamber.txt").read_bytes() == chamber_bytes.encode()
