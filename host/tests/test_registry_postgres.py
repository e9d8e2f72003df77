"""The lab registry on a PostgreSQL server (docs/registry.md, "A lab's
server"): the revisions migrating a new database, a newer schema refused,
what the commands record and `registry rebuild` listing the sensors and
history SQLite lists, two processes writing at once losing nothing, and an
unreachable server or bad credentials answered in one line.

Every test is long (make test-long). The server is a throwaway one this
test run starts with Debian's binaries (make system-deps), listening on a
unix socket in a temporary folder only; each test has a database of its
own. Its databases sort text as a lab's server does, by language (ICU's
en-US), not character by character as SQLite does."""

from __future__ import annotations

import itertools
import os
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import pytest
import test_registry
from alembic import command
from sqlalchemy import create_engine, inspect, select
from sqlalchemy.pool import NullPool
from test_registry import (
    EEPROM_BYTES,
    assert_alembic_check_passes,
    assert_one_line_error,
    ingest_from_two_processes_at_once,
    url_of,
    write_fit,
    write_run,
)
from test_registry_recording import parsed

from thermotilt.calibration.upload_record import record_upload
from thermotilt.registry.database import Registry, alembic_config, newest_revision
from thermotilt.registry.recording import record_made
from thermotilt.registry.schema import Base, BoardRun, Sensor, Upload
from thermotilt.wire.coefficients import SENSOR_ID_RECORD_ADDRESS, encode_sensor_id_record

pytestmark = pytest.mark.long

# test_registry.py's lab, written by the project's own writers, for these tests too.
lab_template, lab = test_registry.lab_template, test_registry.lab

# Debian's server binaries, a folder per major version: /usr/lib/postgresql/15/bin/initdb.
SERVER_VERSIONS = Path("/usr/lib/postgresql")
# initdb and postgres refuse to run as root: as root they run as the user Debian's package makes.
SERVER_USER = "postgres"
SUPERUSER = "postgres"
# A role that logs in with a password (every other login is trusted).
PASSWORD_ROLE, PASSWORD = "rig", "right-secret"
SERVER_START_TIMEOUT_S = 60


@dataclass(frozen=True)
class PostgresServer:
    socket_dir: Path
    database_numbers: Iterator[int] = field(default_factory=itertools.count)

    def url(self, database: str, user: str = SUPERUSER, password: str | None = None) -> str:
        login = user if password is None else f"{user}:{password}"
        return f"postgresql+psycopg://{login}@/{database}?host={self.socket_dir}"

    def execute(self, *statements: str) -> None:
        """Statements as the superuser, each outside a transaction (CREATE DATABASE's way)."""
        engine = create_engine(self.url("postgres"), isolation_level="AUTOCOMMIT", poolclass=NullPool)
        try:
            with engine.connect() as connection:
                for statement in statements:
                    connection.exec_driver_sql(statement)
        finally:
            engine.dispose()

    def new_database(self, owner: str = SUPERUSER) -> str:
        """A new, empty database's name."""
        name = f"registry_{next(self.database_numbers)}"
        self.execute(f"CREATE DATABASE {name} OWNER {owner}")
        return name


def server_binaries() -> Path:
    """The newest PostgreSQL major version's bin folder."""
    majors = [initdb.parent for initdb in SERVER_VERSIONS.glob("*/bin/initdb") if initdb.parents[1].name.isdigit()]
    if not majors:
        pytest.fail(
            f"no PostgreSQL server in {SERVER_VERSIONS}/*/bin (initdb, pg_ctl): `make system-deps` installs "
            "Debian's postgresql package, which the registry's PostgreSQL tests start a server of",
            pytrace=False,
        )
    return max(majors, key=lambda folder: int(folder.parent.name))


def as_server_user(*command: object) -> list[str]:
    prefix = ["runuser", "-u", SERVER_USER, "--"] if os.geteuid() == 0 else []
    return [*prefix, *map(str, command)]


