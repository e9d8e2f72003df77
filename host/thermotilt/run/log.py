"""The run log, ``run.csv``: one row per IMU output frame (docs/run-log.md).

The same schema comes from the twin (``thermotilt simulate``) and from real
boards (``thermotilt log``), so every later tool reads both; both write
their rows through ``thermotilt.wire.recorder``. Columns the source cannot
know stay empty: a real rig knows no ``true_*`` value, and the chamber
columns are empty when no chamber board is logged. Values that came from a
frame are written as the board sent them, so nothing is rounded twice.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import IO, Any

import numpy as np

COLUMNS: tuple[str, ...] = (
    "time_s",
    "ambient_c",
    "setpoint_c",
    "chamber_c",
    "outer_c",
    "pwm",
    "direction",
    "phase",
    "chamber_fault",
    "imu_temp_c",
    "incl_x_deg",
    "incl_y_deg",
    "since_move_s",
    "ax_raw",
    "ay_raw",
    "az_raw",
    "ax_filt",
    "ay_filt",
    "az_filt",
    "ax_comp",
    "ay_comp",
    "az_comp",
    "comp_set",
    "coef_source",
    "temp_domain",
    "imu_seq",
)

# Ground truth only a simulation has, sampled in the 10 ms step in which the
# IMU frame reached the host.
TRUE_COLUMNS: tuple[str, ...] = (
    "true_inner_c",
    "true_outer_c",
    "true_die_c",
    "true_reported_c",
    "true_rate_c_per_s",
    "true_drift_set",
    "true_warming_share",
    "true_ax",
    "true_ay",
    "true_az",
    "true_drift_x",
    "true_drift_y",
    "true_drift_z",
    "true_duty",
    "true_direction",
)

ALL_COLUMNS: tuple[str, ...] = COLUMNS + TRUE_COLUMNS

# Logs written before the IMU frame carried temp_domain read as they are,
# without that column.
_BEFORE_TEMP_DOMAIN = tuple(column for column in COLUMNS if column != "temp_domain")
# Twin logs written before the model's set state was logged, likewise.
_BEFORE_WARMING_SHARE = tuple(column for column in TRUE_COLUMNS if column != "true_warming_share")
HEADERS: tuple[tuple[str, ...], ...] = (
    COLUMNS,
    ALL_COLUMNS,
    COLUMNS + _BEFORE_WARMING_SHARE,
    _BEFORE_TEMP_DOMAIN,
    _BEFORE_TEMP_DOMAIN + TRUE_COLUMNS,
    _BEFORE_TEMP_DOMAIN + _BEFORE_WARMING_SHARE,
)


def format_numbers(values: Iterable[float | None], decimals: int) -> list[str]:
    """Fixed decimals, so the same run always writes the same bytes; NaN and
    None (unknown) are empty cells.

    A log's column is long, so its texts are built in numpy, from each number
    times 10**decimals rounded as Python's format rounds (_scaled_and_rounded).
    Values numpy does not read as plain numbers, and numbers it cannot round
    that way in float64 (infinite, or 2**50 and more once scaled), go through
    _format_each, one at a time, byte for byte as before."""
    values = values if isinstance(values, list | tuple | np.ndarray) else list(values)
    numbers = _as_floats(values) if len(values) >= 256 else None  # fewer are quicker one by one
    if numbers is None or type(decimals) is not int or not 0 <= decimals <= 10:
        return _format_each(values, decimals)
    unknown = np.isnan(numbers)
    if unknown.all():  # a column of unknowns
        return [""] * len(numbers)
    with np.errstate(invalid="ignore", over="ignore"):  # NaN (signalling too) and inf are _format_each's
        rest, fast = _scaled_and_rounded(abs(numbers), decimals)
        sign_due = (numbers < 0) & (rest > 0)  # no sign on a number rounded to zero
    whole_digits = len(str(int(rest.max()) // 10**decimals))
    # A line of characters a number, right-aligned: spaces, a sign slot, the
    # integer digits, the point and the fraction. A number left out of the
    # fast path (NaN, inf, too large) reads 0 here and is replaced below.
    width = 1 + whole_digits + (decimals + 1 if decimals else 0)
    chars = np.full((len(rest), width + 1), ord("."), np.uint8)
    chars[:, width] = ord("\n")
    for column in (column for column in range(width - 1, -1, -1) if column != whole_digits + 1):
        higher = rest // 10
        digit = rest - 10 * higher + ord("0")
        if column < whole_digits:  # left of the units digit
            blank = rest == 0
            digit = np.where(blank, np.where(sign_due, ord("-"), ord(" ")), digit)
            sign_due &= ~blank
        chars[:, column] = digit
        rest = higher
    texts = chars.tobytes().decode("ascii").split()
    for at in np.flatnonzero(unknown).tolist():
        texts[at] = ""
    slow = np.flatnonzero(~fast & ~unknown).tolist()
    for at, text in zip(slow, _format_each([values[at] for at in slow], decimals)):
        texts[at] = text
    return texts


def _scaled_and_rounded(magnitudes: Any, decimals: int) -> tuple[Any, Any]:
    """magnitudes (>= 0) times 10**decimals rounded to int64 as Python's
    format rounds: the exact product to nearest, half to even; and where that
    was done (finite, under 2**50 scaled). Rounding to float64 is monotone and
    a half-integer under 2**50 is a float64, so the float64 product is on the
    exact one's side of every .5 boundary, or on one; only there can np.rint
    round otherwise, and the product's rounding error, found exactly (Dekker's
    two-product: 10**decimals has at most 26 significant bits), decides."""
    scale = 10.0**decimals
    product = magnitudes * scale
    fast = product < 2.0**50
    product = np.where(fast, product, 0.0)
    rounded = np.rint(product)
    on_half = np.flatnonzero(abs(product - rounded) == 0.5)
    x, product = magnitudes[on_half], product[on_half]
    x_high = x * 134217729.0 - (x * 134217729.0 - x)
    error = (x - x_high) * scale - (product - x_high * scale)  # the exact product - product
    rounded[on_half] = np.rint(product + 0.5 * np.sign(error))
    return rounded.astype(np.int64), fast


def _as_floats(values: Sequence[Any]) -> Any:
    """values as a float64 array, None unknown (NaN); None when numpy does
    not read them as a list of plain numbers."""
    try:
        numbers = np.array(values)
        if numbers.dtype == object:
            numbers = np.array([math.nan if value is None else value for value in values])
    except (TypeError, ValueError, OverflowError):
        return None
    return numbers.astype(np.float64, copy=False) if numbers.ndim == 1 and numbers.dtype.kind in "biuf" else None


def _format_each(values: Iterable[Any], decimals: int) -> list[str]:
    pattern = f"{{:.{decimals}f}}".format
    texts = []
    for value in values:
        if value is None or math.isnan(value):
            texts.append("")
            continue
        text = pattern(value)
        # "-0.000" and "0.000" are the same number; write it one way.
        texts.append(text[1:] if text[0] == "-" and not text.strip("-0.") else text)
    return texts


def format_number(value: float | None, decimals: int) -> str:
    return _format_each((value,), decimals)[0]


class RunLogWriter:
    """Writes run.csv rows. Logging real boards flushes each row, so a crash
    or Ctrl-C loses nothing already received; the twin can rerun instead."""

    def __init__(self, stream: IO[str], with_truth: bool, flush_each_row: bool = True):
        self.columns = ALL_COLUMNS if with_truth else COLUMNS
        self._stream = stream
        self._flush_each_row = flush_each_row
        self._writer = csv.DictWriter(stream, fieldnames=self.columns, lineterminator="\n")
        self._writer.writeheader()
        if flush_each_row:
            self._stream.flush()
        self.rows = 0

    def write_row(self, cells: Mapping[str, str]) -> None:
        """One row of text cells by column; a column left out is empty."""
        self._writer.writerow(cells)
        if self._flush_each_row:
            self._stream.flush()
        self.rows += 1

    def write_columns(self, cells: Mapping[str, Sequence[str]]) -> None:
        """Rows from text cells by column, all of one length; a column left
        out is empty. At least one column: none would leave the count of
        rows unknown."""
        lengths = {len(values) for values in cells.values()}
        if len(lengths) != 1:
            raise ValueError(f"write_columns needs columns of one length, not {sorted(lengths) or 'none'}")
        (count,) = lengths
        empty = ("",) * count
        self._writer.writer.writerows(zip(*(cells.get(column, empty) for column in self.columns)))
        if self._flush_each_row:
            self._stream.flush()
        self.rows += count


class RunLogError(ValueError):
    """A file that is not a run.csv; one readable line."""


def read_run_log(path: str) -> list[dict[str, str]]:
    """Rows of a run.csv as text cells, checked: the header must be the
    twin's or the logger's (HEADERS) and every row must have all its cells.
    The package reads logs with read_run_columns, which falls back on this
    to name what is wrong with a file; tests compare cells as written."""
    try:
        with open(path, newline="", encoding="utf-8") as stream:
            records = [cells for cells in csv.reader(stream) if cells]
    except OSError as error:
        raise RunLogError(f"{path}: cannot read: {error.strerror or error}") from None
    except UnicodeDecodeError as error:
        raise RunLogError(f"{path}: not UTF-8 text (byte {error.start})") from None
    except csv.Error as error:
        raise RunLogError(f"{path}: not CSV: {error}") from None
    if not records or tuple(records[0]) not in HEADERS:
        raise RunLogError(f"{path}: the header is not run.csv's (docs/run-log.md)")
    header = records[0]
    for number, cells in enumerate(records[1:], start=1):
        if len(cells) != len(header):
            raise RunLogError(f"{path}: row {number} has {len(cells)} cells, the header {len(header)}")
    return [dict(zip(header, cells)) for cells in records[1:]]


TEXT_COLUMNS = frozenset(
    {"direction", "phase", "chamber_fault", "comp_set", "coef_source", "temp_domain", "true_drift_set"}
)


@dataclass(frozen=True)
class RunColumns:
    """A run.csv as columns: numbers as float arrays, empty or unreadable
    cells NaN and counted per column; text columns (``phase``,
    ``comp_set``, ...) as arrays of str, empty cells "" """

    path: str
    numbers: Mapping[str, Any]  # column -> numpy float array
    texts: Mapping[str, Any]  # column -> numpy array of str (dtype object)
    unreadable: Mapping[str, int]  # column -> cells that were not numbers

    @property
    def rows(self) -> int:
        return len(self.numbers["time_s"])

    def where(self, keep: Any) -> RunColumns:
        """The rows a boolean array keeps."""
        return RunColumns(
            self.path,
            {column: values[keep] for column, values in self.numbers.items()},
            {column: values[keep] for column, values in self.texts.items()},
            self.unreadable,
        )


def read_run_columns(path: str) -> RunColumns:
    """A run.csv as columns, with read_run_log's checks. pandas' C parser
    reads a well-formed log; a file it cannot take whole (a short row,
    quoting, bytes that are not UTF-8) goes through read_run_log, which
    names what is wrong and where."""
    import numpy as np
    import pandas as pd

    header = _header(path)
    numeric = [column for column in header if column not in TEXT_COLUMNS]
    try:
        with open(path, "rb") as stream:
            data = stream.read()
        frame = pd.read_csv(
            io.BytesIO(data),
            dtype={column: str for column in header if column in TEXT_COLUMNS},
            keep_default_na=False,
            na_values={column: [""] for column in numeric},
            encoding="utf-8",
            engine="c",
            on_bad_lines="error",
        )
        whole = data.count(b",") == (len(header) - 1) * (len(frame) + 1) and data.count(b'"') == 0
    except (OSError, ValueError, pd.errors.ParserError):
        whole = False
    if not whole or tuple(frame.columns) != header:
        return _columns_of_rows(path, read_run_log(path))
    numbers: dict[str, Any] = {}
    unreadable: dict[str, int] = {}
    for column in numeric:
        values = frame[column]
        if not pd.api.types.is_numeric_dtype(values):
            converted = pd.to_numeric(values, errors="coerce")
            unreadable[column] = int((converted.isna() & values.notna() & (values != "")).sum())
            values = converted
        else:
            unreadable[column] = 0
        numbers[column] = values.to_numpy(dtype=float, na_value=np.nan)
    texts = {column: frame[column].to_numpy(dtype=object) for column in header if column in TEXT_COLUMNS}
    return RunColumns(path, numbers, texts, unreadable)


def _header(path: str) -> tuple[str, ...]:
    """The log's header; RunLogError (from read_run_log, which says why)
    when it is not run.csv's."""
    try:
        with open(path, newline="", encoding="utf-8") as stream:
            first = tuple(next(csv.reader(stream), ()))
    except (OSError, UnicodeDecodeError, csv.Error):
        first = ()
    if first not in HEADERS:
        read_run_log(path)
    return first


def _columns_of_rows(path: str, rows: list[dict[str, str]]) -> RunColumns:
    """RunColumns of rows read_run_log checked; unreadable cells counted."""
    header = tuple(rows[0]) if rows else COLUMNS
    numbers: dict[str, Any] = {}
    texts: dict[str, Any] = {}
    unreadable: dict[str, int] = {}
    for column in header:
        cells = [row[column] for row in rows]
        if column in TEXT_COLUMNS:
            texts[column] = np.array(cells, dtype=object)
            continue
        values = np.full(len(cells), math.nan)
        bad = 0
        for index, cell in enumerate(cells):
            if cell:
                try:
                    values[index] = float(cell)
                except ValueError:
                    bad += 1
        numbers[column] = values
        unreadable[column] = bad
    return RunColumns(path, numbers, texts, unreadable)
