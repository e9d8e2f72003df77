"""Bad input on every CLI path gives one readable line on stderr and a
non-zero exit, never a traceback; a closed pipe, a full disk and Ctrl-C end
cleanly and keep what ran (docs/reliability.md, "Bad input (host CLI)").
Property tests check the parsers behind the CLI: frames, model files and run
logs give a result or their own error, never another exception."""

import csv
import fcntl
import json
import math
import os
import re
import signal
import subprocess
import sys
import termios
import time
import tomllib
from pathlib import Path

import pytest
from child_process import THERMOTILT, popen, run, thermotilt
from hypothesis import given, reject, settings
from hypothesis import strategies as st
from test_log import imu_frame, rows_of, wait_for, wait_until_opened

from thermotilt import cli
from thermotilt.physics import (
    CONSTANT_PARAMETERS,
    FAULT_NAMES,
    TERM_PARAMETERS,
    Bounds,
    Chamber,
    Model,
    ModelError,
    PerAxis,
    Sensor,
)
from thermotilt.run.log import ALL_COLUMNS, COLUMNS, RunLogError, read_run_log
from thermotilt.wire import coefficients as wire_coefficients
from thermotilt.wire.protocol import FRAMES, FrameReader, build_frame, format_value, parse_line

DEFAULT_TOML = Path(__file__).resolve().parents[1] / "thermotilt" / "models" / "default.toml"
PHYSICS_DOC = Path(__file__).resolve().parents[2] / "docs" / "physics-model.md"
PROPERTY = settings(max_examples=150, deadline=None)
SEED_RANGE = "must be from 0 to 18446744073709551615"
BOARD_SECONDS = "must be from 0.001 to 4294967.295 s"
AMBIENT = "must be from -40 to 85 degC"


def assert_one_line_error(result, code, message=""):
    assert "Traceback" not in result.stderr, result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("thermotilt: error: ") and message in lines[0], lines[0]
    assert result.returncode == code


def test_the_command_exits_with_mains_status_and_one_line():
    """Bad input is tested on cli.main in this process, but where only a
    process will do (a full disk or a closed pipe on stdout, a closed stdin,
    Ctrl-C); this test runs `python -m thermotilt` as a shell does: main's
    status is the exit code and the error is one line on stderr."""
    result = thermotilt("frames", "/nonexistent/capture.txt")
    assert_one_line_error(result, 1, "cannot read /nonexistent/capture.txt: No such file or directory")
    assert result.stdout == ""


# --- arguments --------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["simulate", "fig8", "--seed", "-1"], f"argument --seed: {SEED_RANGE}, got -1"),
        (["simulate", "fig8", "--seed", 2**70], f"argument --seed: {SEED_RANGE}, got {2**70}"),
        (["simulate", "fig8", "--seed", "x"], "argument --seed: invalid int value: 'x'"),
        (["simulate", "fig8", "--ambient", "nan"], f"argument --ambient: {AMBIENT}, got nan"),
        (["simulate", "fig8", "--ambient", "-300"], f"argument --ambient: {AMBIENT}, got -300"),
        (["simulate", "field-warming", "--duration", "nan"], f"argument --duration: {BOARD_SECONDS}, got nan"),
        (["simulate", "field-warming", "--duration", "inf"], f"argument --duration: {BOARD_SECONDS}, got inf"),
        (["simulate", "field-warming", "--duration", "-1"], f"argument --duration: {BOARD_SECONDS}, got -1"),
        (["simulate", "fig8", "--hold-seconds", "0"], "argument --hold-seconds: must be from 1 to 3600, got 0"),
        (["simulate", "cycle", "--rest-seconds", "-1"], "argument --rest-seconds: must be from 0 to 86400, got -1"),
        (["simulate", "cycle", "--incl-x", "91"], "argument --incl-x: must be from -90 to 90 deg, got 91"),
        (["log", "--port", "loop://", "--rows", "0"], "argument --rows: must be at least 1, got 0"),
        (["log", "--port", "loop://", "--duration", "-1"], f"argument --duration: {BOARD_SECONDS}, got -1"),
        (["log", "--port", "loop://", "--duration", "nan"], f"argument --duration: {BOARD_SECONDS}, got nan"),
        (["log", "--port", "loop://", "--ambient", "-300"], f"argument --ambient: {AMBIENT}, got -300"),
        (["log", "--port", "loop://", "--incl-y", "inf"], "argument --incl-y: must be from -90 to 90 deg, got inf"),
    ],
)
def test_bad_numbers_are_refused_before_anything_runs(cli_in_process, tmp_path, args, message):
    out = tmp_path / "out"
    result = cli_in_process(*args, "--out", out)
    assert_one_line_error(result, 2, message)
    assert result.stdout == "" and not out.exists()


