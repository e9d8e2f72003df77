"""The commands record what they make (thermotilt.registry.recording,
docs/registry.md): the folder each writes, found from its arguments and
ingested as `registry ingest` would; upload and assign-id as rows of what
they did; a registry that cannot take the record costing the command a
warning and not its exit status; THERMOTILT_REGISTRY=off; and commands
that make no folder recording nothing, nor loading the database.

Each test records in its own registry (conftest's registry_of_the_test,
which processes the tests start inherit)."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from alembic.script import ScriptDirectory
from child_process import thermotilt
from sqlalchemy import select
from test_calibration_fit import ANGLES_DEG, cycle, write_campaign_file, write_run_log
from test_registry import assert_one_line_error, rows, url_of, write_run
from test_upload import write_fit
from test_validate import write_field_log

from thermotilt.calibration import upload as upload_workflow
from thermotilt.calibration.certificate import issue as certificate_issue
from thermotilt.calibration.upload import AssignResult, UploadError, UploadResult, read_fit_to_upload
from thermotilt.cli import build_parser
from thermotilt.options import EXIT_INTERRUPTED
from thermotilt.registry import folders as registry_folders
from thermotilt.registry.database import Registry, alembic_config, newest_revision
from thermotilt.registry.ingest import rebuild
from thermotilt.registry.recording import MADE_FOLDERS, record_made
from thermotilt.registry.schema import BoardRun, Calibration, IdAssignment, Sensor, Upload, Validation

UNWRITABLE = "sqlite:////nonexistent-folder/registry.sqlite3"


def field_run(folder: Path) -> Path:
    write_field_log(folder / "run.csv", np.linspace(9.0, 48.0, 800))
    return folder


def folders_of(registry_file: Path, table) -> list[str]:
    with Registry.open(url_of(registry_file)) as registry, registry.reading() as session:
        return sorted(session.scalars(select(table.folder)))


def test_fit_and_validate_record_the_folders_they_wrote(tmp_path, cli_in_process, registry_of_the_test):
    temperatures, sets = cycle(600)
    campaign = tmp_path / "campaign"
    for angle in ANGLES_DEG[:4]:
        write_run_log(campaign / f"{angle}.csv", angle, temperatures, sets)
    write_campaign_file(campaign, ["TT-R"] * 4)
    fitted = cli_in_process("fit", campaign, "--out", tmp_path / "fit")
    assert (fitted.returncode, fitted.stderr) == (0, "")
    validated = cli_in_process("validate", field_run(tmp_path / "field") / "run.csv")
    assert validated.returncode == 0 and "warning: not recorded" not in validated.stderr
    assert folders_of(registry_of_the_test, Calibration) == [str(tmp_path / "fit")]
    # validation.json goes into the run folder; --out's report is not an artefact.
    assert folders_of(registry_of_the_test, Validation) == [str(tmp_path / "field")]
    assert folders_of(registry_of_the_test, BoardRun) == [str(tmp_path / "field")]
    listing = cli_in_process("sensors").stdout.splitlines()
    assert len(listing) == 2 and listing[1].startswith("TT-R") and str(tmp_path / "fit") in listing[1]


def test_simulate_records_the_run_folder_it_named_itself(tmp_path, registry_of_the_test):
    result = thermotilt("simulate", "idle", "--duration", "2", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    (run,) = (tmp_path / "runs").iterdir()
    assert run.name.startswith("idle-") and folders_of(registry_of_the_test, BoardRun) == [str(run)]


def parsed(*args) -> object:
    return build_parser().parse_args([str(arg) for arg in args])


def test_each_command_s_folder_comes_from_its_arguments(tmp_path):
    made = {
        ("campaign", "--twin", "--out", "lab/c1"): Path("lab/c1"),
        ("fit", tmp_path, "--out", "fits/TT-01"): Path("fits/TT-01"),
        ("log", "--port", "/dev/ttyUSB0", "--out", "runs/rig"): Path("runs/rig"),
        ("log", "--port", "/dev/ttyUSB0", "--out", "runs/rig/run.csv"): Path("runs/rig"),
        ("simulate", "fig8", "--out", "runs/f8"): Path("runs/f8"),
        ("validate", field_run(tmp_path / "field") / "run.csv", "--out", "report"): tmp_path / "field",
    }
    for args, folder in made.items():
        namespace = parsed(*args)
        assert MADE_FOLDERS[namespace.command](namespace) == folder, args
    assert not {"frames", "coefficients", "compare", "discover", "hide-effect", "sensors", "history"} & set(
        MADE_FOLDERS
    )


def test_an_interrupted_log_is_recorded_and_a_failed_one_is_not(tmp_path, registry_of_the_test):
    run = write_run(tmp_path / "rig", scenario=None)
    args = parsed("log", "--port", "/dev/ttyUSB0", "--out", run / "run.csv")
    assert record_made(args, 1) is None and not registry_of_the_test.exists()
    assert record_made(args, EXIT_INTERRUPTED) is None
    assert folders_of(registry_of_the_test, BoardRun) == [str(run)]


@pytest.mark.parametrize(
    ("registry", "reason"),
    [
        (UNWRITABLE, "unable to open database file"),
        ("not a url", "Could not parse SQLAlchemy URL from given URL string"),
    ],
)
def test_a_registry_that_cannot_take_the_record_costs_a_warning_not_the_exit_status(
    tmp_path, cli_in_process, registry, reason
):
    result = cli_in_process("validate", field_run(tmp_path / "field"), "--registry", registry)
    assert result.returncode == 0 and (tmp_path / "field" / "validation.json").is_file()
    assert result.stderr == f"thermotilt: warning: not recorded in the registry {registry}: {reason}\n"


def test_the_warning_reaches_a_real_process_with_its_exit_status(tmp_path, monkeypatch):
    (tmp_path / "notes.sqlite3").write_text("not a database\n")
    monkeypatch.setenv("THERMOTILT_REGISTRY", url_of(tmp_path / "notes.sqlite3"))
    result = thermotilt("validate", field_run(tmp_path / "field"))
    assert result.returncode == 0 and "Traceback" not in result.stderr
    assert result.stderr.splitlines()[-1] == (
        f"thermotilt: warning: not recorded in the registry {url_of(tmp_path / 'notes.sqlite3')}: file is not a database"
    )


def test_off_records_nothing_and_the_registry_s_own_commands_say_it_is_off(tmp_path, cli_in_process, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("THERMOTILT_REGISTRY", "off")
    result = cli_in_process("validate", field_run(tmp_path / "field"))
    assert result.returncode == 0 and "warning" not in result.stderr
    monkeypatch.setenv("THERMOTILT_REGISTRY", url_of(tmp_path / "lab.sqlite3"))
    assert cli_in_process("validate", tmp_path / "field", "--registry", "off").returncode == 0
    assert not list(tmp_path.rglob("*.sqlite3*")) and not (tmp_path / "runs").exists()
    monkeypatch.setenv("THERMOTILT_REGISTRY", "off")
    assert_one_line_error(cli_in_process("sensors"), "the registry is off (THERMOTILT_REGISTRY=off): give --registry")


def test_commands_that_make_no_folder_record_nothing_and_load_no_database(tmp_path, registry_of_the_test):
    code = (
        "import sys; from thermotilt import cli; status = cli.main(['coefficients']); "
        "print(status, sorted({'sqlalchemy', 'alembic'} & set(sys.modules)), file=sys.stderr)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path)
    assert result.stderr == "0 []\n" and not registry_of_the_test.exists() and not (tmp_path / "runs").exists()


@pytest.fixture
def board_on_a_port(monkeypatch, tmp_path):
    """upload's and assign-id's workflows answering as a board that took
    everything would: what the command line records is their arguments'."""
    fit_dir = write_fit(tmp_path / "fit", sensor_id="TT-U")
    fit = read_fit_to_upload(fit_dir)

    def uploaded(fit_dir, port, baud, save):
        reset = ("COMMANDED", "E", 3) if save else (None, "U", 0)
        after = fit.table if save else None
        return UploadResult(port, "0.4.1", fit.table, fit.table, after, save, *reset, fit.sensor_id, fit.domain)

    monkeypatch.setattr(upload_workflow, "upload", uploaded)
    monkeypatch.setattr(
        upload_workflow, "assign_id", lambda port, sensor_id, baud, replace: AssignResult(port, "", sensor_id, "D", ())
    )
    return fit_dir


