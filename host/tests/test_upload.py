"""`thermotilt upload`: a fit's surfaces into the IMU reader and back, against
the real imu_reader image in the twin: through `thermotilt simulate idle
--pty` ports as a user runs it, and on a twin Board directly (simulated
time) with the line or the board tampered with for the failures the
firmware cannot stage by itself. Also `simulate --eeprom` and the bad input
of both.

Expected values come from docs/protocol.md (answers, ERR codes, COE's five
significant digits, the 188-byte block) and from the fit written here.
"""

import json
import os
import struct
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import serial
from child_process import thermotilt as run
from firmware_helpers import of_type
from test_bad_input import assert_one_line_error
from twin_helpers import pty_twin

from thermotilt.calibration.fit import SurfaceFit, write_outputs
from thermotilt.calibration.upload import (
    UploadError,
    assign_sensor_id,
    printed_equal,
    read_fit_to_upload,
    read_table,
    upload_table,
)
from thermotilt.cli import main
from thermotilt.physics import Model
from thermotilt.run.log import read_run_log
from thermotilt.surfaces import AXES, COEFFICIENT_NAMES, SETS, Surface
from thermotilt.twin import simulate
from thermotilt.twin.boards import Board
from thermotilt.twin.scenarios import ScenarioOptions, build
from thermotilt.twin.simulate import SimulationError
from thermotilt.wire.client import CommandClient
from thermotilt.wire.coefficients import BLOCK_SIZE, decode_block, encode_block
from thermotilt.wire.protocol import build_frame, parse_line

# -1700 / -400 / 16000 LSB, raw temperature 32 -> 25.000 degC.
SENSOR = (-1700, -400, 16000, 32)
# A twin-campaign-like fit: near the paper's surfaces, with more digits than
# COE prints, so that the read-back check has rounding to see through.
FITTED = {
    ("W", "X"): Surface(560.123456, -19.0612345, 1.60123e-3, -0.1011234, -6.9012345e-5, 6.3e-9),
    ("C", "X"): Surface(575.25, -21.0987654, 7.5e-4, -7.9e-2, -6.3e-5, -7.3e-8),
    ("W", "Y"): Surface(350.5, -13.9, 5.7e-3, -2.9e-3, -1.9e-4, -5.3e-8),
    ("C", "Y"): Surface(330.75, -12.8, 4.4e-3, -3.3e-2, -1.6e-4, -1.4e-8),
}
BLANK = b"\xff" * BLOCK_SIZE


def write_fit(out_dir: Path, surfaces=FITTED, sensor_id: str = "") -> Path:
    """A FIT_DIR as `thermotilt fit` writes it (fit.write_outputs), its rows
    over -10..45 degC and +-16000 LSB."""
    fits = [
        SurfaceFit(
            s,
            a,
            1000,
            surface,
            tuple((v, v) for v in surface),
            tuple((v, v) for v in surface),
            10,
            np.zeros((6, 6)),
            1.0,
            0.9,
            0.9,
            1.0,
            (-10.0, 45.0),
            (-16000.0, 16000.0),
        )
        for (s, a), surface in surfaces.items()
    ]
    campaign = SimpleNamespace(positions=["0", "X+30", "X-30"], skipped_rows=0, stabilizing_rows=0)
    write_outputs(fits, campaign, out_dir, sensor_id)
    return out_dir


@pytest.fixture(scope="module")
def fit_dir(tmp_path_factory):
    return write_fit(tmp_path_factory.mktemp("fit"))


@pytest.fixture(scope="module")
def fit_07(tmp_path_factory):
    """The same fit, made for sensor NODE-07."""
    return write_fit(tmp_path_factory.mktemp("fit-07"), sensor_id="NODE-07")


def imu_board() -> Board:
    board = Board.imu_reader()
    board.attach_lsm9ds0()
    board.set_lsm9ds0(*SENSOR)
    return board


def surfaces_of(client: CommandClient) -> dict:
    read = {}
    for s in SETS:
        for a in AXES:
            (coe,) = of_type(client.command("GETCOE", [s, a]).data, "COE")
            read[(s, a)] = tuple(coe[term] for term in COEFFICIENT_NAMES)
    return read


def assert_printed_equal(read: dict, table) -> None:
    for key, printed in read.items():
        sent = table.surface(*key)
        assert all(printed_equal(want, got) for want, got in zip(sent, printed)), (key, sent, printed)