def test_an_unknown_campaign_position_is_refused(cli_in_process, tmp_path):
    result = cli_in_process("simulate", "campaign", "--positions", "0,Z+5", "--out", tmp_path / "run")
    assert_one_line_error(result, 1, "unknown position(s) Z+5")


# --- model files ------------------------------------------------------------


def default_text():
    return DEFAULT_TOML.read_text(encoding="utf-8")


def with_parameter(text, section, name, value):
    head, header, body = text.partition(f"\n[{section}]\n")
    body, count = re.subn(rf"^{name} = .*$", f"{name} = {value}", body, count=1, flags=re.M)
    assert header and count == 1, (section, name)
    return head + header + body


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"\xff\xfe[chamber]\n", "not UTF-8 text (byte 0)"),
        (
            with_parameter(default_text(), "chamber", "inner_heat_capacity_j_per_k", "1e-300").encode(),
            "[chamber] inner_heat_capacity_j_per_k: must be >= 4 and <= 100000 J/K, got 1e-300",
        ),
        (
            with_parameter(default_text(), "temperature_offset", "offset_c", "9" * 400).encode(),
            "[temperature_offset] offset_c: must be >= -20 and <= 20 degC, got 9999",
        ),
        (b"chamber = " + b"[" * 5000, "not valid TOML: nested too deeply"),
        (b'"a\\nb" = 1\n', "unknown section [a\\nb]"),
    ],
)
def test_bad_model_files_are_refused_before_the_twin_starts(cli_in_process, tmp_path, content, message):
    model = tmp_path / "model.toml"
    model.write_bytes(content)
    result = cli_in_process("simulate", "fig8", "--model", model, "--out", tmp_path / "run")
    assert_one_line_error(result, 1, f"{model}: {message}")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("path", "message"),
    [
        ("{tmp}", "cannot read: Is a directory"),
        ("/dev/zero", "larger than 1048576 bytes, not a model file"),
    ],
)
def test_a_model_that_is_no_file_is_refused(cli_in_process, tmp_path, path, message):
    result = cli_in_process("simulate", "fig8", "--model", path.format(tmp=tmp_path), "--out", tmp_path / "run")
    assert_one_line_error(result, 1, message)


def bounded_parameters():
    for section, parameters in {**CONSTANT_PARAMETERS, **TERM_PARAMETERS}.items():
        for name, kind in parameters.items():
            if isinstance(kind, (Bounds, PerAxis)):
                yield pytest.param(section, name, kind, id=f"{section}.{name}")


def toml_number(number):
    return "nan" if math.isnan(number) else repr(number)


def model_with(tmp_path, section, name, kind, number):
    value = toml_number(number)
    if isinstance(kind, PerAxis):
        *first, last = kind.keys
        value = "{ " + "".join(f"{key} = 0.0, " for key in first) + f"{last} = {value} }}"
    path = tmp_path / "model.toml"
    path.write_text(with_parameter(default_text(), section, name, value), encoding="utf-8")
    return path


