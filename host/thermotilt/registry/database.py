"""The registry's database: which one (``--registry URL``, else
``THERMOTILT_REGISTRY``, else ``runs/registry.sqlite3`` here), opening it
at the newest schema (Alembic, ``migrations/``), and its transactions.

SQLite runs in WAL mode, so readers never wait for a writer, and every
write transaction begins IMMEDIATE with a busy timeout: a second writer (a
second rig, a rebuild) waits for the first instead of failing, and no
transaction can find its snapshot stale when it starts to write.

PostgreSQL (a lab's rigs sharing one server) does the same with a lock:
every write transaction first takes one transaction-level advisory lock, so
writers run one after another, each at READ COMMITTED reading what the one
before committed; a reader sees one snapshot and waits for no one.
"""

from __future__ import annotations

import os
import sqlite3
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import URL, Connection, Engine, create_engine, event, inspect, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import DBAPIError, SQLAlchemyError
from sqlalchemy.orm import Session

from . import DEFAULT_FILE, ENVIRONMENT_VARIABLE, OFF, configured_url

if TYPE_CHECKING:
    from alembic.config import Config
    from alembic.script import ScriptDirectory

MIGRATIONS = Path(__file__).resolve().parent / "migrations"
# Alembic's table of the revision a database is at.
VERSION_TABLE = "alembic_version"
# How long a writer waits for another's transaction to end (SQLite's busy
# timeout, PostgreSQL's lock timeout): a rebuild of a lab's folders writes
# for well under this.
BUSY_TIMEOUT_MS = 60_000
WAL_RETRY_S = 0.01
# SQLite's files beside a database.
SQLITE_COMPANIONS = ("", "-wal", "-shm", "-journal")
# The key of the PostgreSQL advisory lock every write transaction takes (any
# constant; advisory locks are per database): "ttreg" in ASCII.
POSTGRES_WRITE_LOCK = 0x74_74_72_65_67
# How long a PostgreSQL connection may take before the registry counts as
# unreachable (libpq's default is to wait as long as the network does).
POSTGRES_CONNECT_TIMEOUT_S = 10
# The execution option that marks a write transaction's connection.
_WRITER = "thermotilt_registry_writer"


class RegistryError(RuntimeError):
    """A registry that cannot be opened or written; one readable line.
    reason is what went wrong without the registry's name."""

    def __init__(self, message: str, reason: str | None = None) -> None:
        super().__init__(message)
        self.reason = reason or message


def registry_url(option: str | None = None) -> str:
    """The database URL: the option, else the environment's, else the SQLite
    file in ./runs (made if missing)."""
    url = configured_url(option)
    if url == OFF:
        raise RegistryError(
            f"the registry is off ({ENVIRONMENT_VARIABLE}={OFF}): give --registry URL to read one",
            "the registry is off",
        )
    if not option and not os.environ.get(ENVIRONMENT_VARIABLE):
        folder = Path.cwd() / DEFAULT_FILE.parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise RegistryError(f"cannot create {folder}: {error.strerror or error}") from None
    return url


def shown(url: str) -> str:
    """The URL as messages show it: as given, but without a password (after
    the user's name, or in the query as libpq also takes it)."""
    try:
        parsed = make_url(url)
    except SQLAlchemyError:
        return url
    if parsed.password is None and "password" not in parsed.query:
        return url
    return parsed.difference_update_query(["password"]).render_as_string(hide_password=True)


def reason(error: BaseException) -> str:
    """What went wrong, in one line: the driver's message (libpq's has a
    hint on a line of its own), else SQLAlchemy's first line."""
    if isinstance(error, DBAPIError) and error.orig is not None:
        return "; ".join(line.strip() for line in str(error.orig).splitlines() if line.strip())
    return str(error).splitlines()[0] if str(error) else type(error).__name__


def newest_revision() -> str:
    """The newest revision's ID, from the revisions' file names (0001_...,
    0002_...; test_registry_recording.py holds it to Alembic's head) without loading Alembic."""
    return max(path.name.partition("_")[0] for path in (MIGRATIONS / "versions").glob("[0-9][0-9][0-9][0-9]_*.py"))