def test_upload_and_assign_id_are_recorded_as_what_they_did(
    board_on_a_port, tmp_path, cli_in_process, registry_of_the_test
):
    fit_dir = board_on_a_port
    for args in (("assign-id", "TT-U"), ("upload", fit_dir), ("upload", fit_dir, "--no-save")):
        result = cli_in_process(*args, "--port", "/dev/ttyUSB3")
        assert (result.returncode, result.stderr) == (0, ""), args
    with Registry.open(url_of(registry_of_the_test)) as registry:
        with registry.reading() as session:
            uploads = session.scalars(select(Upload).order_by(Upload.id)).all()
            (assignment,) = session.scalars(select(IdAssignment)).all()
        assert (assignment.sensor_id, assignment.port) == ("TT-U", "/dev/ttyUSB3")
        block = hashlib.sha256((fit_dir / "coefficients.bin").read_bytes()).hexdigest()
        assert [(row.sensor_id, row.fit_folder, row.coefficients_sha256, row.saved) for row in uploads] == [
            ("TT-U", str(fit_dir), block, True),
            ("TT-U", str(fit_dir), block, False),
        ]
        assert uploads[0].uploaded_utc <= uploads[1].uploaded_utc and assignment.assigned_utc <= uploads[0].uploaded_utc
        # The fit folder holds the uploads (uploads.jsonl); no folder holds the
        # assignment, so a rebuild keeps it, and it makes no sensor of the fleet.
        rebuild(registry, [tmp_path / "fit"])
        assert (rows(registry, Upload), rows(registry, IdAssignment), rows(registry, Sensor)) == (2, 1, 1)
    assert len((fit_dir / "uploads.jsonl").read_text().splitlines()) == 2
    # A registry deleted and rebuilt from the folder has the uploads as they were.
    with Registry.open(url_of(tmp_path / "new.sqlite3")) as registry:
        (fit_dir / "uploads.jsonl").write_text((fit_dir / "uploads.jsonl").read_text() + '{"cut short\n')
        ingestion = rebuild(registry, [tmp_path / "fit"])
        with registry.reading() as session:
            again = session.scalars(select(Upload).order_by(Upload.id)).all()
        assert [(row.sensor_id, row.coefficients_sha256, row.saved, row.uploaded_utc) for row in again] == [
            (row.sensor_id, row.coefficients_sha256, row.saved, row.uploaded_utc) for row in uploads
        ]
        assert ingestion.uploads == 2 and ingestion.malformed_upload_lines == 1
        assert "skipped 1 lines of uploads.jsonl" in ingestion.summary()


