"""summary.json: one versioned schema every producer writes, read through
read_summary / RunFolder.summary (docs/run-log.md); and the recorder's one
rule for when a chamber program is over."""

import json

import pytest

from thermotilt.run.folder import RunFolder
from thermotilt.run.summary import (
    SCHEMA,
    BoardReport,
    RunSummary,
    RunSummaryError,
    read_summary,
)
from thermotilt.wire.protocol import build_frame, parse_line
from thermotilt.wire.recorder import ProgramEnd


def twin_summary(**changes):
    values = dict(
        source="twin",
        rows=12,
        end_reason="program done",
        wall_seconds=1.5,
        boards={
            "imu_reader": BoardReport(
                frames=13,
                frames_by_type={"IMU": 12, "VER": 1},
                rejected=0,
                rejected_by_reason={},
                sequence_gaps=0,
                reported_errors=["RESET WATCHDOG at 30.51 s"],
                firmware="imu_reader 0.2.0 protocol 2",
                cycles=16000000,
            )
        },
        scenario="cycle",
        options={"hold_s": 1, "positions": None},
        seed=5,
        model="default",
        terms={"heatsink": True},
        faults=[{"name": "imu_hang", "start_s": 30.0, "end_s": None, "rate": None}],
        imu_eeprom_preloaded_bytes=0,
        realtime=False,
        sim_seconds=62.5,
        speed_x_real_time=41.67,
        positions=[{"at_s": 0.0, "label": "0", "incl_x_deg": 0.0, "incl_y_deg": 0.0}],
    )
    return RunSummary(**(values | changes))


def write_document(folder, document):
    folder.mkdir(exist_ok=True)
    (folder / "summary.json").write_text(json.dumps(document))
    return folder


def test_a_summary_reads_back_as_written(tmp_path):
    summary = twin_summary()
    summary.write(tmp_path)
    document = json.loads((tmp_path / "summary.json").read_text())
    assert list(document)[:1] == ["schema"] and document["schema"] == SCHEMA
    assert document["interrupted"] is False
    assert document["boards"]["imu_reader"]["reported_errors"] == ["RESET WATCHDOG at 30.51 s"]
    assert read_summary(tmp_path) == summary


def test_interrupted_is_the_end_reason(tmp_path):
    twin_summary(end_reason="interrupted").write(tmp_path)
    assert json.loads((tmp_path / "summary.json").read_text())["interrupted"] is True
    assert read_summary(tmp_path).interrupted is True


@pytest.mark.parametrize(
    "document, message",
    [
        (
            {"schema": SCHEMA + 1, "rows": 3},
            f"summary schema {SCHEMA + 1} is newer than this thermotilt reads ({SCHEMA})",
        ),
        ({"schema": "one"}, "unknown summary schema 'one'"),
        ({"schema": SCHEMA, "source": "twin"}, "missing key 'boards'"),
        (
            {"schema": SCHEMA, "source": "bench", "rows": 1, "end_reason": "x", "wall_seconds": 1, "boards": {}},
            "source 'bench' is neither 'twin' nor 'boards'",
        ),
        (
            {"schema": SCHEMA, "source": "twin", "rows": "many", "end_reason": "x", "wall_seconds": 1, "boards": {}},
            "rows is 'many', not a number",
        ),
        (
            {
                "schema": SCHEMA,
                "source": "twin",
                "rows": 1,
                "end_reason": "x",
                "wall_seconds": 1,
                "boards": {},
                "colour": "red",
            },
            "unknown key 'colour'",
        ),
        (
            {
                "schema": SCHEMA,
                "source": "twin",
                "rows": 1,
                "end_reason": "x",
                "wall_seconds": 1,
                "boards": {"imu_reader": {"volts": 5}},
            },
            "board imu_reader: unknown key 'volts'",
        ),
        ({"rows": 3}, "not a run summary"),
        ([1, 2], "not a run summary (a JSON object)"),
    ],
)
def test_a_summary_this_version_cannot_read_is_one_line(tmp_path, document, message):
    write_document(tmp_path, document)
    with pytest.raises(RunSummaryError) as raised:
        read_summary(tmp_path)
    text = str(raised.value)
    assert text.startswith(f"{tmp_path / 'summary.json'}: ") and message in text and "\n" not in text


def test_no_summary_and_not_json(tmp_path):
    with pytest.raises(RunSummaryError, match="summary.json: no such file"):
        read_summary(tmp_path)
    (tmp_path / "summary.json").write_text("{")
    with pytest.raises(RunSummaryError, match="not JSON"):
        read_summary(tmp_path)


