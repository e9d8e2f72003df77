"""thermotilt.wire.client.CommandClient against the real imu_reader and
thermal_chamber images in the twin (directly, and through a pseudo-terminal
with pyserial) and against a scripted port for what the twin cannot stage.

Expected values come from docs/protocol.md (answers, ERR codes) and the
paper's default coefficients.
"""

import itertools
import threading

import pytest
import serial
from firmware_helpers import chamber, of_type

from thermotilt.surfaces import AXES, COEFFICIENT_NAMES, PAPER_DEFAULTS, SETS
from thermotilt.twin.boards import Board
from thermotilt.wire.client import CommandClient, CommandRefused, CommandTimeout
from thermotilt.wire.protocol import FrameReader, build_frame, parse_line

# -1700 / -400 / 16000 LSB, raw temperature 32 -> 25.000 degC.
SENSOR = (-1700, -400, 16000, 32)
COMMANDS = 50


class RecordingBoard:
    """A twin Board that also keeps every command line written to it."""

    def __init__(self, board: Board):
        self.board = board
        self.written: list[str] = []

    def write_uart(self, data: bytes) -> None:
        self.written.append(data.decode("ascii"))
        self.board.write_uart(data)

    def __getattr__(self, name):
        return getattr(self.board, name)


@pytest.fixture
def imu():
    with Board.imu_reader() as board:
        board.attach_lsm9ds0()
        board.set_lsm9ds0(*SENSOR)
        board.run_until(0.3)
        yield RecordingBoard(board)


def surfaces():
    return itertools.cycle([(s, a) for s in SETS for a in AXES])


@pytest.mark.twin
def test_fifty_getcoe_through_the_client_are_all_answered(imu):
    streamed = []
    client = CommandClient(imu, on_frame=streamed.append)
    for seq, (set_, axis) in zip(range(COMMANDS), surfaces()):
        answer = client.command("GETCOE", [set_, axis])
        assert (answer.ack["cmd_seq"], answer.ack["cmd_type"]) == (seq, "GETCOE")
        (coe,) = answer.data
        assert (coe["set"], coe["axis"]) == (set_, axis)
        paper = PAPER_DEFAULTS.surface(set_, axis)
        assert tuple(coe[term] for term in COEFFICIENT_NAMES) == pytest.approx(tuple(paper), rel=1e-4, abs=1e-12)
    assert len(imu.written) == COMMANDS
    assert client.reader.malformed == 0 and client.reader.gaps == 0
    # The board kept streaming meanwhile, and those frames were passed on.
    assert of_type(streamed, "IMU")
    assert not of_type(streamed, "ERR")


@pytest.mark.twin
def test_fifty_getcoe_sent_back_to_back_overrun_the_board(imu):
    # Why the client waits: the twin's line never drops a byte (it holds them
    # while simavr's receiver says XOFF), so every loss is in the firmware's
    # 64-byte receive buffer, overrun while the board sends its answers.
    imu.write_uart(b"".join(build_frame("GETCOE", seq, ["W", "X"]).encode() for seq in range(COMMANDS)))
    imu.run_until(imu.seconds + 2.0)
    frames = FrameReader().feed(imu.read_uart())
    assert len(of_type(frames, "ACK")) < COMMANDS
    assert {e["code"] for e in of_type(frames, "ERR")} == {"BAD_FRAME"}


@pytest.mark.twin
def test_every_data_frame_of_a_chamber_query_is_its_answer_and_not_passed_on():
    # docs/protocol.md: the chamber answers STATUS with PRG and GRD, then ACK.
    passed_on = []
    with chamber(22.0) as board:
        board.run_until(0.3)
        client = CommandClient(board, on_frame=passed_on.append)
        status = client.command("STATUS")
        version = client.command("VERSION")
        client.wait_for(lambda frame: frame.type == "CHS", 1.5)
    assert [frame.type for frame in status.data] == ["PRG", "GRD"]
    assert [frame.type for frame in version.data] == ["VER"]
    assert {frame.type for frame in passed_on} == {"VER", "CHS"}
    # The VER passed on is the one the board sent when it started.
    assert of_type(passed_on, "VER")[0].seq == 0


@pytest.mark.twin
def test_a_refused_command_raises_with_the_boards_code_and_is_not_retried(imu):
    client = CommandClient(imu)
    with pytest.raises(CommandRefused) as refused:
        client.command("SETDEC", [0])
    assert (refused.value.command, refused.value.code, refused.value.detail) == ("SETDEC", "BAD_ARG", "FACTOR_1_255")
    with pytest.raises(CommandRefused, match="UNKNOWN_CMD SETPRG"):
        client.command("SETPRG", [20, 30, 2, 60, 1200, 1, "T"])
    assert [parse_line(line).type for line in imu.written] == ["SETDEC", "SETPRG"]
    # The client goes on after a refusal.
    assert client.command("SETDEC", [20]).ack["cmd_type"] == "SETDEC"