@pytest.mark.parametrize(("section", "name", "kind"), list(bounded_parameters()))
def test_every_parameter_is_held_to_its_range(tmp_path, section, name, kind):
    bounds, where = (kind.bounds, f"{name}.{kind.keys[-1]}") if isinstance(kind, PerAxis) else (kind, name)
    below = bounds.low if bounds.low_exclusive else bounds.low - max(1.0, abs(bounds.low))
    for number in (below, bounds.high + max(1.0, abs(bounds.high)), math.nan, math.inf):
        with pytest.raises(ModelError) as raised:
            Model.load(model_with(tmp_path, section, name, kind, number))
        assert f"[{section}] {where}: must be {bounds}, got " in str(raised.value)
    inside = [bounds.high] if bounds.low_exclusive else [bounds.low, bounds.high]
    for number in inside:
        Model.load(model_with(tmp_path, section, name, kind, float(number)))


def test_a_drift_surface_term_is_held_to_its_range(tmp_path):
    zero = "[0, 0, 0, 0, 0, 0]"
    surfaces = f"{{ X = [0, 0, 0, 0, 1.0, 0], Y = {zero}, Z = {zero} }}"
    text = default_text().replace('coefficients = "paper"', f"coefficients = {{ W = {surfaces}, C = {surfaces} }}")
    path = tmp_path / "model.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ModelError, match=r"\[drift\] coefficients\.W\.X p11: must be >= -0\.0235"):
        Model.load(path)


# The fastest chamber the ranges allow (docs/physics-model.md, "Parameter
# ranges"): the heatsink's 4 J/K between 10 W/K to the inner face and 50 W/K
# to the room, a time constant of 67 ms. The integrator splits a step at 5 %
# of the shortest time constant, 3.3 ms: a 10 ms step in 3.
FASTEST_CHAMBER_SUBSTEPS = 3


def test_the_extremes_of_the_ranges_take_a_few_substeps_a_step(tmp_path):
    """The fastest chamber the ranges allow: smallest heat capacities, largest
    conductances, the integrator still takes a few substeps per 10 ms and
    stays finite."""
    text = default_text()
    for section, name, value in [
        ("chamber", "inner_heat_capacity_j_per_k", 4.0),
        ("heatsink", "heat_capacity_j_per_k", 4.0),
        ("ambient_leak", "conductance_w_per_k", 10.0),
        ("heatsink", "inner_conductance_w_per_k", 10.0),
        ("heatsink", "ambient_conductance_w_per_k", 50.0),
        ("peltier_pumping", "full_duty_w", 500.0),
    ]:
        text = with_parameter(text, section, name, value)
    path = tmp_path / "fast.toml"
    path.write_text(text, encoding="utf-8")
    chamber = Chamber(Model.load(path), 22.0)
    assert chamber.substeps(0.01) == FASTEST_CHAMBER_SUBSTEPS
    for _ in range(1000):
        chamber.step(0.01, 1.0, -1, 22.0)
    assert math.isfinite(chamber.inner_c)


RANGE_CELL = re.compile(r"(?P<exclusive>> )?(?P<low>-?[\d.e]+) … (?P<high>[\d.e]+)|±(?P<half>[\d.]+)")


def documented_ranges():
    """(section, name) -> the range cell of docs/physics-model.md's table."""
    table = PHYSICS_DOC.read_text(encoding="utf-8").split("### Parameter ranges")[1]
    ranges = {}
    for line in table.split("\n## ")[0].splitlines():
        if line.startswith("| `["):
            names, cell = line.split("|")[1:3]
            for section, name in re.findall(r"`\[(\w+)\] (\w+)`", names):
                ranges[section, name] = cell.strip()
    return ranges


def test_the_documented_ranges_are_the_loaders():
    documented = documented_ranges()
    parameters = {**CONSTANT_PARAMETERS, **TERM_PARAMETERS}
    assert set(documented) == {(section, name) for section, names in parameters.items() for name in names}
    for (section, name), cell in documented.items():
        kind = parameters[section][name]
        bounds = kind.bounds if isinstance(kind, PerAxis) else kind
        if not isinstance(bounds, Bounds):
            continue
        match = RANGE_CELL.match(cell.replace("−", "-").replace("10⁷", "1e7"))
        if match["half"]:
            stated = Bounds(-float(match["half"]), float(match["half"]))
        else:
            stated = Bounds(float(match["low"]), float(match["high"]), low_exclusive=bool(match["exclusive"]))
        assert (stated.low, stated.high, stated.low_exclusive) == (bounds.low, bounds.high, bounds.low_exclusive), (
            section,
            name,
            cell,
        )


