"""The lab registry (docs/registry.md): every sensor's calibrations,
campaigns, validations and board runs in a database (SQLAlchemy, SQLite by
default, schema by Alembic), rebuilt from the folders the commands write,
which stay the source of truth. Importing this package loads nothing: its
commands import the database when they run, and the command line records
what a command made only after it ran (``recording``)."""

import os
from pathlib import Path

# Where the registry is when --registry does not say (database.registry_url).
ENVIRONMENT_VARIABLE = "THERMOTILT_REGISTRY"
DEFAULT_FILE = Path("runs") / "registry.sqlite3"
# The URL that turns the registry off: the commands record nothing.
OFF = "off"

# How long after its last calibration a sensor is due for another (thermotilt sensors --interval-days).
DEFAULT_INTERVAL_DAYS = 365


def configured_url(option: str | None = None) -> str:
    """The URL the option, else the environment, else the default names
    (possibly OFF), without making anything or loading the database."""
    return option or os.environ.get(ENVIRONMENT_VARIABLE) or f"sqlite:///{Path.cwd() / DEFAULT_FILE}"