# ---- through the twin's pseudo-terminals, as a user runs it ---------------


def idle_twin(out: Path, *options):
    """`thermotilt simulate idle --pty` (its hour is far more than a test
    needs at ~20x real time): the two ports, then Ctrl-C."""
    return pty_twin(out, "idle", *options)


@pytest.mark.slow
@pytest.mark.twin
def test_upload_round_trip_through_the_twins_ports(fit_dir, tmp_path):
    table = read_table(fit_dir)
    absurd = write_fit(tmp_path / "absurd", {**FITTED, ("W", "X"): Surface(2e7, 0, 0, 0, 0, 0)})
    out = tmp_path / "twin"
    with idle_twin(out) as ports:
        imu = ports["imu_reader"]
        refused = run("upload", absurd, "--port", imu)
        assert_one_line_error(refused, 1, "SETCOE W X refused by")
        assert "BAD_ARG OUTPUT_TOO_LARGE; nothing saved" in refused.stderr
        assert_one_line_error(
            run("upload", fit_dir, "--port", ports["thermal_chamber"]), 1, "is the thermal_chamber, not the imu_reader"
        )
        in_ram = run("upload", fit_dir, "--port", imu, "--no-save")
        assert in_ram.returncode == 0, in_ram.stderr
        assert "in RAM only (coef_source U)" in in_ram.stdout
        saved = run("upload", fit_dir, "--port", imu)
        assert saved.returncode == 0, saved.stderr
        assert "after the reset (COMMANDED) the board runs them: coef_source E" in saved.stdout
        table_lines = [line for line in saved.stdout.splitlines() if line.startswith("  W ") or line.startswith("  C ")]
        assert len(table_lines) == 6 and all(line.split()[-2:] == ["equal", "equal"] for line in table_lines)
        # The board, asked by another client afterwards: the uploaded surfaces, from EEPROM.
        with serial.Serial(imu, 115200, timeout=0) as port:
            client = CommandClient(port, timeout_s=2.0)
            (config,) = of_type(client.command("STATUS").data, "ICF")
            read = surfaces_of(client)
    assert config["coef_source"] == "E"
    assert_printed_equal(read, table)
    # What the twin itself logged: defaults, then the RAM upload, then EEPROM;
    # one commanded reset, and no fault reported.
    sources = [row["coef_source"] for row in read_run_log(str(out / "run.csv"))]
    assert [s for i, s in enumerate(sources) if i == 0 or s != sources[i - 1]] == ["D", "U", "E"]
    captured = (out / "serial" / "imu_reader.txt").read_text()
    assert captured.count(",COMMANDED*") == 1 and ",RESET,WATCHDOG" not in captured


@pytest.mark.twin
def test_simulate_eeprom_starts_the_imu_with_the_fitted_block(fit_dir, tmp_path):
    with idle_twin(tmp_path / "twin", "--eeprom", fit_dir / "coefficients.bin") as ports:
        with serial.Serial(ports["imu_reader"], 115200, timeout=0) as port:
            frames = []
            client = CommandClient(port, timeout_s=2.0, on_frame=frames.append)
            (config,) = of_type(client.command("STATUS").data, "ICF")
            read = surfaces_of(client)
            client.wait_for(lambda frame: frame.type == "IMU", 5.0)
    assert config["coef_source"] == "E"
    assert_printed_equal(read, read_table(fit_dir))
    imu = of_type(frames, "IMU")
    assert imu and {frame["coef_source"] for frame in imu} == {"E"}
    assert not [e for e in of_type(frames, "ERR") if e["code"].startswith("EEPROM")]


ID_RECORD = slice(512, 523)


