"""Tilt-table moves: the IMU restarts its filters on RESEED, the twin's
campaign sends it at every move, and the run log says how long ago the
table moved, so no tool fits settling data by accident."""

from __future__ import annotations

import pytest
from child_process import THERMOTILT, run
from firmware_helpers import of_type

from thermotilt.physics import Model
from thermotilt.run.log import read_run_log
from thermotilt.twin.boards import Board
from thermotilt.wire.protocol import FrameReader, build_frame

pytestmark = pytest.mark.twin

LSB_PER_G = 16393.44
TEMPERATURE_RAW_25C = 32  # (25 - 21) * 8


def test_reseed_restarts_the_filters_from_the_next_sample():
    reader = FrameReader()
    with Board.imu_reader() as board:
        board.attach_lsm9ds0()
        board.set_lsm9ds0(0, 0, 16393, TEMPERATURE_RAW_25C)
        board.run_until(3.0)
        # The table tilts 45 deg on X: ax jumps from 0 to sin(45 deg) g.
        board.set_lsm9ds0(11592, 0, 11592, TEMPERATURE_RAW_25C)
        board.run_until(4.0)
        before = reader.feed(board.read_uart())
        board.write_uart(build_frame("RESEED", 1).encode())
        board.run_until(5.0)
        after = reader.feed(board.read_uart())
    # Without RESEED the filter (gain ~1/n three seconds after its seed,
    # falling to 1e-3) is still more than half the step away a second after
    # the move ...
    assert of_type(before, "IMU")[-1]["ax_filt"] < 11592 / 2
    assert [(f["cmd_seq"], f["cmd_type"]) for f in of_type(after, "ACK")] == [(1, "RESEED")]
    # ... with it, every frame after the ACK is the new angle exactly (the
    # readings are constant, so a freshly seeded mean is the reading itself).
    acknowledged = of_type(after, "ACK")[0].seq
    reseeded = [f for f in of_type(after, "IMU") if f.seq > acknowledged]
    assert len(reseeded) >= 8
    assert all((f["ax_filt"], f["az_filt"]) == (11592.0, 11592.0) for f in reseeded)


@pytest.mark.slow
def test_the_campaign_reseeds_at_every_move_and_logs_the_time_since(tmp_path):
    out = tmp_path / "campaign"
    result = run(
        [
            *THERMOTILT,
            "simulate",
            "campaign",
            "--positions",
            "0,X+45",
            "--hold-seconds",
            "2",
            "--rest-seconds",
            "0",
            "--hold-start",
            "T",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert "refused" not in result.stdout
    capture = (out / "serial" / "imu_reader.txt").read_bytes()
    acks = [f for f in FrameReader().feed(capture) if f.type == "ACK" and f["cmd_type"] == "RESEED"]
    assert len(acks) == 2
    rows = read_run_log(str(out / "run.csv"))
    tilted = [row for row in rows if row["incl_x_deg"] == "45.00"]
    since = [float(row["since_move_s"]) for row in tilted]
    assert since[0] < 0.2 and all(b > a for a, b in zip(since, since[1:]))
    # From 2 s after the move the filtered X axis is the new angle plus the
    # model's drift and measuring offset (of the set the model is in), within
    # the noise of a 200-sample mean and the die's slow temperature change
    # (a stale filter would be ~11 600 LSB off).
    offsets = Model.load().terms["measuring_offset"]
    offset_x = {"W": offsets["warming_lsb"]["x"], "C": offsets["cooling_lsb"]["x"]}
    settled = [row for row in tilted if 2.0 <= float(row["since_move_s"]) <= 10.0]
    assert len(settled) >= 70
    for row in settled:
        expected = float(row["true_ax"]) + float(row["true_drift_x"]) + offset_x[row["true_drift_set"]]
        assert abs(float(row["ax_filt"]) - expected) < 30, row["time_s"]