def test_an_upload_that_failed_is_not_recorded(board_on_a_port, monkeypatch, cli_in_process, registry_of_the_test):
    def refused(*_args, **_options):
        raise UploadError("SETCOE W X refused by /dev/ttyUSB3: BAD_ARG OUTPUT_TOO_LARGE; nothing saved")

    monkeypatch.setattr(upload_workflow, "upload", refused)
    assert_one_line_error(cli_in_process("upload", board_on_a_port, "--port", "/dev/ttyUSB3"), "nothing saved")
    assert not registry_of_the_test.exists()


def test_the_newest_revision_named_by_its_file_is_alembic_s_head():
    assert ScriptDirectory.from_config(alembic_config()).get_current_head() == newest_revision() == "0002"


def test_the_block_file_the_registry_names_is_the_one_the_certificate_names():
    # folders.py names it itself so that recording an upload loads none of the certificate's modules.
    assert registry_folders.COEFFICIENTS_BIN == certificate_issue.COEFFICIENTS_BIN


def test_a_recalibration_s_fit_takes_its_previous_calibration_from_the_registry(tmp_path, cli_in_process):
    # Two campaigns of TT-R, in January and in June: June's fit is certified
    # with the change since January's as its long-term stability component.
    temperatures, sets = cycle(600)
    fits = {}
    for month, started in (("january", "2026-01-05T08:00:00Z"), ("june", "2026-06-01T08:00:00Z")):
        campaign = tmp_path / month
        for angle in ANGLES_DEG[:4]:
            write_run_log(campaign / f"{angle}.csv", angle, temperatures, sets)
        positions = [
            {"label": str(index), "status": "done", "sensor_id": "TT-R", "started_utc": started, "wall_seconds": 60.0}
            for index in range(4)
        ]
        (campaign / "campaign.json").write_text(json.dumps({"format": 1, "positions": positions}))
        fits[month] = tmp_path / f"fit-{month}"
        fitted = cli_in_process("fit", campaign, "--out", fits[month])
        assert (fitted.returncode, fitted.stderr) == (0, "")
    first, second = (json.loads((fits[m] / "certificate.json").read_text()) for m in ("january", "june"))
    assert first["previous_calibration"] is None
    assert second["previous_calibration"] == {
        "certificate_number": first["certificate_number"],
        "ended_utc": "2026-01-05T08:01:00Z",
        "fit": str(fits["january"]),
    }
    stability = [c for c in second["budget"]["X"]["components"] if c["name"] == "long-term stability"]
    assert stability[0]["added"] and first["certificate_number"] in stability[0]["source"]
    # Fitting January's campaign again takes no calibration made after it began.
    again = cli_in_process("fit", tmp_path / "january", "--out", tmp_path / "fit-again")
    assert again.returncode == 0
    assert json.loads((tmp_path / "fit-again" / "certificate.json").read_text())["previous_calibration"] is None