@pytest.mark.slow
@pytest.mark.twin
def test_upload_refuses_a_fit_for_another_sensor_through_the_twins_ports(fit_07, fit_dir, tmp_path):
    out = tmp_path / "twin"
    with idle_twin(out) as ports:
        imu = ports["imu_reader"]
        unassigned = run("upload", fit_07, "--port", imu)
        assert_one_line_error(unassigned, 1, f"{fit_07} was fitted for sensor NODE-07, {imu} has no sensor ID")
        assert f"`thermotilt assign-id NODE-07 --port {imu}`" in unassigned.stderr
        assigned = run("assign-id", "NODE-08", "--port", imu)
        assert assigned.returncode == 0, assigned.stderr
        assert f"{imu} is now sensor NODE-08" in assigned.stdout
        other = run("upload", fit_07, "--port", imu)
        assert_one_line_error(
            other, 1, f"{fit_07} was fitted for sensor NODE-07, {imu} is sensor NODE-08; nothing written"
        )
        nameless = run("upload", fit_dir, "--port", imu)
        assert_one_line_error(nameless, 1, f"{fit_dir} was fitted for no particular sensor, {imu} is sensor NODE-08")
        assert "--sensor-id NODE-08" in nameless.stderr
        kept = run("assign-id", "NODE-07", "--port", imu)
        assert_one_line_error(kept, 1, f"{imu} is already sensor NODE-08; add --replace")
        with serial.Serial(imu, 115200, timeout=0) as port:
            (config,) = of_type(CommandClient(port, timeout_s=2.0).command("STATUS").data, "ICF")
    assert (config["sensor_id"], config["coef_source"]) == ("NODE-08", "D")
    # The EEPROM the twin kept: the ID record, and no coefficient block.
    eeprom = (out / "imu_reader_eeprom.bin").read_bytes()
    assert eeprom[:BLOCK_SIZE] == BLANK and eeprom[ID_RECORD].startswith(b"INODE-08\0")
    assert [row["coef_source"] for row in read_run_log(str(out / "run.csv"))][-1] == "D"


@pytest.mark.slow
@pytest.mark.twin
def test_upload_of_a_fit_for_the_boards_sensor_through_the_twins_ports(fit_07, tmp_path):
    out = tmp_path / "twin"
    with idle_twin(out) as ports:
        imu = ports["imu_reader"]
        assigned = run("assign-id", "NODE-07", "--port", imu)
        assert assigned.returncode == 0, assigned.stderr
        assert "is now sensor NODE-07; it has no saved coefficients (coef_source D)" in assigned.stdout
        saved = run("upload", fit_07, "--port", imu)
        assert saved.returncode == 0, saved.stderr
        assert f"on {imu} (sensor NODE-07)" in saved.stdout
        assert "calibrated domain W: T -10..45 degC, X -16000..16000 LSB" in saved.stdout
        assert "after the reset (COMMANDED) the board runs them: coef_source E" in saved.stdout
        again = run("assign-id", "NODE-07", "--port", imu)
        assert "already sensor NODE-07; nothing written (coef_source E)" in again.stdout
        # Another ID: the block is kept but no longer loads; the ID it was fitted for loads it again.
        replaced = run("assign-id", "NODE-09", "--port", imu, "--replace")
        assert replaced.returncode == 0, replaced.stderr
        assert "now sensor NODE-09 (was NODE-07); its saved coefficients were fitted for another sensor" in (
            replaced.stdout
        )
        restored = run("assign-id", "NODE-07", "--port", imu, "--replace")
        assert "its saved coefficients load for this ID (coef_source E)" in restored.stdout
    stored = decode_block((out / "imu_reader_eeprom.bin").read_bytes()[:BLOCK_SIZE])
    fit = read_fit_to_upload(fit_07)
    assert (stored.sensor_id, stored.domain) == ("NODE-07", fit.domain)
    sources = [row["coef_source"] for row in read_run_log(str(out / "run.csv"))]
    assert [s for i, s in enumerate(sources) if i == 0 or s != sources[i - 1]] == ["D", "U", "E", "D", "E"]


# ---- on a twin Board: exact, and the failures ----------------------------


@pytest.mark.twin
@pytest.mark.parametrize(
    "board_id, fitted_for, message",
    [
        ("NODE-08", "NODE-07", "the fit was fitted for sensor NODE-07, the board is sensor NODE-08; nothing written"),
        ("", "NODE-07", "the board has no sensor ID: if it carries sensor NODE-07, assign it with"),
        ("NODE-08", "", "was fitted for no particular sensor, the board is sensor NODE-08"),
    ],
)
def test_a_fit_for_another_sensor_is_refused_before_anything_is_written(fit_dir, board_id, fitted_for, message):
    fit = read_fit_to_upload(fit_dir)
    with imu_board() as board:
        if board_id:
            assign_sensor_id(board, board_id)
        eeprom = board.read_eeprom()
        line = TamperedLine(board)
        with pytest.raises(UploadError) as error:
            upload_table(line, replace(fit, sensor_id=fitted_for))
        assert board.read_eeprom() == eeprom
    text = str(error.value)
    assert message in text and "\n" not in text
    assert line.commands == ["VERSION", "STATUS"]


