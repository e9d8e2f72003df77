"""The lab registry (thermotilt.registry, docs/registry.md): folders
recognised by the files the commands write and recorded once each, a
rebuild from the folders alone giving the same fleet, two writers at once
losing nothing, the schema made by its Alembic revisions, and bad input
answered in one line.

The lab's folders are written by the project's own writers (campaign.json
by CampaignFile, the fits by fit.write_outputs and write_certificate,
summary.json by RunSummary, validation.json from Validation.document), so
their formats cannot drift from what the registry reads."""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
import shutil
import subprocess
import sys
from datetime import UTC, date, datetime
from pathlib import Path

import pytest
from alembic import command
from child_process import thermotilt
from sqlalchemy import func, select
from test_certificate import fitted

from thermotilt.calibration.campaign.folder import DONE, CampaignFolder, Position
from thermotilt.calibration.certificate import certify, write_certificate
from thermotilt.calibration.fit import write_outputs
from thermotilt.calibration.tilt_change import Installation, TiltChange
from thermotilt.calibration.validate import Validation
from thermotilt.registry.database import (
    MIGRATIONS,
    Registry,
    RegistryError,
    alembic_config,
    create_registry_engine,
    registry_url,
)
from thermotilt.registry.fleet import fleet
from thermotilt.registry.folders import FolderError
from thermotilt.registry.ingest import NEW, UNCHANGED, UPDATED, ingest, rebuild
from thermotilt.registry.schema import BoardRun, Calibration, Campaign, Sensor
from thermotilt.registry.schema import Validation as ValidationRow
from thermotilt.run.summary import BoardReport, RunSummary
from thermotilt.wire.coefficients import SENSOR_ID_RECORD_ADDRESS, encode_sensor_id_record

FIRMWARE = "imu_reader 0.4.1 protocol 2"
# The ATmega328P's EEPROM, erased, as the twin saves it beside run.csv.
EEPROM_BYTES = 1024
POSITIONS = (("0", 0.0), ("X+15", 15.0), ("X-15", -15.0))
JANUARY, JUNE = "2026-01-10T08:00:00Z", "2026-06-02T08:00:00Z"
MARCH_MTIME, JULY_MTIME = (datetime(2026, month, 1, 12, tzinfo=UTC).timestamp() for month in (3, 7))


def write_campaign(folder: Path, sensor_id: str, started_utc: str) -> None:
    """A finished campaign of three positions on real boards, each an hour."""
    positions = [Position(label, x, 0.0, index) for index, (label, x) in enumerate(POSITIONS)]
    program = {"start_c": -10.0, "max_c": 45.0, "step_c": 2.0, "hold_s": 600}
    campaign = CampaignFolder(folder).start(
        {"format": 1, "rig": "boards", "created_utc": started_utc, "program": program}, positions
    )
    for record in campaign.records.values():
        record.status, record.started_utc, record.wall_seconds = DONE, started_utc, 3600.0
        record.firmware, record.sensor_id = {"imu_reader": FIRMWARE}, sensor_id
    campaign.save()
    # A position's run folder belongs to its campaign: no board run of its own.
    write_run(folder / "0", scenario=None)


def write_fit(folder: Path, sensor_id: str, campaign_dir: Path | None) -> None:
    """A fit; certified (its dates from campaign_dir's campaign.json) when campaign_dir is given."""
    campaign, fits = fitted(5)
    write_outputs(fits, campaign, folder, sensor_id)
    if campaign_dir is not None:
        write_certificate(folder, certify(campaign, fits, campaign_dir, sensor_id))


def write_run(folder: Path, scenario: str | None = "field-warming", eeprom: bytes | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "run.csv").write_text("time_s,ax_raw\n0.1,-1792\n")
    RunSummary("twin", 1, "program done", 0.1, {"imu_reader": BoardReport(firmware=FIRMWARE)}, scenario).write(folder)
    if eeprom is not None:
        (folder / "imu_reader_eeprom.bin").write_bytes(eeprom)
    return folder


def board_eeprom(sensor_id: str, fit: Path) -> bytes:
    """A board given sensor_id (assign-id) running fit's coefficient block (upload)."""
    image = bytearray(b"\xff" * EEPROM_BYTES)
    block, record = (fit / "coefficients.bin").read_bytes(), encode_sensor_id_record(sensor_id)
    image[: len(block)] = block
    image[SENSOR_ID_RECORD_ADDRESS : SENSOR_ID_RECORD_ADDRESS + len(record)] = record
    return bytes(image)


