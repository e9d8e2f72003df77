"""Where a run's rows stand: the table's mountings, the rows settled after a
move, and the rows of the chamber's staircase once it reached its setpoint.
Calibration (fit) and discovery both take their rows from here."""

from __future__ import annotations

import numpy as np

from ..program import REACHED_BAND_C
from . import SETTLE_S

# The program is running a staircase: warming (W) or cooling (C) (lib/Program).
RUNNING_PHASES = ("W", "C")


def mountings(incl_x_deg: np.ndarray, incl_y_deg: np.ndarray, since_move_s: np.ndarray) -> np.ndarray:
    """Each row's mounting: 0 from the first row, one more at every table
    move (the angles change, or since_move_s starts again). Empty angles are
    one angle: a log without the table's angles is one mounting."""
    moved = np.zeros(len(incl_x_deg), dtype=bool)
    moved[1:] = _changed(incl_x_deg) | _changed(incl_y_deg)
    with np.errstate(invalid="ignore"):
        moved[1:] |= np.diff(since_move_s) < 0
    return np.cumsum(moved)


def _changed(values: np.ndarray) -> np.ndarray:
    """Whether each value differs from the one before it, NaN equal to NaN."""
    after, before = values[1:], values[:-1]
    return (after != before) & ~(np.isnan(after) & np.isnan(before))


def since_move(time_s: np.ndarray, mounting: np.ndarray, since_move_s: np.ndarray) -> np.ndarray:
    """Seconds since the table last moved: the log's since_move_s where it
    has one, else the time since the mounting's first row."""
    first_of_mounting = time_s[np.searchsorted(mounting, mounting)]
    return np.where(np.isfinite(since_move_s), since_move_s, time_s - first_of_mounting)


def settled(
    time_s: np.ndarray, mounting: np.ndarray, since_move_s: np.ndarray, settle_s: float = SETTLE_S
) -> np.ndarray:
    """The rows at least settle_s after a table move (SETTLE_S: the
    firmware's filters have forgotten the move)."""
    with np.errstate(invalid="ignore"):
        return since_move(time_s, mounting, since_move_s) >= settle_s


def staircase(
    phase: np.ndarray, chamber_c: np.ndarray, setpoint_c: np.ndarray, mounting: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(kept, stabilizing): the rows of each program run (phase W or C) from
    the first one whose inner face is within REACHED_BAND_C of its setpoint,
    and the program rows before it. Before that the chamber is still coming
    at full drive from where the program found it (the lab, a rest): the
    paper's "temperature stabilization" ahead of its measuring steps
    (section 3.1), whose fast cooling would otherwise fill the cooling set
    (docs/calibration.md). A log without the inner face's temperature keeps
    every program row. A program run ends at a row of another phase or a
    new mounting."""
    running = np.isin(phase, RUNNING_PHASES)
    if np.isfinite(chamber_c).any():
        with np.errstate(invalid="ignore"):
            reached = running & (np.abs(chamber_c - setpoint_c) <= REACHED_BAND_C)
    else:
        reached = running
    reached_so_far = np.cumsum(reached)
    starts = ~running
    starts[1:] |= mounting[1:] != mounting[:-1]
    if len(starts):
        starts[0] = True
    before_start = np.maximum.accumulate(np.where(starts, reached_so_far - reached, 0))
    kept = running & (reached_so_far > before_start)
    return kept, running & ~kept