# --- outputs ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("out", "message"),
    [
        ("{tmp}/file", "cannot create folder {tmp}/file: File exists"),
        ("{tmp}/file/run", "cannot create folder {tmp}/file/run: Not a directory"),
        ("{tmp}/full", "cannot write {tmp}/full/run.csv: No space left on device"),
        ("{tmp}/rig.csv", "--out {tmp}/rig.csv: a run folder's log is run.csv; give the folder, e.g. --out {tmp}/rig"),
    ],
)
def test_log_outputs_that_cannot_be_written(cli_in_process, tmp_path, out, message):
    (tmp_path / "file").write_text("not a folder\n")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "run.csv").symlink_to("/dev/full")
    result = cli_in_process("log", "--port", "loop://", "--out", out.format(tmp=tmp_path), "--force")
    assert_one_line_error(result, 1, message.format(tmp=tmp_path))


def test_log_names_where_the_raw_bytes_went(cli_in_process, tmp_path):
    result = cli_in_process("log", "--port", "loop://", "--out", tmp_path / "run", "--raw-dir", tmp_path / "raw")
    assert_one_line_error(result, 1, "--raw-dir is gone: log keeps each port's bytes in the run folder's serial/")
    assert not (tmp_path / "run").exists() and not (tmp_path / "raw").exists()


def test_a_line_break_in_a_name_is_escaped(cli_in_process, tmp_path):
    result = cli_in_process("log", "--port", "no\nport", "--out", tmp_path / "run")
    assert_one_line_error(result, 1, "cannot open no\\nport: ")


def test_a_port_url_pyserial_cannot_parse(cli_in_process, tmp_path):
    result = cli_in_process("log", "--port", "loop://?bad", "--out", tmp_path / "run")
    assert_one_line_error(result, 1, "cannot open loop://?bad: ")


def test_a_simulation_folder_that_is_a_file(cli_in_process, tmp_path):
    out = tmp_path / "file"
    out.write_text("not a folder\n")
    result = cli_in_process("simulate", "fig8", "--out", out)
    assert_one_line_error(result, 1, f"cannot write {out}: Not a directory")


@pytest.mark.parametrize("args", [["coefficients"], ["--version"], ["--help"]])
def test_a_full_disk_on_stdout(args):
    with open("/dev/full", "w") as full:
        result = thermotilt(*args, stdout=full)
    assert_one_line_error(result, 1, "cannot write standard output: No space left on device")