def run_server_tool(*command: object, log: Path | None = None) -> None:
    result = subprocess.run(as_server_user(*command), capture_output=True, text=True, check=False)
    if result.returncode != 0:
        logged = log.read_text(errors="replace") if log is not None and log.is_file() else ""
        pytest.fail(f"{' '.join(map(str, command))} failed:\n{result.stdout}{result.stderr}{logged}", pytrace=False)


def require_passwords_of(data: Path, role: str) -> None:
    """pg_hba.conf's first match wins: the role's logins need its password."""
    hba = data / "pg_hba.conf"
    hba.write_text(f"local all {role} scram-sha-256\n" + hba.read_text())


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[PostgresServer]:
    """A server of this test run's own on a unix socket only (so no port is
    shared with anything), stopped and deleted at the end, also on failure."""
    binaries = server_binaries()
    # Not under pytest's temporary folder, whose 0700 parents keep the server's user out.
    home = Path(tempfile.mkdtemp(prefix="thermotilt-pg-"))
    data, sockets, log = home / "data", home / "socket", home / "server.log"
    sockets.mkdir()
    if os.geteuid() == 0:
        for folder in (home, sockets):
            shutil.chown(folder, SERVER_USER)
    try:
        run_server_tool(
            binaries / "initdb",
            *("-D", data, "-U", SUPERUSER, "--auth=trust", "--no-sync", "--encoding=UTF8"),
            *("--locale=C.UTF-8", "--locale-provider=icu", "--icu-locale=en-US"),
        )
        require_passwords_of(data, PASSWORD_ROLE)
        options = f"-k {sockets} -c listen_addresses='' -c fsync=off"
        run_server_tool(
            *(binaries / "pg_ctl", "start", "-w", "-t", SERVER_START_TIMEOUT_S),
            *("-D", data, "-l", log, "-o", options),
            log=log,
        )
        server = PostgresServer(sockets)
        server.execute(f"CREATE ROLE {PASSWORD_ROLE} LOGIN PASSWORD '{PASSWORD}'")
        yield server
    finally:
        if (data / "postmaster.pid").exists():
            subprocess.run(as_server_user(binaries / "pg_ctl", "stop", "-w", "-m", "fast", "-D", data), check=False)
        shutil.rmtree(home, ignore_errors=True)


@pytest.fixture
def postgres_url(postgres_server) -> str:
    return postgres_server.url(postgres_server.new_database())


def test_a_new_database_is_migrated_to_the_newest_revision_the_models_declare(postgres_url):
    with Registry.open(postgres_url) as registry:
        assert set(inspect(registry.engine).get_table_names()) == {*Base.metadata.tables, "alembic_version"}
        with registry.engine.connect() as connection:
            assert connection.exec_driver_sql("SELECT version_num FROM alembic_version").scalars().all() == [
                newest_revision()
            ]
        with registry.engine.begin() as connection:
            command.check(alembic_config(connection))
            command.downgrade(alembic_config(connection), "base")
        assert inspect(registry.engine).get_table_names() == ["alembic_version"]
    with Registry.open(postgres_url) as registry, registry.reading() as session:
        assert session.scalars(select(Sensor)).all() == []
    # Alembic's own command line (env.py), as a developer writing a revision runs it.
    assert_alembic_check_passes(postgres_url)


def test_a_database_of_a_newer_schema_is_refused_in_one_line_and_left_as_it_was(postgres_url, cli_in_process):
    with Registry.open(postgres_url) as registry, registry.writing() as session:
        session.connection().exec_driver_sql("UPDATE alembic_version SET version_num = 'f00d'")
    result = cli_in_process("sensors", "--registry", postgres_url)
    assert_one_line_error(result, f"the registry {postgres_url} has schema revision f00d, which this thermotilt")
    engine = create_engine(postgres_url, poolclass=NullPool)
    with engine.connect() as connection:
        assert connection.exec_driver_sql("SELECT version_num FROM alembic_version").scalar() == "f00d"
    engine.dispose()


