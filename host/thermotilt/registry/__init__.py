"""The lab registry (docs/registry.md): every sensor's calibrations,
campaigns, validations and board runs in a database (SQLAlchemy, SQLite by
default, schema by Alembic), rebuilt from the folders the commands write,
which stay the source of truth. Importing this package loads nothing: its
commands import the database when they run."""

# How long after its last calibration a sensor is due for another (thermotilt sensors --interval-days).
DEFAULT_INTERVAL_DAYS = 365