@pytest.mark.twin
def test_a_fit_for_the_boards_sensor_is_saved_with_its_id_and_domain(fit_07):
    fit = read_fit_to_upload(fit_07)
    assert fit.sensor_id == "NODE-07" and fit.domain["C"].temperature_c == (-10.0, 45.0)
    with imu_board() as board:
        assign_sensor_id(board, "NODE-07")
        result = upload_table(board, fit)
        stored = decode_block(board.read_eeprom(0, BLOCK_SIZE))
    assert (result.sensor_id, result.coef_source) == ("NODE-07", "E")
    assert (stored.sensor_id, stored.domain) == ("NODE-07", fit.domain)


def ulps_apart(a: float, b: float) -> int:
    """Distance of two float32 in units in the last place (same sign)."""
    bits_a, bits_b = (struct.unpack("<i", struct.pack("<f", value))[0] for value in (a, b))
    return abs(bits_a - bits_b)


@pytest.mark.twin
def test_the_saved_block_holds_the_uploaded_float32_to_one_unit_in_the_last_place(fit_dir):
    table = read_table(fit_dir)
    with imu_board() as board:
        result = upload_table(board, table)
        stored = decode_block(board.read_eeprom(0, BLOCK_SIZE))
    # SETCOE's nine digits carry each float32 exactly, but avr-libc's strtod
    # is not correctly rounded: some values land one ulp away.
    distances = [ulps_apart(sent, kept) for sent, kept in zip(table.values(), stored.table.values(), strict=True)]
    assert max(distances) == 1 and sum(d > 0 for d in distances) < len(distances) / 2
    assert (result.saved, result.reset_cause, result.coef_source) == (True, "COMMANDED", "E")
    assert result.imu_frames_checked > 0
    assert result.read_back.surfaces.keys() == result.after_reset.surfaces.keys() == table.surfaces.keys()


@pytest.mark.twin
def test_no_save_leaves_the_eeprom_as_it_was(fit_dir):
    with imu_board() as board:
        result = upload_table(board, read_table(fit_dir), save=False)
        assert board.read_eeprom(0, BLOCK_SIZE) == BLANK
    assert (result.saved, result.coef_source, result.after_reset) == (False, "U", None)


class TamperedLine:
    """A twin Board behind a line a test can tamper with: on_command(line,
    command) forwards a command by returning True; rewrite(frame) returns
    the text of a frame the board sent, changed or not."""

    def __init__(self, board: Board, on_command=None, rewrite=None):
        self.board = board
        self.commands: list[str] = []
        self._on_command = on_command
        self._rewrite = rewrite
        self._partial = b""
        self._injected = b""

    def write_uart(self, data: bytes) -> None:
        command = parse_line(data.decode("ascii"))
        self.commands.append(command.type)
        if self._on_command is None or self._on_command(self, command):
            self.board.write_uart(data)

    def inject(self, frame_type: str, values) -> None:
        self._injected += build_frame(frame_type, 999, values).encode()

    def read_uart(self) -> bytes:
        data = self._partial + self.board.read_uart()
        complete, end, self._partial = data.rpartition(b"\n")
        lines = (complete + end).splitlines(keepends=True)
        if self._rewrite is not None:
            lines = [
                self._rewrite(parse_line(line.decode("ascii"))).encode() if line.startswith(b"$") else line
                for line in lines
            ]
        injected, self._injected = self._injected, b""
        return b"".join(lines) + injected

    def __getattr__(self, name):
        return getattr(self.board, name)


def changed(frame, **fields) -> str:
    values = [fields.get(name, value) for name, value in frame.fields.items()]
    return build_frame(frame.type, frame.seq, values)


def rewrite_coe_cy(frame):
    if frame.type == "COE" and (frame["set"], frame["axis"]) == ("C", "Y"):
        return changed(frame, p10=frame["p10"] * 1.001)
    return frame.line + "\r\n"


def rewrite_protocol(frame):
    return changed(frame, protocol_version=1) if frame.type == "VER" else frame.line + "\r\n"