def uploaded_twice(fit_dir: Path) -> None:
    """What two uploads of fit_dir (saved, then --no-save) leave in its uploads.jsonl."""
    for saved in (True, False):
        board = SimpleNamespace(port="/dev/ttyUSB3", sensor_id="TT-A", firmware_version="0.4.1", saved=saved)
        record_upload(fit_dir, SimpleNamespace(**vars(board), coef_source="E" if saved else "U"))


def record_what_a_lab_made(lab: Path, url: str) -> None:
    """What campaign, fit, upload and validate record as they finish, in
    the order the lab made them (the commands' record, without running them;
    the uploads' lines are in the fit folder already, uploaded_twice)."""
    made = []
    for month in ("january", "june"):
        campaign, fit = lab / "campaigns" / f"TT-A-{month}", lab / "fits" / f"TT-A-{month}"
        made += [("campaign", "--twin", "--out", campaign), ("fit", campaign, "--out", fit)]
    made += [
        ("upload", lab / "fits" / "TT-A-june", "--port", "/dev/ttyUSB3"),
        ("upload", lab / "fits" / "TT-A-june", "--port", "/dev/ttyUSB3", "--no-save"),
        ("fit", lab / "campaigns" / "TT-A-june", "--out", lab / "fits" / "TT-B"),
        ("validate", lab / "field" / "TT-A-march" / "run.csv"),
        ("validate", lab / "field" / "TT-A-july" / "run.csv"),
    ]
    for args in made:
        assert record_made(parsed(*args, "--registry", url), 0) is None, args


def what_it_lists(url: str, cli_in_process) -> tuple[str, str, list[tuple]]:
    """`sensors`, `history TT-A` and the uploads recorded."""
    listings = [cli_in_process(*args, "--registry", url) for args in (("sensors",), ("history", "TT-A"))]
    assert [(result.returncode, result.stderr) for result in listings] == [(0, ""), (0, "")]
    with Registry.open(url) as registry, registry.reading() as session:
        uploads = session.scalars(select(Upload).order_by(Upload.id)).all()
    return (
        listings[0].stdout,
        listings[1].stdout,
        [(row.sensor_id, row.port, row.fit_folder, row.coefficients_sha256, row.saved) for row in uploads],
    )


def test_what_the_commands_record_lists_the_sensors_and_history_sqlite_lists(
    lab, tmp_path, postgres_url, cli_in_process
):
    listed = {}
    uploaded_twice(lab / "fits" / "TT-A-june")
    for url in (url_of(tmp_path / "registry.sqlite3"), postgres_url):
        record_what_a_lab_made(lab, url)
        listed[url] = what_it_lists(url, cli_in_process)
    on_sqlite, on_postgres = listed.values()
    assert on_postgres == on_sqlite
    sensors, history, uploads = on_postgres
    assert [line.split()[:2] for line in sensors.splitlines()[1:]] == [["TT-A", "2026-06-02"], ["TT-B", "-"]]
    assert history.startswith("sensor TT-A: 2 calibrations\n")
    assert [upload[-1] for upload in uploads] == [True, False]


def test_rebuild_from_the_folders_lists_the_sensors_sqlite_lists(
    lab, tmp_path, postgres_url, cli_in_process, monkeypatch
):
    # Language sorts TT-a before TT-B, characters after it.
    write_fit(lab / "fits" / "TT-a", "TT-a", None)
    monkeypatch.chdir(lab)
    sqlite_url = url_of(tmp_path / "registry.sqlite3")

    def sensors(url: str) -> str:
        return cli_in_process("sensors", "--interval-days", "400", "--registry", url).stdout

    # Recorded piecemeal first: the fits, then everything.
    for folder in ("fits", "."):
        assert cli_in_process("registry", "ingest", folder, "--registry", postgres_url).returncode == 0
    piecemeal = sensors(postgres_url)
    for url in (postgres_url, sqlite_url):
        rebuilt = cli_in_process("registry", "rebuild", ".", "--registry", url)
        assert rebuilt.returncode == 0 and "skipped 1 folder with files" in rebuilt.stdout, rebuilt.stdout
    assert sensors(postgres_url) == piecemeal == sensors(sqlite_url)
    assert [line.split()[0] for line in piecemeal.splitlines()[1:]] == ["TT-A", "TT-B", "TT-a"]