def write_validation(run: Path, p95_deg: float, modified: float) -> None:
    installation = Installation(0.0, 60.0, 600, 20.0, {"X": 0.0, "Y": 0.0}, False, True)
    change = TiltChange(installation, [], p95_deg, 1.0, "the certificate's domain", 0, {})
    after_from = "compensated here with fits/TT-A-june"
    validation = Validation(str(run / "run.csv"), 1, 0, (10.0, 40.0), after_from, "coef_source E", None, change=change)
    (run / "validation.json").write_text(json.dumps(validation.document(), indent=2) + "\n", encoding="utf-8")
    os.utime(run / "validation.json", (modified, modified))


@pytest.fixture(scope="module")
def lab_template(tmp_path_factory) -> Path:
    """TT-A calibrated in January and again in June (each campaign fitted
    and certified) and validated twice in the field on a board running its
    June fit; TT-B fitted without a certificate; a fit for no sensor; a
    board run with no EEPROM image; a folder of notes."""
    lab = tmp_path_factory.mktemp("lab")
    for month, started in (("january", JANUARY), ("june", JUNE)):
        write_campaign(lab / "campaigns" / f"TT-A-{month}", "TT-A", started)
        write_fit(lab / "fits" / f"TT-A-{month}", "TT-A", lab / "campaigns" / f"TT-A-{month}")
    write_fit(lab / "fits" / "TT-B", "TT-B", None)
    write_fit(lab / "fits" / "no-id", "", None)
    board = board_eeprom("TT-A", lab / "fits" / "TT-A-june")
    write_validation(write_run(lab / "field" / "TT-A-march", eeprom=board), 0.2, MARCH_MTIME)
    write_validation(write_run(lab / "field" / "TT-A-july", eeprom=board), 0.05, JULY_MTIME)
    write_run(lab / "bench" / "idle", scenario="idle")
    (lab / "notes").mkdir()
    (lab / "notes" / "readme.txt").write_text("not an artefact\n")
    return lab


@pytest.fixture
def lab(lab_template, tmp_path) -> Path:
    copy = tmp_path / "lab"
    shutil.copytree(lab_template, copy)
    return copy


def url_of(path: Path) -> str:
    return f"sqlite:///{path}"


def rows(registry: Registry, table) -> int:
    with registry.reading() as session:
        return session.scalar(select(func.count()).select_from(table))


def test_each_folder_is_recognised_by_its_files_and_recorded_with_what_they_say(lab, tmp_path):
    with Registry.open(url_of(tmp_path / "registry.sqlite3")) as registry:
        ingestion = ingest(registry, [lab])
        with registry.reading() as session:
            june = session.scalars(select(Calibration).where(Calibration.folder.endswith("TT-A-june"))).one()
            campaign = session.scalars(select(Campaign).where(Campaign.folder.endswith("TT-A-june"))).one()
            validations = {row.folder: row for row in session.scalars(select(ValidationRow))}
            boards = {Path(row.folder).name: row for row in session.scalars(select(BoardRun))}
            sensors = list(session.scalars(select(Sensor.sensor_id).order_by(Sensor.sensor_id)))
            no_id = session.scalars(select(Calibration).where(Calibration.folder.endswith("no-id"))).one()
            no_id_sensor = no_id.sensor_id
    assert {kind: ingestion.recorded(kind) for kind in ("campaign", "fit", "validation", "board run")} == {
        "campaign": 2,
        "fit": 4,
        "validation": 2,
        "board run": 3,
    }
    assert ingestion.unrecognised == [(lab / "notes").resolve()]
    certificate = json.loads((lab / "fits" / "TT-A-june" / "certificate.json").read_text())
    coefficients = (lab / "fits" / "TT-A-june" / "coefficients.bin").read_bytes()
    assert june.sensor_id == "TT-A" and june.certificate_number == certificate["certificate_number"]
    assert june.coefficients_sha256 == hashlib.sha256(coefficients).hexdigest()
    assert june.tilt_u95_deg == certificate["tilt_u95_deg"] and june.domain == certificate["domain"]
    assert (june.started_utc, june.ended_utc) == (datetime(2026, 6, 2, 8), datetime(2026, 6, 2, 9))
    assert (campaign.rig, campaign.positions_planned, campaign.positions_done) == ("boards", 3, 3)
    assert campaign.sensor_id == "TT-A" and campaign.firmware == [FIRMWARE]
    july = validations[str((lab / "field" / "TT-A-july").resolve())]
    assert (july.sensor_id, july.tilt_change_p95_deg, july.validated_utc) == ("TT-A", 0.05, datetime(2026, 7, 1, 12))
    assert boards["TT-A-july"].eeprom_coefficients_sha256 == june.coefficients_sha256
    assert boards["TT-A-july"].eeprom_fitted_for == "TT-A" and boards["idle"].sensor_id is None
    assert sensors == ["TT-A", "TT-B"] and no_id_sensor is None