def rewrite_imu_source(frame):
    return changed(frame, coef_source="D") if frame.type == "IMU" else frame.line + "\r\n"


def on_reset(action):
    def on_command(line, command):
        if command.type != "RESET":
            return True
        return action(line, command)

    return on_command


def damage_eeprom(line, command):
    byte = line.board.read_eeprom(77, 1)[0]
    line.board.write_eeprom(bytes([byte ^ 0x04]), offset=77)
    return True


def acknowledge_without_reset(line, command):
    line.inject("ACK", [command.seq, "RESET"])
    return False


def hang_instead(line, command):
    line.inject("ACK", [command.seq, "RESET"])
    line.board.hang()
    return False


def lose_the_sensor(line, command):
    line.board.set_lsm9ds0_fault("absent")
    return True


FAILURES = {
    # name: (on_command, rewrite, message, saved)
    "read back differs": (
        None,
        rewrite_coe_cy,
        "GETCOE C Y read back p10 = -1.2813e+01, sent -12.8000002; nothing saved",
        False,
    ),
    "another protocol": (None, rewrite_protocol, "speaks protocol 1, this host 2", False),
    "EEPROM damaged before the reset": (
        on_reset(damage_eeprom),
        None,
        "after the reset the board runs coef_source D, not E (it reported EEPROM_CRC DEFAULTS)",
        True,
    ),
    "no restart": (on_reset(acknowledge_without_reset), None, "the board did not come back within 3 s of RESET", True),
    "a hang, not a commanded reset": (
        on_reset(hang_instead),
        None,
        "after RESET the board reported reset_cause WATCHDOG, not COMMANDED (it reported RESET WATCHDOG)",
        True,
    ),
    "IMU frames say D": (
        None,
        rewrite_imu_source,
        "after the reset the board sent IMU frames with coef_source D, not E",
        True,
    ),
    "no IMU frame after the reset": (
        on_reset(lose_the_sensor),
        None,
        "no IMU frame from the board within 3 s after the reset (it reported SENSOR_MISSING NO_ANSWER",
        True,
    ),
}


@pytest.mark.twin
@pytest.mark.parametrize("failure", FAILURES)
def test_each_failure_stops_with_one_line_and_saves_only_after_every_check(fit_dir, failure):
    on_command, rewrite, message, saved = FAILURES[failure]
    table = read_table(fit_dir)
    with imu_board() as board:
        line = TamperedLine(board, on_command, rewrite)
        with pytest.raises(UploadError) as error:
            upload_table(line, table)
        stored = board.read_eeprom(0, BLOCK_SIZE)
    text = str(error.value)
    assert message in text and "\n" not in text
    assert ("SAVECOE" in line.commands) == saved
    if not saved:
        assert stored == BLANK


@pytest.mark.twin
def test_a_surface_the_board_refuses_stops_before_anything_is_saved(fit_dir):
    table = read_table(write_fit(fit_dir.parent / "refused-cz", {**FITTED, ("C", "Z"): Surface(2e7, 0, 0, 0, 0, 0)}))
    with imu_board() as board:
        line = TamperedLine(board)
        with pytest.raises(
            UploadError, match="SETCOE C Z refused by the board: BAD_ARG OUTPUT_TOO_LARGE; nothing saved"
        ):
            upload_table(line, table)
        assert board.read_eeprom(0, BLOCK_SIZE) == BLANK
    assert line.commands.count("SETCOE") == 6 and "SAVECOE" not in line.commands


@pytest.mark.twin
def test_the_chamber_is_not_uploaded_to(fit_dir):
    with Board.thermal_chamber() as board:
        with pytest.raises(UploadError, match="the board is the thermal_chamber, not the imu_reader"):
            upload_table(board, read_table(fit_dir))


# ---- the comparison and the table -----------------------------------------


def test_printed_equal_is_half_a_unit_of_the_fifth_significant_digit():
    assert printed_equal(571.5, float(f"{571.5:.4e}"))
    assert printed_equal(-6.936e-5, -6.9360e-05)
    assert printed_equal(999.996, 1.0000e3)  # rounds up to the next power of ten
    assert printed_equal(1.03125, 1.0313) and printed_equal(1.03125, 1.0312)  # a tie either way
    assert not printed_equal(1.03125, 1.0314)
    assert not printed_equal(-20.23, -2.0240e01)
    assert printed_equal(0.0, 0.0) and printed_equal(-0.0, 0.0) and not printed_equal(0.0, 1e-30)


