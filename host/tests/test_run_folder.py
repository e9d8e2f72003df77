"""The run folder (thermotilt.run): the columnar reader against the
row-by-row one it stands in for, the staircase rule against its loop form,
and what a folder or a log names."""

import io
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from thermotilt.program import REACHED_BAND_C
from thermotilt.run import positions
from thermotilt.run.folder import RunFolder, RunFolderError
from thermotilt.run.log import (
    COLUMNS,
    RunLogError,
    RunLogWriter,
    _columns_of_rows,
    format_numbers,
    read_run_columns,
    read_run_log,
)

numeric_cells = st.one_of(
    st.just(""),
    st.floats(allow_nan=False, allow_infinity=False, width=32).map(lambda value: f"{value:.3f}"),
    st.integers(-32768, 32767).map(str),
    st.sampled_from(["x", "1e", "--1", " 2"]),
)
text_cells = st.sampled_from(["", "W", "C", "H", "O", "D", "NONE"])


def write_log(path, rows):
    path.write_text(",".join(COLUMNS) + "\n" + "".join(",".join(row) + "\n" for row in rows))
    return str(path)


@st.composite
def log_rows(draw):
    rows = []
    for _ in range(draw(st.integers(0, 8))):
        rows.append(
            [
                draw(text_cells)
                if column in ("direction", "phase", "chamber_fault", "comp_set", "coef_source")
                else draw(numeric_cells)
                for column in COLUMNS
            ]
        )
    return rows


@settings(max_examples=30, deadline=None)
@given(rows=log_rows())
def test_the_columnar_reader_reads_what_the_row_reader_reads(tmp_path_factory, rows):
    path = write_log(tmp_path_factory.mktemp("log") / "run.csv", rows)
    columns = read_run_columns(path)
    reference = _columns_of_rows(path, read_run_log(path))
    assert columns.unreadable == reference.unreadable
    for column, values in reference.numbers.items():
        np.testing.assert_array_equal(columns.numbers[column], values, err_msg=column)
    for column, values in reference.texts.items():
        assert list(columns.texts[column]) == list(values), column


@settings(max_examples=30, deadline=None)
@given(rows=log_rows(), dropped=st.sets(st.sampled_from(COLUMNS), max_size=len(COLUMNS) - 1))
def test_writing_by_columns_writes_the_bytes_of_writing_by_rows(rows, dropped):
    kept = [column for column in COLUMNS if column not in dropped]
    by_rows, by_columns = io.StringIO(), io.StringIO()
    writer = RunLogWriter(by_rows, with_truth=False, flush_each_row=False)
    for row in rows:
        writer.write_row({column: cell for column, cell in zip(COLUMNS, row) if column in kept})
    columns = RunLogWriter(by_columns, with_truth=False, flush_each_row=False)
    columns.write_columns({column: [row[COLUMNS.index(column)] for row in rows] for column in kept})
    assert by_columns.getvalue() == by_rows.getvalue()
    assert columns.rows == writer.rows == len(rows)


@pytest.mark.parametrize("cells", [{}, {"time_s": ["1.0"], "chamber_c": ["2.0", "3.0"]}])
def test_writing_by_columns_needs_columns_of_one_length(cells):
    with pytest.raises(ValueError, match="one length"):
        RunLogWriter(io.StringIO(), with_truth=False, flush_each_row=False).write_columns(cells)


@given(st.lists(st.one_of(st.none(), st.floats(width=32)), max_size=20), st.integers(0, 4))
def test_numbers_are_written_with_fixed_decimals_unknown_empty_and_zero_unsigned(values, decimals):
    texts = format_numbers(values, decimals)
    for value, text in zip(values, texts, strict=True):
        if value is None or math.isnan(value):
            assert text == ""
        elif text.strip("-0.") == "":
            assert text == f"{0.0:.{decimals}f}"
        else:
            assert text == f"{value:.{decimals}f}"


def test_a_short_row_is_named_by_the_columnar_reader_too(tmp_path):
    rows = [["1"] * len(COLUMNS), ["2"] * (len(COLUMNS) - 1)]
    with pytest.raises(RunLogError, match=f"row 2 has {len(COLUMNS) - 1} cells, the header {len(COLUMNS)}"):
        read_run_columns(write_log(tmp_path / "run.csv", rows))


def staircase_by_rows(phase, chamber_c, setpoint_c, mounting):
    """The rule row by row: within a program run, rows from the first that
    reached its setpoint; a run ends at another phase or a new mounting."""
    knows_face = any(math.isfinite(value) for value in chamber_c)
    kept, stabilizing = [], []
    arrived, last_mounting = False, None
    for p, c, s, m in zip(phase, chamber_c, setpoint_c, mounting):
        if p not in ("W", "C") or m != last_mounting:
            arrived = False
        last_mounting = m
        running = p in ("W", "C")
        arrived = running and (arrived or not knows_face or abs(c - s) <= REACHED_BAND_C)
        kept.append(arrived)
        stabilizing.append(running and not arrived)
    return kept, stabilizing


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["", "I", "W", "C", "R", "D", "F"]),
            st.one_of(st.just(math.nan), st.floats(-12, 48)),
            st.floats(-10, 45),
            st.booleans(),
        ),
        max_size=40,
    ),
    st.booleans(),
)
def test_the_staircase_rule_is_its_row_by_row_form(rows, face_known):
    phase = np.array([row[0] for row in rows], dtype=str)
    chamber_c = np.array([row[1] if face_known else math.nan for row in rows], dtype=float)
    setpoint_c = np.array([row[2] for row in rows], dtype=float)
    mounting = np.cumsum([row[3] for row in rows]).astype(int)
    kept, stabilizing = positions.staircase(phase, chamber_c, setpoint_c, mounting)
    expected_kept, expected_stabilizing = staircase_by_rows(phase, chamber_c, setpoint_c, mounting)
    assert kept.tolist() == expected_kept and stabilizing.tolist() == expected_stabilizing


def test_settling_counts_from_the_move_the_log_states_or_else_the_mountings_first_row():
    time_s = np.array([10.0, 20.0, 130.0, 140.0, 150.0, 275.0])
    mounting = np.array([0, 0, 0, 1, 1, 1])
    stated = np.array([115.0, 125.0, 235.0, 0.0, 10.0, 135.0])
    assert positions.settled(time_s, mounting, stated, 120.0).tolist() == [False, True, True, False, False, True]
    unknown = np.full(len(time_s), np.nan)
    assert positions.settled(time_s, mounting, unknown, 120.0).tolist() == [False, False, True, False, False, True]


def test_a_move_starts_a_new_mounting():
    incl_x = np.array([0.0, 0.0, 15.0, 15.0, 15.0])
    since_move = np.array([1.0, 2.0, 0.5, 1.5, 0.2])
    assert positions.mountings(incl_x, np.zeros(5), since_move).tolist() == [0, 0, 1, 1, 2]


def test_a_run_is_a_folder_or_its_log(tmp_path):
    (tmp_path / "run.csv").write_text(",".join(COLUMNS) + "\n")
    (tmp_path / "x15.csv").write_text(",".join(COLUMNS) + "\n")
    assert RunFolder.of(tmp_path) == RunFolder.of(tmp_path / "run.csv") == RunFolder.at(tmp_path)
    lone = RunFolder.of(tmp_path / "x15.csv")
    assert (lone.path, lone.log, lone.name) == (tmp_path, tmp_path / "x15.csv", "x15")
    assert lone.summary() is None
    with pytest.raises(RunFolderError, match="no run log"):
        RunFolder.of(tmp_path / "missing")