def test_ingesting_a_folder_again_adds_nothing_and_a_changed_one_is_updated(lab, tmp_path):
    with Registry.open(url_of(tmp_path / "registry.sqlite3")) as registry:
        first = ingest(registry, [lab])
        again = ingest(registry, [lab, lab / "fits"])
        assert set(first.counts) == {(kind, NEW) for kind in ("campaign", "fit", "validation", "board run")}
        assert set(again.counts) == {(kind, UNCHANGED) for kind in ("campaign", "fit", "validation", "board run")}
        assert sum(again.counts.values()) == sum(first.counts.values()) == 11
        write_validation(lab / "field" / "TT-A-july", 0.07, JULY_MTIME)
        changed = ingest(registry, [lab / "field"])
        assert changed.counts["validation", UPDATED] == 1 and rows(registry, ValidationRow) == 2
        assert fleet(registry).lines[0].validation_p95_deg == 0.07


def test_the_sensors_listing_shows_the_last_calibration_and_validation_and_when_recalibration_is_due(lab, tmp_path):
    with Registry.open(url_of(tmp_path / "registry.sqlite3")) as registry:
        ingest(registry, [lab])
        early, late = fleet(registry, today=date(2027, 5, 1)), fleet(registry, 30, today=date(2027, 5, 1))
    a, b = early.lines
    june = (lab / "fits" / "TT-A-june").resolve()
    assert (a.sensor_id, a.calibrated, a.fit_folder) == ("TT-A", date(2026, 6, 2), str(june))
    assert (a.validation_p95_deg, a.validated) == (0.05, date(2026, 7, 1))
    assert (b.sensor_id, b.calibrated, b.u95_deg, b.validation_p95_deg) == ("TT-B", None, None, None)
    lines = early.summary().splitlines()
    assert lines[0].split()[:2] == ["sensor", "calibrated"]
    u95 = f"{json.loads((june / 'certificate.json').read_text())['tilt_u95_deg']:#.2g}".rstrip(".")
    assert lines[1].split() == ["TT-A", "2026-06-02", u95, str(june), "-", "0.050", "(2026-07-01)", "2027-06-02"]
    assert lines[2].split() == ["TT-B", "-", "-", str((lab / "fits" / "TT-B").resolve()), "-", "-", "-"]
    assert late.summary().splitlines()[1].endswith("2026-07-02 overdue")


def test_rebuild_from_the_folders_gives_the_sensors_listing_the_deleted_registry_gave(lab, cli_in_process, monkeypatch):
    monkeypatch.chdir(lab)
    monkeypatch.delenv("THERMOTILT_REGISTRY", raising=False)
    # Recorded piecemeal: the fits first, then everything.
    assert cli_in_process("registry", "ingest", "fits").returncode == 0
    assert cli_in_process("registry", "ingest", ".").returncode == 0
    before = cli_in_process("sensors", "--interval-days", "400")
    assert before.returncode == 0 and before.stdout.splitlines()[1].split()[:2] == ["TT-A", "2026-06-02"]
    assert "fits/TT-A-june" in before.stdout and str(lab) not in before.stdout
    for path in (lab / "runs").glob("registry.sqlite3*"):
        path.unlink()
    rebuilt = cli_in_process("registry", "rebuild", ".")
    assert rebuilt.returncode == 0 and "skipped 1 folder with files" in rebuilt.stdout, rebuilt.stdout
    assert cli_in_process("sensors", "--interval-days", "400").stdout == before.stdout