@pytest.mark.twin
def test_a_command_without_an_answer_times_out_after_its_retries(imu):
    # Every byte both ways gets a bit flipped: nothing valid arrives.
    imu.set_uart_corruption(1.0, 7)
    client = CommandClient(imu, timeout_s=0.2, retries=2)
    started = imu.seconds
    with pytest.raises(CommandTimeout) as timeout:
        client.command("GETCOE", ["W", "X"])
    assert (timeout.value.command, timeout.value.attempts) == ("GETCOE", 3)
    # Three attempts of 0.2 s of simulated time each.
    assert imu.seconds - started == pytest.approx(0.6, abs=1e-6)
    assert [parse_line(line).seq for line in imu.written] == [0, 1, 2]


@pytest.mark.twin
def test_start_is_sent_once(imu):
    imu.set_uart_corruption(1.0, 7)
    client = CommandClient(imu, timeout_s=0.2, retries=2)
    with pytest.raises(CommandTimeout, match="not retried") as timeout:
        client.command("START")
    assert timeout.value.attempts == 1
    assert len(imu.written) == 1


class ScriptedPort:
    """A pyserial-like port whose board answers from a script: the i-th
    command written gets script[i](command) bytes back at once."""

    def __init__(self, script):
        self._script = list(script)
        self._pending = bytearray()
        self.commands = []

    def write(self, data: bytes) -> None:
        command = parse_line(data.decode("ascii"))
        self._pending += self._script[len(self.commands)](command)
        self.commands.append(command)

    def flush(self) -> None:
        pass

    @property
    def in_waiting(self) -> int:
        return len(self._pending)

    def read(self, size: int) -> bytes:
        chunk = bytes(self._pending[:size])
        del self._pending[:size]
        return chunk


def coe_and_ack(board_seq: int, set_: str, axis: str, cmd_seq: int) -> bytes:
    surface = PAPER_DEFAULTS.surface(set_, axis)
    return (
        build_frame("COE", board_seq, [set_, axis, *surface]) + build_frame("ACK", board_seq + 1, [cmd_seq, "GETCOE"])
    ).encode()


def test_a_late_answer_to_an_earlier_attempt_is_not_taken_for_the_retry():
    port = ScriptedPort(
        [
            lambda command: b"",
            # The first attempt's answer arrives late, in front of the second's.
            lambda command: coe_and_ack(10, "W", "X", command.seq - 1) + coe_and_ack(12, "C", "Y", command.seq),
        ]
    )
    streamed = []
    client = CommandClient(port, timeout_s=0.05, retries=1, on_frame=streamed.append)
    answer = client.command("GETCOE", ["C", "Y"])
    assert [command.seq for command in port.commands] == [0, 1]
    assert answer.ack["cmd_seq"] == 1
    assert [(f["set"], f["axis"]) for f in answer.data] == [("C", "Y")]
    # The late answer is passed on, not lost.
    assert [(f.type, f.seq) for f in streamed] == [("COE", 10), ("ACK", 11)]


def test_frames_after_a_refusal_are_passed_on():
    imu_frame = build_frame("IMU", 3, [1000, 1, 2, 3, 1.0, 2.0, 3.0, 1.0, 2.0, 3.0, 25.0, "W", "D", "U"])
    port = ScriptedPort(
        [lambda command: (build_frame("ERR", 2, [command.seq, "BAD_ARG", "SET_AXIS"]) + imu_frame).encode()]
    )
    streamed = []
    client = CommandClient(port, on_frame=streamed.append)
    with pytest.raises(CommandRefused, match="BAD_ARG SET_AXIS"):
        client.command("GETCOE", ["Q", "X"])
    assert [f.type for f in streamed] == ["IMU"]


@pytest.mark.twin
def test_the_client_drives_the_twin_through_its_pty_with_pyserial(imu):
    path = imu.open_pty()
    stop = threading.Event()

    def run_board():
        # The twin runs as fast as it can; the pty carries its bytes.
        while not stop.is_set():
            imu.run_until(imu.seconds + 0.01)

    runner = threading.Thread(target=run_board)
    with serial.Serial(path, 115200, timeout=0) as port:
        runner.start()
        try:
            client = CommandClient(port, timeout_s=2.0)
            (version,) = client.command("VERSION").data
            answers = [client.command("GETCOE", [set_, axis]) for set_, axis in itertools.islice(surfaces(), 6)]
        finally:
            stop.set()
            runner.join()
    assert version["device"] == "imu_reader"
    assert [(a.data[0]["set"], a.data[0]["axis"]) for a in answers] == [(s, a) for s in SETS for a in AXES]
    assert imu.pty_dropped_bytes == 0


@pytest.mark.twin
def test_wait_for_reads_what_the_board_sends_on_its_own(imu):
    passed_on = []
    client = CommandClient(imu, on_frame=passed_on.append)
    boot = client.wait_for(lambda frame: frame.type == "VER", 0.5)
    assert (boot["device"], boot["reset_cause"]) == ("imu_reader", "POWER_ON")
    client.command("RESET")
    restart = client.wait_for(lambda frame: frame.type == "VER", 0.5)
    assert restart["reset_cause"] == "COMMANDED"
    # Every frame read went on, the wanted ones too.
    assert boot in passed_on and restart in passed_on and of_type(passed_on, "IMU")
    started = imu.seconds
    assert client.wait_for(lambda frame: frame.type == "CHS", 0.3) is None
    assert imu.seconds >= started + 0.3