def eeprom_naming(sensor_id: str) -> bytes:
    """A twin board's EEPROM image holding only assign-id's record of sensor_id."""
    image = bytearray(b"\xff" * EEPROM_BYTES)
    record = encode_sensor_id_record(sensor_id)
    image[SENSOR_ID_RECORD_ADDRESS : SENSOR_ID_RECORD_ADDRESS + len(record)] = record
    return bytes(image)


@pytest.mark.parametrize("migrated", [False, True], ids=["a new database", "a migrated one"])
def test_two_processes_writing_at_once_lose_no_record(tmp_path, postgres_url, migrated):
    """As test_registry's SQLite test: both open the database at the same
    moment (a new one: one creates its tables, the other waits), then write
    a transaction per folder, interleaved. The sides' runs name the same
    sensors in the same order, so both try to add each new one at once
    (without the writers' lock, nearly every run here failed on one or the
    other: a table or a sensor added twice)."""
    runs = {
        side: [write_run(tmp_path / side / f"run-{index}", eeprom=eeprom_naming(f"TT-{index}")) for index in range(25)]
        for side in ("a", "b")
    }
    if migrated:
        Registry.open(postgres_url).close()
    ingest_from_two_processes_at_once(postgres_url, runs)
    with Registry.open(postgres_url) as registry, registry.reading() as session:
        recorded = set(session.scalars(select(BoardRun.folder)))
        sensors = set(session.scalars(select(Sensor.sensor_id)))
    assert recorded == {str(folder.resolve()) for folders in runs.values() for folder in folders}
    assert sensors == {f"TT-{index}" for index in range(25)}


@pytest.mark.parametrize(
    ("login", "query", "shown_login"),
    [
        (f"{PASSWORD_ROLE}:{PASSWORD}", "", f"{PASSWORD_ROLE}:***"),
        (PASSWORD_ROLE, f"&password={PASSWORD}", PASSWORD_ROLE),
    ],
    ids=["password after the user", "password in the query"],
)
def test_an_unreachable_server_is_one_line_without_the_password(
    tmp_path, lab, cli_in_process, login, query, shown_login
):
    no_server = f"postgresql+psycopg://{login}@/lab?host={tmp_path}{query}"
    shown = f"postgresql+psycopg://{shown_login}@/lab?host="
    result = cli_in_process("sensors", "--registry", no_server)
    assert_one_line_error(result, f"cannot open the registry {shown}")
    assert "Is the server running" in result.stderr and PASSWORD not in result.stderr
    # What a command made, recorded as it finishes: a warning of one line.
    warning = record_made(parsed("upload", lab / "fits" / "TT-B", "--port", "/dev/ttyUSB3", "--registry", no_server), 0)
    assert warning is not None and "\n" not in warning and PASSWORD not in warning
    assert warning.startswith(f"not recorded in the registry {shown}")


def test_bad_credentials_are_one_line_without_the_password(postgres_server, lab, cli_in_process):
    database = postgres_server.new_database(owner=PASSWORD_ROLE)
    wrong = postgres_server.url(database, PASSWORD_ROLE, "wrong-secret")
    result = cli_in_process("sensors", "--registry", wrong)
    assert_one_line_error(result, f'password authentication failed for user "{PASSWORD_ROLE}"')
    assert "wrong-secret" not in result.stderr
    rebuilt = cli_in_process(
        "registry", "rebuild", lab, "--registry", postgres_server.url(database, PASSWORD_ROLE, PASSWORD)
    )
    assert rebuilt.returncode == 0, rebuilt.stderr
    assert rebuilt.stdout.startswith(f"registry postgresql+psycopg://{PASSWORD_ROLE}:***@/{database}?host=")
    assert PASSWORD not in rebuilt.stdout