def test_a_rebuild_that_meets_a_corrupt_file_leaves_the_registry_as_it_was(lab, tmp_path, cli_in_process):
    registry = ("--registry", url_of(tmp_path / "registry.sqlite3"))
    assert cli_in_process("registry", "rebuild", lab, *registry).returncode == 0
    before = cli_in_process("sensors", *registry).stdout
    (lab / "fits" / "TT-B" / "coefficients.json").write_text('{"sensor_id": "TT-B", "fits": {')
    result = cli_in_process("registry", "rebuild", lab, *registry)
    assert_one_line_error(result, f"{lab / 'fits' / 'TT-B' / 'coefficients.json'}: not JSON")
    assert cli_in_process("sensors", *registry).stdout == before


def test_an_empty_registry_says_so(tmp_path, cli_in_process):
    result = cli_in_process("sensors", "--registry", url_of(tmp_path / "empty.sqlite3"))
    assert result.returncode == 0 and result.stdout.startswith("no sensors in the registry sqlite:///")
    assert "thermotilt registry rebuild FOLDER" in result.stdout


def connect_at_once(url: str, start) -> None:
    engine = create_registry_engine(url)
    start.wait()
    with engine.connect():
        pass
    engine.dispose()


def test_two_processes_opening_a_new_sqlite_file_at_once_both_get_wal(tmp_path):
    """Switching a new file to WAL answers a second process BUSY at once
    (no busy handler): without waiting for it, about half of these rounds
    failed."""
    context = multiprocessing.get_context("fork")
    for index in range(20):
        url = url_of(tmp_path / f"new-{index}.sqlite3")
        start = context.Barrier(2)
        processes = [context.Process(target=connect_at_once, args=(url, start)) for _ in range(2)]
        for process in processes:
            process.start()
        for process in processes:
            process.join(60)
        assert [process.exitcode for process in processes] == [0, 0], index
        with create_registry_engine(url).connect() as connection:
            assert connection.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"


def ingest_one_at_a_time(url: str, folders: list[Path], start) -> None:
    start.wait()
    with Registry.open(url) as registry:
        for folder in folders:
            ingest(registry, [folder])


def ingest_from_two_processes_at_once(url: str, runs: dict[str, list[Path]]) -> None:
    """Each side's folders ingested one at a time by its own process, both
    starting at one moment; both must end well."""
    context = multiprocessing.get_context("fork")
    start = context.Barrier(2)
    processes = [context.Process(target=ingest_one_at_a_time, args=(url, runs[side], start)) for side in runs]
    for process in processes:
        process.start()
    for process in processes:
        process.join(60)
    assert [process.exitcode for process in processes] == [0, 0]


def test_two_processes_ingesting_into_one_sqlite_file_at_once_lose_no_record(tmp_path):
    """Both open a new registry at the same moment (one creates its tables,
    the other waits) and then write a transaction per folder, interleaved."""
    runs = {side: [write_run(tmp_path / side / f"run-{index}") for index in range(25)] for side in ("a", "b")}
    url = url_of(tmp_path / "shared.sqlite3")
    ingest_from_two_processes_at_once(url, runs)
    with Registry.open(url) as registry, registry.reading() as session:
        recorded = set(session.scalars(select(BoardRun.folder)))
    assert recorded == {str(folder.resolve()) for folders in runs.values() for folder in folders}


def assert_alembic_check_passes(url: str) -> None:
    """`alembic check` through Alembic's own command line (env.py) on the registry at url."""
    checked = subprocess.run(
        [sys.executable, "-m", "alembic", "-c", MIGRATIONS / "alembic.ini", "check"],
        env={**os.environ, "THERMOTILT_REGISTRY": url},
        capture_output=True,
        text=True,
        check=False,
    )
    assert (checked.returncode, checked.stdout) == (0, "No new upgrade operations detected.\n"), checked.stderr


def test_the_revisions_build_the_schema_the_models_declare_and_take_it_down_again(tmp_path):
    url = url_of(tmp_path / "registry.sqlite3")
    with Registry.open(url) as registry:
        with registry.engine.begin() as connection:
            command.check(alembic_config(connection))
            command.downgrade(alembic_config(connection), "base")
        with pytest.raises(RegistryError, match="no such table"):
            rows(registry, Sensor)
    with Registry.open(url) as registry:
        assert rows(registry, Sensor) == 0
    # Alembic's own command line, as a developer writing a revision runs it.
    assert_alembic_check_passes(url)