def test_a_closed_pipe_on_stdout_ends_quietly():
    """`thermotilt coefficients | head -c 20` once head has gone: the standard
    recipe, exit 1 and nothing on stderr (nobody reads what follows)."""
    process = popen([*THERMOTILT, "coefficients"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    process.stdout.close()
    stderr = process.stderr.read()
    assert process.wait(timeout=60) == 1
    assert stderr == ""


# --- inputs -----------------------------------------------------------------


def test_inputs_that_cannot_be_read(cli_in_process, tmp_path):
    assert_one_line_error(cli_in_process("frames", tmp_path), 1, f"cannot read {tmp_path}: Is a directory")
    assert_one_line_error(cli_in_process("coefficients", "--block", "/dev/zero"), 1, "/dev/zero: coefficient block is")


def test_a_closed_standard_input():
    closed_stdin = run(
        ["sh", "-c", 'exec "$0" -m thermotilt frames - <&-', sys.executable], capture_output=True, text=True, timeout=60
    )
    assert_one_line_error(closed_stdin, 1, "standard input is closed")


# --- Ctrl-C -----------------------------------------------------------------


def test_children_take_ctrl_c_whatever_this_test_run_inherited():
    """A test run started with SIGINT ignored (`nohup make test &`) still
    starts each child with it at its default: Python there raises
    KeyboardInterrupt on Ctrl-C."""
    inherited = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        child = run(
            [sys.executable, "-c", "import signal; print(signal.getsignal(signal.SIGINT))"],
            capture_output=True,
            text=True,
            timeout=60,
        )
    finally:
        signal.signal(signal.SIGINT, inherited)
    assert child.stdout == f"{signal.default_int_handler}\n", child.stderr


def assert_interrupted(process):
    stdout, stderr = process.communicate(timeout=60)
    assert stderr == "thermotilt: interrupted\n"
    assert process.returncode == 130
    return stdout


def unread_bytes(pipe):
    return int.from_bytes(fcntl.ioctl(pipe, termios.FIONREAD, bytes(4)), sys.byteorder)


def test_ctrl_c_in_frames_prints_the_counts_so_far():
    read_end, write_end = os.pipe()
    process = popen(
        [*THERMOTILT, "frames", "-"], stdin=read_end, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        os.write(write_end, imu_frame(0, 1000).encode() + imu_frame(1, 1100).encode())
        # The frames command is reading once the pipe is empty again.
        wait_for(lambda: unread_bytes(read_end) == 0, "frames read its input")
        time.sleep(0.2)
        process.send_signal(signal.SIGINT)
        stdout = assert_interrupted(process)
    finally:
        os.close(read_end)
        os.close(write_end)
    assert stdout.splitlines()[:2] == ["frames: 2", "  IMU: 2"]


def test_ctrl_c_in_log_keeps_the_rows(tmp_path):
    master, slave = os.openpty()
    out = tmp_path / "run.csv"
    process = popen(
        [*THERMOTILT, "log", "--port", os.ttyname(slave), "--out", out],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        wait_until_opened(master)
        os.write(master, "".join(imu_frame(seq, 1000 + 100 * seq) for seq in range(3)).encode())
        wait_for(lambda: len(rows_of(out)) == 3, "the rows written")
        process.send_signal(signal.SIGINT)
        stdout = assert_interrupted(process)
    finally:
        os.close(master)
        os.close(slave)
    assert stdout.startswith("rows: 3 ") and stdout.rstrip().endswith("(interrupted)")
    assert len(read_run_log(str(out))) == 3


@pytest.mark.twin
def test_ctrl_c_in_simulate_keeps_the_run(tmp_path):
    out = tmp_path / "run"
    process = popen(
        [*THERMOTILT, "simulate", "fig8", "--out", out], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )

    def running():
        assert process.poll() is None, process.communicate()
        return (out / "run.csv").exists() and (out / "run.csv").stat().st_size > 0

    # The twin writes run.csv in blocks: the first one means it is running.
    wait_for(running, "the twin's first rows", timeout_s=60)
    process.send_signal(signal.SIGINT)
    stdout = assert_interrupted(process)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["rows"] > 0
    assert f"rows: {summary['rows']} " in stdout
    assert len(read_run_log(str(out / "run.csv"))) == summary["rows"]


def test_ctrl_c_anywhere_else_is_one_line(monkeypatch, capsys):
    def interrupted(table):
        raise KeyboardInterrupt

    monkeypatch.setattr(wire_coefficients, "setcoe_frames", interrupted)
    assert cli.main(["coefficients"]) == 130
    assert capsys.readouterr().err == "thermotilt: interrupted\n"


# --- properties of the parsers ---------------------------------------------


def text_field():
    printable = st.characters(min_codepoint=0x20, max_codepoint=0x7E, exclude_characters=",*$")
    return st.text(printable, max_size=8)


FIELD_VALUES = {
    "i": st.integers(-(2**31), 2**31 - 1),
    "f": st.floats(width=32),
    "t": text_field(),
}


@st.composite
def frames(draw):
    frame_type = draw(st.sampled_from(sorted(FRAMES)))
    values = [draw(FIELD_VALUES[spec.kind]) for spec in FRAMES[frame_type].fields]
    return frame_type, draw(st.integers(0, 65535)), values


def frame_line(frame):
    try:
        return build_frame(*frame)
    except ValueError:
        # Longer than a line may be, or a text the reader takes for a number.
        reject()


frame_like_bytes = st.lists(
    st.one_of(
        st.binary(max_size=12),
        frames().map(frame_line).map(str.encode),
        st.sampled_from([b"$", b"\r\n", b"\n", b"*", b",", b"\x00", b"\xff"]),
    ),
    max_size=25,
).map(b"".join)


@PROPERTY
@given(st.one_of(st.binary(max_size=400), frame_like_bytes), st.lists(st.integers(0, 400)))
def test_any_bytes_are_frames_or_counted_malformed_lines(data, cuts):
    whole = FrameReader()
    found = whole.feed(data) + whole.feed(b"\n")
    assert len(found) == whole.frames == sum(whole.frames_by_type.values())
    # Each '$' starts a line, and each line ends as a frame or a malformed count.
    assert whole.frames + whole.malformed == data.count(b"$")
    chunked = FrameReader()
    bounds = [0, *sorted(cuts), len(data)]
    pieces = [data[begin:end] for begin, end in zip(bounds, bounds[1:])]
    found_in_pieces = [frame for piece in pieces for frame in chunked.feed(piece)]
    found_in_pieces += chunked.feed(b"\n")
    assert [frame.line for frame in found_in_pieces] == [frame.line for frame in found]
    assert chunked.malformed_by_reason == whole.malformed_by_reason


@PROPERTY
@given(frames())
def test_build_frame_round_trips(frame):
    frame_type, seq, values = frame
    line = frame_line(frame)
    parsed = parse_line(line)
    assert (parsed.type, parsed.seq) == (frame_type, seq)
    assert parsed.raw_fields == tuple(format_value(value) for value in values)
    assert parsed.line + "\r\n" == line
    for spec, value in zip(FRAMES[frame_type].fields, values):
        expected = float(format_value(value)) if spec.kind == "f" else value
        got = parsed[spec.name]
        assert got == expected or (math.isnan(expected) and math.isnan(got))
    assert [read.line for read in FrameReader().feed(line.encode())] == [parsed.line]


def toml_value(value):
    """The TOML text of a value hypothesis drew; JSON's quoted strings and
    integers are TOML's too."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else repr(value)
    if isinstance(value, (int, str)):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(map(toml_value, value)) + "]"
    return "{" + ", ".join(f"{toml_value(key)} = {toml_value(item)}" for key, item in value.items()) + "}"


def toml_document(document):
    return "\n".join(f"{toml_value(key)} = {toml_value(value)}" for key, value in document.items())


toml_values = st.recursive(
    st.one_of(st.booleans(), st.integers(), st.floats(), st.text(max_size=12)),
    lambda children: st.one_of(
        st.lists(children, max_size=4), st.dictionaries(st.text(max_size=8), children, max_size=4)
    ),
    max_leaves=8,
)
faults = st.fixed_dictionaries(
    {"name": st.sampled_from([*FAULT_NAMES, "meteor"])},
    optional={key: st.one_of(st.floats(), st.integers()) for key in ("start_s", "end_s", "rate")},
)
DEFAULT_DOCUMENT = tomllib.loads(default_text())


def load_or_model_error(path, text):
    path.write_bytes(text if isinstance(text, bytes) else text.encode("utf-8"))
    try:
        return Model.load(path)
    except ModelError as error:
        assert "\n" not in str(error)
        return None


def test_the_document_writer_keeps_the_default_model(tmp_path):
    written = load_or_model_error(tmp_path / "model.toml", toml_document(DEFAULT_DOCUMENT))
    assert written is not None and written.terms == Model.load().terms


@PROPERTY
@given(st.one_of(st.binary(max_size=300), st.text(st.sampled_from('[]{}="., \n#-+_e019abnxyz'), max_size=200)))
def test_any_model_text_is_a_model_or_a_model_error(tmp_path_factory, text):
    load_or_model_error(tmp_path_factory.mktemp("model") / "model.toml", text)


@pytest.mark.slow
@PROPERTY
@given(st.data())
def test_any_model_document_is_a_usable_model_or_a_model_error(tmp_path_factory, data):
    document = json.loads(json.dumps(DEFAULT_DOCUMENT))
    for _ in range(data.draw(st.integers(1, 3))):
        section = data.draw(st.sampled_from([*sorted(document), "faults", "wind"]))
        table = document.get(section)
        change = data.draw(st.sampled_from(["parameter", "section", "drop", "fault"]))
        if change == "parameter" and isinstance(table, dict) and table:
            name = data.draw(st.sampled_from([*sorted(table), "extra"]))
            table[name] = data.draw(toml_values)
        elif change == "section":
            document[section] = data.draw(toml_values)
        elif change == "drop":
            document.pop(section, None)
        else:
            entries = document.get("faults")
            document["faults"] = [*(entries if isinstance(entries, list) else []), data.draw(faults)]
    model = load_or_model_error(tmp_path_factory.mktemp("model") / "model.toml", toml_document(document))
    if model is not None:
        chamber = Chamber(model, 22.0)
        chamber.step(0.01, 0.5, 1, 22.0)
        assert all(map(math.isfinite, chamber.thermistor_millivolts()))
        Sensor(model, 1, 22.0).step(0.01, 23.0, 30.0, -30.0)


def within(bounds):
    return st.floats(bounds.low, bounds.high, exclude_min=bounds.low_exclusive)


@PROPERTY
@given(st.data())
def test_any_values_within_the_ranges_make_a_model_that_steps(tmp_path_factory, data):
    document = json.loads(json.dumps(DEFAULT_DOCUMENT))
    for section, parameters in {**CONSTANT_PARAMETERS, **TERM_PARAMETERS}.items():
        for name, kind in parameters.items():
            if isinstance(kind, Bounds):
                document[section][name] = data.draw(within(kind), label=f"{section}.{name}")
            elif isinstance(kind, PerAxis):
                document[section][name] = {
                    key: data.draw(within(kind.bounds), label=f"{section}.{name}.{key}") for key in kind.keys
                }
    model = load_or_model_error(tmp_path_factory.mktemp("model") / "model.toml", toml_document(document))
    assert model is not None
    chamber, sensor = Chamber(model, 22.0), Sensor(model, 1, 22.0)
    assert chamber.substeps(0.01) <= FASTEST_CHAMBER_SUBSTEPS
    for direction in (1, -1):
        for _ in range(10):
            chamber.step(0.01, 1.0, direction, 22.0)
            sample = sensor.step(0.01, chamber.inner_c, 45.0, -45.0)
    assert all(map(math.isfinite, chamber.thermistor_millivolts()))
    assert all(-32768 <= value <= 32767 for value in (sample.ax, sample.ay, sample.az))


# Cells hold frame fields and numbers: no control characters (the csv module
# would not quote a lone CR).
csv_cells = st.text(st.characters(exclude_categories=("Cc", "Cs")), max_size=6)


@PROPERTY
@given(
    st.sampled_from([COLUMNS, ALL_COLUMNS]).flatmap(
        lambda header: st.tuples(
            st.just(header), st.lists(st.lists(csv_cells, min_size=len(header), max_size=len(header)), max_size=5)
        )
    )
)
def test_run_logs_read_back_as_written(tmp_path_factory, log):
    header, rows = log
    path = tmp_path_factory.mktemp("log") / "run.csv"
    with open(path, "w", newline="", encoding="utf-8") as stream:
        csv.writer(stream, lineterminator="\n").writerows([header, *rows])
    assert read_run_log(str(path)) == [dict(zip(header, row)) for row in rows]


@PROPERTY
@given(
    st.one_of(
        st.binary(max_size=300),
        st.lists(st.text(max_size=20), max_size=5).map(lambda lines: "\n".join([",".join(COLUMNS), *lines]).encode()),
    )
)
def test_any_bytes_are_a_run_log_or_a_run_log_error(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("log") / "run.csv"
    path.write_bytes(data)
    try:
        rows = read_run_log(str(path))
    except RunLogError as error:
        assert "\n" not in str(error)
    else:
        assert all(tuple(row) in (COLUMNS, ALL_COLUMNS) for row in rows)