def test_read_table_fills_the_surfaces_a_fit_did_not_make_with_zero(tmp_path):
    table = read_table(write_fit(tmp_path / "x-only", {key: value for key, value in FITTED.items() if key[1] == "X"}))
    for s in SETS:
        assert table.surface(s, "Y") == table.surface(s, "Z") == Surface(0, 0, 0, 0, 0, 0)
        assert table.surface(s, "X") == pytest.approx(FITTED[(s, "X")], rel=1e-7)
    # float32, as the firmware holds them.
    assert table == table.to_float32() and table.surface("W", "X").p00 != FITTED[("W", "X")].p00


# ---- bad input: one line, exit 1 ------------------------------------------


def assert_one_line(capsys, status: int, message: str) -> None:
    """What cli.main printed for a command that failed (in-process; the
    uploads through the twin's ports above run the real command)."""
    err = capsys.readouterr().err
    assert status == 1 and err.count("\n") == 1, err
    assert err.startswith("thermotilt: error: ") and message in err, err


def corrupt_json(directory: Path, text: str) -> Path:
    directory.mkdir()
    (directory / "coefficients.json").write_text(text)
    return directory


def edited_fit(directory: Path, edit) -> Path:
    """A fit's coefficients.json with edit(document) applied, as a hand or another tool might."""
    path = write_fit(directory) / "coefficients.json"
    document = json.loads(path.read_text())
    edit(document)
    path.write_text(json.dumps(document))
    return directory


def rename_wx_to_qx(document) -> None:
    document["fits"]["QX"] = document["fits"].pop("WX")


def set_wx_p00_beyond_float32(document) -> None:
    document["fits"]["WX"]["coefficients"]["p00"]["value"] = 1e39


def set_cy_p02_nan(document) -> None:
    document["fits"]["CY"]["coefficients"]["p02"]["value"] = float("nan")


def set_sensor_id_with_a_space(document) -> None:
    document["sensor_id"] = "NODE 7"


def set_domain_beyond_int16(document) -> None:
    document["calibrated_domain"]["W"]["temperature_c"] = [-10.0, 400.0]


def drop_domain_axis(document) -> None:
    del document["calibrated_domain"]["C"]["acceleration_lsb"]["Y"]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda tmp: tmp / "missing", "missing/coefficients.json: cannot read"),
        (lambda tmp: corrupt_json(tmp / "garbage", "{not json"), "not a coefficients.json written by thermotilt fit"),
        (lambda tmp: corrupt_json(tmp / "empty", '{"fits": {}}'), "no fitted surface to upload"),
        (lambda tmp: edited_fit(tmp / "unknown", rename_wx_to_qx), "unknown surface 'QX'"),
        (
            lambda tmp: edited_fit(tmp / "huge", set_wx_p00_beyond_float32),
            "WX p00 = 1e+39, which the firmware's float32 cannot hold",
        ),
        (lambda tmp: edited_fit(tmp / "nan", set_cy_p02_nan), "CY p02 = nan"),
        (
            lambda tmp: edited_fit(tmp / "id", set_sensor_id_with_a_space),
            "sensor ID 'NODE 7' may hold only letters, digits",
        ),
        (
            lambda tmp: edited_fit(tmp / "domain", set_domain_beyond_int16),
            "calibrated_domain W temperature_c [-10.0, 400.0] is not a range the board can hold",
        ),
        (
            lambda tmp: edited_fit(tmp / "axis", drop_domain_axis),
            "calibrated_domain is not the one thermotilt fit writes",
        ),
    ],
    ids=["missing", "not-json", "no-fits", "unknown-surface", "beyond-float32", "nan", "id", "domain", "axis"],
)
def test_a_bad_fit_dir_is_one_line(tmp_path, capsys, make, message):
    # The fit is read before the port is opened: this port does not exist.
    assert_one_line(capsys, main(["upload", str(make(tmp_path)), "--port", str(tmp_path / "no-port")]), message)


@pytest.mark.parametrize(
    ("sensor_id", "message"),
    [("NODE 7", "may hold only letters, digits"), ("NODE-0007", "at most 8"), ("", "cannot be empty")],
)
def test_assign_id_refuses_what_is_no_sensor_id_before_opening_the_port(cli_in_process, tmp_path, sensor_id, message):
    assert_one_line_error(cli_in_process("assign-id", sensor_id, "--port", tmp_path / "no-port"), 2, message)