def alembic_config(connection: Connection | None = None) -> Config:
    """Alembic's configuration for the packaged migrations; with a
    connection, env.py migrates through it."""
    from alembic.config import Config

    # Alembic's default stdout is the one at its import, which may be closed by now (a test's capture).
    config = Config(stdout=sys.stdout)
    config.set_main_option("script_location", str(MIGRATIONS))
    config.attributes["connection"] = connection
    return config


def _use_wal(cursor: Any) -> None:
    """WAL mode, waiting for another process as the busy timeout would:
    switching takes the file's exclusive lock, and SQLite answers BUSY at
    once instead of calling the busy handler, so two processes opening a
    new file together would fail (about half of 200 tries here). WAL then
    stays set in the file."""
    deadline = time.monotonic() + BUSY_TIMEOUT_MS / 1000.0
    while True:
        try:
            cursor.execute("PRAGMA journal_mode = WAL")
            return
        except sqlite3.OperationalError as error:
            if "locked" not in str(error) or time.monotonic() > deadline:
                raise
            time.sleep(WAL_RETRY_S)


def create_registry_engine(url: str) -> Engine:
    """An engine for url: for SQLite, WAL, the busy timeout and SQLAlchemy's
    own BEGIN; for PostgreSQL, READ COMMITTED and the writers' lock."""
    parsed = make_url(url)
    if parsed.get_backend_name() == "postgresql":
        # The lock serialises writers only if each statement after it reads
        # what was committed before it, whatever the server's default isolation.
        engine = create_engine(parsed, isolation_level="READ COMMITTED", connect_args=_postgres_connect_args(parsed))
        _lock_postgres_writers(engine)
    else:
        engine = create_engine(parsed)
        if engine.dialect.name == "sqlite":
            _configure_sqlite(engine)
    return engine


def _configure_sqlite(engine: Engine) -> None:
    @event.listens_for(engine, "connect")
    def configure(dbapi_connection: Any, _record: Any) -> None:
        # sqlite3 would BEGIN by itself, deferred and not before DDL; the begin hook does.
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute(f"PRAGMA busy_timeout = {BUSY_TIMEOUT_MS}")
        _use_wal(cursor)
        cursor.execute("PRAGMA foreign_keys = ON")
        cursor.close()

    @event.listens_for(engine, "begin")
    def begin(connection: Connection) -> None:
        mode = "IMMEDIATE" if connection.get_execution_options().get(_WRITER) else "DEFERRED"
        connection.exec_driver_sql(f"BEGIN {mode}")


def _lock_postgres_writers(engine: Engine) -> None:
    """Every write transaction begins by taking one advisory lock, released
    at its end: writers wait for each other as SQLite's BEGIN IMMEDIATE
    makes them, so ingest's look-then-insert of sensors and folders (unique
    keys) never meets another's uncommitted rows, a migration runs once, and
    no transaction is retried. Simpler than INSERT ... ON CONFLICT, which
    would not cover the updates, a rebuild's deletes or a migration, and
    than SERIALIZABLE, whose failures would replay a whole ingestion."""

    @event.listens_for(engine, "begin")
    def begin(connection: Connection) -> None:
        if connection.get_execution_options().get(_WRITER):
            connection.exec_driver_sql(f"SET LOCAL lock_timeout = {BUSY_TIMEOUT_MS}")
            connection.exec_driver_sql(f"SELECT pg_advisory_xact_lock({POSTGRES_WRITE_LOCK})")


def _postgres_connect_args(url: URL) -> dict[str, Any]:
    """psycopg's connect_timeout unless the URL sets one: a lab server that
    is down is then one line within seconds, not minutes of TCP retries."""
    if url.get_driver_name() not in ("psycopg", "psycopg2") or "connect_timeout" in url.query:
        return {}
    return {"connect_timeout": POSTGRES_CONNECT_TIMEOUT_S}