def test_a_registry_of_a_newer_schema_is_refused(tmp_path):
    url = url_of(tmp_path / "registry.sqlite3")
    with Registry.open(url) as registry, registry.writing() as session:
        session.connection().exec_driver_sql("UPDATE alembic_version SET version_num = 'f00d'")
    with pytest.raises(RegistryError, match="schema revision f00d, which this thermotilt does not know"):
        Registry.open(url)


def test_the_url_is_the_option_else_the_environments_else_runs_registry_sqlite3_here(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("THERMOTILT_REGISTRY", raising=False)
    assert registry_url() == f"sqlite:///{tmp_path / 'runs' / 'registry.sqlite3'}" and (tmp_path / "runs").is_dir()
    monkeypatch.setenv("THERMOTILT_REGISTRY", "sqlite:///lab.sqlite3")
    assert registry_url() == "sqlite:///lab.sqlite3" and registry_url("sqlite:///x.sqlite3") == "sqlite:///x.sqlite3"


def test_the_registry_loads_its_database_only_when_a_command_runs():
    code = "import sys, thermotilt.cli; thermotilt.cli.build_parser(); print(sorted({'sqlalchemy', 'alembic'} & set(sys.modules)))"
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert loaded.stdout.strip() == "[]"


def assert_one_line_error(result, message: str, code: int = 1) -> None:
    assert "Traceback" not in result.stderr, result.stderr
    assert result.stderr.splitlines() == [result.stderr.strip()], result.stderr
    assert result.stderr.startswith("thermotilt: error: "), result.stderr
    assert message in result.stderr and result.returncode == code, result.stderr


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("not a url", "cannot open the registry not a url: Could not parse SQLAlchemy URL"),
        ("nosuchdb://host/lab", "Can't load plugin: sqlalchemy.dialects:nosuchdb"),
        ("sqlite:////nonexistent-folder/registry.sqlite3", "unable to open database file"),
    ],
)
def test_a_url_that_names_no_database_is_one_line(url, message, cli_in_process):
    assert_one_line_error(cli_in_process("sensors", "--registry", url), message)


def test_a_file_that_is_not_a_database_or_a_password_in_the_url_is_one_line_without_it(tmp_path, cli_in_process):
    (tmp_path / "notes.sqlite3").write_text("not a database\n")
    result = cli_in_process("sensors", "--registry", url_of(tmp_path / "notes.sqlite3"))
    assert_one_line_error(result, "file is not a database")
    result = cli_in_process("sensors", "--registry", "postgresql+nosuchdriver://lab:secret@localhost/lab")
    assert_one_line_error(result, "postgresql+nosuchdriver://lab:***@localhost/lab")
    assert "secret" not in result.stderr


def test_unreadable_or_missing_folders_are_one_line(lab, tmp_path, cli_in_process):
    registry = ("--registry", url_of(tmp_path / "registry.sqlite3"))
    assert_one_line_error(cli_in_process("registry", "rebuild", tmp_path / "missing", *registry), "no such folder", 2)
    certificate = lab / "fits" / "TT-A-june" / "certificate.json"
    certificate.unlink()
    certificate.mkdir()
    result = cli_in_process("registry", "ingest", lab, *registry)
    assert_one_line_error(result, f"cannot read {certificate}: Is a directory")


def test_a_certificate_of_other_coefficients_is_one_line(lab, tmp_path):
    shutil.copy(lab / "fits" / "TT-B" / "coefficients.bin", lab / "fits" / "TT-A-june" / "coefficients.bin")
    with Registry.open(url_of(tmp_path / "registry.sqlite3")) as registry:
        with pytest.raises(FolderError, match="the certificate is of other coefficients"):
            rebuild(registry, [lab])
        assert rows(registry, Calibration) == 0


def test_errors_reach_a_real_process_as_one_line(tmp_path):
    (tmp_path / "campaign.json").write_text("[]")
    result = thermotilt("registry", "ingest", tmp_path, "--registry", url_of(tmp_path / "registry.sqlite3"))
    assert "Traceback" not in result.stderr and result.returncode == 1
    assert result.stderr == f"thermotilt: error: {tmp_path / 'campaign.json'}: not a JSON object\n"