@pytest.mark.slow
def test_a_missing_port_and_a_silent_board_are_one_line(cli_in_process, fit_dir, tmp_path):
    assert_one_line_error(cli_in_process("upload", fit_dir, "--port", tmp_path / "ttyUSB9"), 1, "cannot open")
    master, slave = os.openpty()
    try:
        silent = cli_in_process("upload", fit_dir, "--port", os.ttyname(slave))
    finally:
        os.close(slave)
        os.close(master)
    assert_one_line_error(silent, 1, "is silent: no answer to VERSION")


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (None, "cannot read"),
        (b"\x54\x01" * 5, "10 bytes; --eeprom takes the 188-byte coefficient block"),
        (b"\xff" * 200, "200 bytes; --eeprom takes"),
        (b"\xff" * 1025, "more than 1024 bytes"),
    ],
    ids=["missing", "short", "between", "long"],
)
def test_simulate_eeprom_of_the_wrong_size_is_one_line(tmp_path, capsys, content, message):
    block = tmp_path / "block.bin"
    if content is not None:
        block.write_bytes(content)
    status = main(["simulate", "idle", "--duration", "1", "--eeprom", str(block), "--out", str(tmp_path / "run")])
    assert_one_line(capsys, status, message)
    assert not (tmp_path / "run").exists()


@pytest.mark.twin
def test_a_block_the_firmware_refuses_runs_on_the_defaults(tmp_path):
    damaged = bytearray(encode_block(read_table(write_fit(tmp_path / "fit"))))
    damaged[77] ^= 0x04
    (tmp_path / "damaged.bin").write_bytes(damaged)
    result = run("simulate", "idle", "--duration", "2", "--eeprom", tmp_path / "damaged.bin", "--out", tmp_path / "run")
    assert result.returncode == 0, result.stderr
    assert "imu_reader reported EEPROM_CRC DEFAULTS" in result.stdout
    assert {row["coef_source"] for row in read_run_log(str(tmp_path / "run" / "run.csv"))} == {"D"}


@pytest.mark.twin
def test_run_refuses_an_eeprom_image_larger_than_the_imus(tmp_path):
    scenario = build("idle", ScenarioOptions(duration_s=0.1))
    with pytest.raises(SimulationError, match="2000 bytes do not fit the IMU's EEPROM of 1024 bytes"):
        simulate.run(scenario, Model.load(), tmp_path, eeprom=b"\xff" * 2000)


def test_the_idle_scenario_powers_both_boards_and_sends_nothing():
    scenario = build("idle", ScenarioOptions(incl_x_deg=30.0, ambient_c=18.0))
    assert (scenario.duration_s, scenario.uses_chamber, scenario.commands) == (3600.0, True, ())
    assert [(p.label, p.incl_x_deg, p.incl_y_deg) for p in scenario.positions] == [("X+30", 30.0, 0.0)]
    assert {scenario.ambient_c(t) for t in (0.0, 1800.0, 3600.0)} == {18.0}
    assert build("idle", ScenarioOptions(duration_s=60.0)).duration_s == 60.0


@pytest.mark.slow
@pytest.mark.twin
def test_a_runs_saved_eeprom_starts_the_next_run(fit_dir, tmp_path):
    """What the IMU saved in one run (imu_reader_eeprom.bin) is what it
    starts with in the next, as a real board keeps its EEPROM."""
    first, second = tmp_path / "first", tmp_path / "second"
    assert (
        run("simulate", "idle", "--duration", "2", "--eeprom", fit_dir / "coefficients.bin", "--out", first).returncode
        == 0
    )
    saved = (first / "imu_reader_eeprom.bin").read_bytes()
    assert len(saved) == 1024 and saved[:BLOCK_SIZE] == (fit_dir / "coefficients.bin").read_bytes()
    assert (
        run(
            "simulate", "idle", "--duration", "2", "--eeprom", first / "imu_reader_eeprom.bin", "--out", second
        ).returncode
        == 0
    )
    assert {row["coef_source"] for row in read_run_log(str(second / "run.csv"))} == {"E"}
    assert (second / "imu_reader_eeprom.bin").read_bytes() == saved