class Registry:
    """An open registry at its newest schema; ``writing()`` and
    ``reading()`` give a session in one transaction."""

    def __init__(self, url: str, engine: Engine) -> None:
        self.url = url
        self.engine = engine
        self._writer = engine.execution_options(**{_WRITER: True})
        # PostgreSQL's readers see one snapshot, as SQLite's do (a read-only
        # transaction is never refused at REPEATABLE READ).
        postgres = engine.dialect.name == "postgresql"
        self._reader = engine.execution_options(isolation_level="REPEATABLE READ") if postgres else engine

    @classmethod
    def open(cls, url: str) -> Registry:
        """The registry at url, upgraded to the newest schema; RegistryError,
        one line, for a URL that names no database this can open, or one
        whose schema is newer than this thermotilt's."""
        try:
            registry = cls(url, create_registry_engine(url))
        except (SQLAlchemyError, ImportError) as error:
            raise RegistryError(f"cannot open the registry {shown(url)}: {reason(error)}", reason(error)) from None
        try:
            registry._upgrade()
        except BaseException:
            registry.close()
            raise
        return registry

    def __enter__(self) -> Registry:
        return self

    def __exit__(self, *_exception: object) -> None:
        self.close()

    def close(self) -> None:
        self.engine.dispose()

    @property
    def shown_url(self) -> str:
        return shown(self.url)

    def database_files(self) -> frozenset[Path]:
        """The files of a SQLite registry (none for a server's)."""
        database = self.engine.url.database
        if self.engine.dialect.name != "sqlite" or not database or database == ":memory:":
            return frozenset()
        path = Path(database).resolve()
        return frozenset(path.with_name(path.name + suffix) for suffix in SQLITE_COMPANIONS)

    def _upgrade(self) -> None:
        """Alembic's upgrade to head, in one write transaction: two processes
        opening a new registry at once create its tables once. A registry at
        the newest revision is only read (Alembic is not even loaded: a
        command's record costs that much less)."""
        try:
            if self._revisions() == {newest_revision()}:
                return
        except (SQLAlchemyError, ImportError) as error:
            raise RegistryError(f"cannot open the registry {self.shown_url}: {reason(error)}", reason(error)) from None
        from alembic import command
        from alembic.script import ScriptDirectory
        from alembic.util import CommandError

        try:
            with self._writer.begin() as connection:
                config = alembic_config(connection)
                self._refuse_newer(connection, ScriptDirectory.from_config(config))
                command.upgrade(config, "head")
        except (SQLAlchemyError, CommandError, ImportError) as error:
            raise RegistryError(f"cannot open the registry {self.shown_url}: {reason(error)}", reason(error)) from None

    def _revisions(self) -> set[str]:
        """The revisions the database is at (none for a new one)."""
        with self.engine.connect() as connection:
            if not inspect(connection).has_table(VERSION_TABLE):
                return set()
            return set(connection.execute(text(f"SELECT version_num FROM {VERSION_TABLE}")).scalars())

    def _refuse_newer(self, connection: Connection, scripts: ScriptDirectory) -> None:
        from alembic.runtime.migration import MigrationContext

        known = {script.revision for script in scripts.walk_revisions()}
        current = MigrationContext.configure(connection).get_current_heads()
        unknown = [revision for revision in current if revision not in known]
        if unknown:
            why = f"schema revision {', '.join(unknown)}, which this thermotilt does not know (a newer thermotilt wrote it)"
            raise RegistryError(f"the registry {self.shown_url} has {why}; use that version or another --registry", why)

    @contextmanager
    def writing(self) -> Iterator[Session]:
        """A session whose transaction holds the write lock from its start; committed at the end."""
        with self._session(self._writer) as session:
            yield session

    @contextmanager
    def reading(self) -> Iterator[Session]:
        with self._session(self._reader) as session:
            yield session

    @contextmanager
    def _session(self, engine: Engine) -> Iterator[Session]:
        try:
            # Rows stay readable after the transaction, as plain values.
            with Session(engine, expire_on_commit=False) as session, session.begin():
                yield session
        except SQLAlchemyError as error:
            raise RegistryError(f"registry {self.shown_url}: {reason(error)}", reason(error)) from None