# The twin's summary.json before it had a schema (simulate fig8 at faf0b5b), cut down.
UNVERSIONED_TWIN = {
    "scenario": "fig8",
    "description": "Figure 8: warming steps 16-18-20-22 degC",
    "options": {"hold_s": 60, "positions": None},
    "seed": 5,
    "model": "default",
    "terms": {"heatsink": True},
    "faults": [],
    "imu_eeprom_preloaded_bytes": 0,
    "interrupted": False,
    "realtime": False,
    "sim_seconds": 341.5,
    "wall_seconds": 10.0,
    "speed_x_real_time": 34.0,
    "rows": 3414,
    "marks": {"program_start_s": 1.5},
    "positions": [{"at_s": 0.0, "label": "table", "incl_x_deg": 0.0, "incl_y_deg": 0.0}],
    "boards": {
        "thermal_chamber": {
            "cycles": 5464000001,
            "awake_cycles": 1,
            "sleep_cycles": 5464000000,
            "frames": 344,
            "frames_by_type": {"CHS": 342},
            "rejected": 0,
            "rejected_by_reason": {},
            "sequence_gaps": 0,
            "corrupted_bytes": 0,
            "unanswered_commands": [],
            "refused_commands": [],
            "reported_errors": ["RUNAWAY WRONG_WAY at 16.01 s"],
        }
    },
}


def test_an_unversioned_twin_summary_reads_as_it_stood(tmp_path):
    summary = read_summary(write_document(tmp_path, UNVERSIONED_TWIN))
    assert (summary.source, summary.scenario, summary.seed, summary.rows) == ("twin", "fig8", 5, 3414)
    # Not recorded then: how the run ended, unless it was cut short, and the firmware.
    assert summary.end_reason is None and summary.interrupted is False
    chamber = summary.boards["thermal_chamber"]
    assert chamber.reported_errors == ["RUNAWAY WRONG_WAY at 16.01 s"] and chamber.firmware is None
    assert chamber.cycles == 5464000001
    interrupted = read_summary(write_document(tmp_path, UNVERSIONED_TWIN | {"interrupted": True}))
    assert interrupted.end_reason == "interrupted" and interrupted.interrupted


def test_an_unversioned_boards_position_keeps_its_end_and_firmware(tmp_path):
    document = {
        "rig": "boards",
        "position": "X+30",
        "rows": 5000,
        "frames": 5600,
        "rejected": 0,
        "gaps": 0,
        "end_reason": "program done",
        "wall_seconds": 4100.0,
        "firmware": {"imu_reader": "imu_reader 0.2.0 protocol 2"},
    }
    summary = read_summary(write_document(tmp_path, document))
    assert (summary.source, summary.rows, summary.end_reason) == ("boards", 5000, "program done")
    assert summary.boards["imu_reader"].firmware == "imu_reader 0.2.0 protocol 2"
    assert summary.boards["imu_reader"].frames is None
    assert summary.positions[0]["label"] == "X+30"


def test_a_run_folder_gives_its_summary(tmp_path):
    (tmp_path / "run.csv").write_text("")
    run = RunFolder.of(tmp_path)
    assert run.summary() is None
    twin_summary().write(tmp_path)
    assert run.summary() == twin_summary()
    write_document(tmp_path, {"schema": SCHEMA + 1})
    with pytest.raises(RunSummaryError, match="newer"):
        run.summary()


def status(phase, fault="OK"):
    return parse_line(build_frame("CHS", 0, [1000, phase, 3, 18.0, 17.9, 23.5, 0, "O", fault]))


@pytest.mark.parametrize(
    "phases, reasons",
    [
        # Idle before START is no end; done or idle after running is.
        (["I", "W", "C", "R", "D"], ["", "", "", "", "program done"]),
        (["I", "W", "I"], ["", "", "program done"]),
        (["I", "I"], ["", ""]),
        # A fault ends it whenever it comes: it latches until CLEAR.
        (["I", "F"], ["", "chamber fault WRONG_WAY"]),
        (["W", "F"], ["", "chamber fault WRONG_WAY"]),
    ],
)
def test_when_a_program_is_over(phases, reasons):
    program = ProgramEnd()
    assert [program.reason(status(phase, "WRONG_WAY" if phase == "F" else "OK")) for phase in phases] == reasons
