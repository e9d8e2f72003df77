import signal
import sys

import pytest
from test_bad_input import assert_one_line_error

from thermotilt import __version__
from thermotilt.cli import main
from thermotilt.surfaces import PAPER_DEFAULTS
from thermotilt.wire.coefficients import SetDomain, decode_block, encode_block
from thermotilt.wire.protocol import PROTOCOL_VERSION, build_frame


def test_version(cli_in_process):
    result = cli_in_process("--version")
    assert result.returncode == 0
    assert result.stdout.strip() == f"thermotilt {__version__} (protocol {PROTOCOL_VERSION})"


def test_frames_counts(tmp_path, capsys):
    capture = tmp_path / "capture.txt"
    capture.write_bytes(
        b"boot noise\r\n"
        + build_frame("ACK", 0, [0, "START"]).encode()
        + build_frame("IMU", 1, [10, 1, 2, 3, 1.5, 2.5, 3.5, 1.0, 2.0, 3.0, 21.5, "W", "D", "U"]).encode()
        + build_frame("ACK", 2, [0, "STOP"]).replace("STOP", "STOQ").encode()
        + build_frame("IMU", 4, [20, 1, 2, 3, 1.5, 2.5, 3.5, 1.0, 2.0, 3.0, 21.5, "W", "D", "U"]).encode()
        + build_frame("IMU", 5, [30, 1, 2, 3, 1.5, 2.5, 3.5, 1.0, 2.0, 3.0, 21.5, "W", "D", "U"])
        .encode()
        .rstrip(b"\r\n")
    )
    assert main(["frames", str(capture)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == [
        "frames: 4",
        "  ACK: 1",
        "  IMU: 3",
        "malformed: 1",
        "  BAD_CHECKSUM: 1",
        "gaps: 1 (lost frames: 2)",
    ]


def test_frames_from_stdin(cli_in_process, tmp_path, monkeypatch):
    capture = tmp_path / "capture.txt"
    capture.write_text(build_frame("START", 1))
    with open(capture) as stdin:
        monkeypatch.setattr(sys, "stdin", stdin)
        result = cli_in_process("frames", "-")
    assert result.returncode == 0
    assert "  START: 1" in result.stdout.splitlines()


def test_frames_missing_file(cli_in_process, tmp_path):
    result = cli_in_process("frames", str(tmp_path / "absent.txt"))
    assert_one_line_error(result, 1)
    assert "cannot read" in result.stderr and "No such file" in result.stderr


def test_frames_without_valid_frames(cli_in_process, tmp_path):
    capture = tmp_path / "junk.bin"
    corrupted = build_frame("ACK", 0, [13, "STOP"]).replace("STOP", "STOQ")
    capture.write_bytes(corrupted.encode() + b"hello\r\n")
    result = cli_in_process("frames", str(capture))
    assert_one_line_error(result, 1)
    assert "no valid frames (1 malformed)" in result.stderr


@pytest.mark.parametrize("args", [[], ["bogus"], ["frames"], ["frames", "a", "b"]])
def test_usage_errors_are_one_line(cli_in_process, args):
    assert_one_line_error(cli_in_process(*args), 2)


def test_coefficients_defaults_and_block(cli_in_process, tmp_path):
    block = tmp_path / "coef.bin"
    result = cli_in_process("coefficients", "--write-block", str(block))
    assert result.returncode == 0
    lines = result.stdout.splitlines()
    assert len(lines) == 6 and all(line.startswith("$SETCOE,") for line in lines)
    assert decode_block(block.read_bytes()).table == PAPER_DEFAULTS.to_float32()
    again = cli_in_process("coefficients", "--block", str(block))
    assert again.returncode == 0 and len(again.stdout.splitlines()) == 6


def test_coefficients_of_a_fitted_block_set_its_domain_too(cli_in_process, tmp_path):
    block = tmp_path / "fit.bin"
    domain = {
        "W": SetDomain.covering((-10.0, 45.0), {"X": (-16000.0, 16000.0)}),
        "C": SetDomain.covering((-9.5, 44.5), {"X": (-15000.0, 15000.0)}),
    }
    block.write_bytes(encode_block(PAPER_DEFAULTS, "NODE-07", domain))
    result = cli_in_process("coefficients", "--block", str(block))
    assert result.returncode == 0
    lines = result.stdout.splitlines()
    assert [line.split(",")[0] for line in lines] == ["$SETCOE"] * 6 + ["$SETDOM"] * 2
    assert lines[6].startswith("$SETDOM,6,W,-10.00,45.00,-16000,16000,32767,-32768,32767,-32768*")
    assert lines[7].startswith("$SETDOM,7,C,-9.50,44.50,-15000,15000,")


def test_coefficients_corrupted_block(cli_in_process, tmp_path):
    block = tmp_path / "bad.bin"
    data = bytearray(encode_block(PAPER_DEFAULTS))
    data[10] ^= 0xFF
    block.write_bytes(bytes(data))
    result = cli_in_process("coefficients", "--block", str(block))
    assert_one_line_error(result, 1)
    assert "CRC" in result.stderr


@pytest.fixture
def ctrl_c_raises_keyboard_interrupt():
    """SIGINT as Python sets it up when started in the foreground, whatever
    this test run inherited (`nohup make test &` starts it ignored)."""
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, inherited)


@pytest.mark.usefixtures("ctrl_c_raises_keyboard_interrupt")
def test_ctrl_c_while_a_position_is_reported_waits_for_the_report(monkeypatch, capsys):
    """tqdm.write turns a KeyboardInterrupt inside its lock into a RuntimeError
    (a traceback instead of exit 130, seen once in CI): the report finishes,
    then the Ctrl-C is raised."""
    import os

    from tqdm import tqdm

    from thermotilt.calibration.campaign.folder import DONE, PositionRecord
    from thermotilt.calibration.campaign.session import report_position

    written = []

    def write_then_ctrl_c(line, file=None):
        written.append(line)
        os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(tqdm, "write", write_then_ctrl_c)
    record = PositionRecord("X+30", 30.0, 0.0, status=DONE, wall_seconds=61.0, reported_errors=["ERR RESET"])
    with pytest.raises(KeyboardInterrupt):
        report_position(record)
    assert written == ["X+30: done in 61 s", "X+30: reported ERR RESET"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
