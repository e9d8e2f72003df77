"""Alembic's environment for the registry: migrates through the connection
``thermotilt.registry.database`` hands it (the registry opening itself),
else, for Alembic's own command line (``alembic -c alembic.ini ...``, a
developer writing a revision), the registry that --registry's default names."""

from alembic import context
from sqlalchemy import Connection

from thermotilt.registry.database import create_registry_engine, registry_url
from thermotilt.registry.schema import Base


def run_migrations(connection: Connection) -> None:
    # SQLite alters a table by copying it; batch mode writes revisions that way.
    context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=True)
    with context.begin_transaction():
        context.run_migrations()


given = context.config.attributes.get("connection")
if given is not None:
    run_migrations(given)
else:
    engine = create_registry_engine(registry_url())
    try:
        with engine.begin() as connection:
            run_migrations(connection)
    finally:
        engine.dispose()
