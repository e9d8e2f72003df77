"""What the firmware tests share: the thermistor divider, a chamber board
with its thermistors set, a program to start, and frame picking."""

import math

from thermotilt.twin.boards import Board
from thermotilt.wire.protocol import build_frame


def divider_millivolts(celsius: float) -> float:
    """The thermistor input for a temperature: beta equation, 100 kOhm NTC
    (beta 3950 K) to ground below a 100 kOhm reference resistor from 5 V."""
    ntc = 100e3 * math.exp(3950.0 * (1.0 / (celsius + 273.15) - 1.0 / 298.15))
    return 5000.0 * ntc / (ntc + 100e3)


def of_type(frames, frame_type):
    return [frame for frame in frames if frame.type == frame_type]


def chamber(inner_c: float, outer_c: float = 25.0) -> Board:
    """The chamber firmware with the L298N watched and both faces held."""
    board = Board.thermal_chamber()
    board.attach_l298n()
    board.set_adc_millivolts(0, divider_millivolts(inner_c))
    board.set_adc_millivolts(1, divider_millivolts(outer_c))
    return board


def start_program(board: Board, start_c: float, seq: int = 1) -> None:
    """The timed staircase from start_c (SETPRG as seq, START as seq + 1);
    its first step holds start_c for 60 s."""
    commands = build_frame("SETPRG", seq, [start_c, start_c + 10, 2, 60, 1200, 1, "T"]) + build_frame("START", seq + 1)
    board.write_uart(commands.encode())
