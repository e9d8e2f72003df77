"""Each watched sensor's line of ``thermotilt sensors`` (registry/fleet.py):
its last calibration, U, fit, last validation and when it is due. A
sensor the registry does not know, a registry that is off, not made yet or
that cannot be read gives no line (the page shows a dash), never an error:
the live view only reads. A SQLite registry that does not exist is not
created."""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from pathlib import Path

from ..registry import OFF, configured_url
from ..registry.fleet import HEADER, Fleet, SensorLine

# The registry changes when a command records what it made: looked up again this often.
LOOKUP_EVERY_S = 30.0

RegistryLine = dict[str, str]
# The columns of a line after the sensor's ID, in the listing's order.
REGISTRY_COLUMNS = HEADER[1:]


def line_cells(listing: Fleet, line: SensorLine) -> RegistryLine:
    """One sensor's line as ``thermotilt sensors`` prints it, by its HEADER's column."""
    # Fleet formats a line's cells for the listing; the page shows the same text.
    return dict(zip(HEADER, listing.cells(line)))


def _missing_sqlite_file(url: str) -> bool:
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        parsed = make_url(url)
    except ArgumentError:
        return False
    database = parsed.database
    return (
        parsed.get_backend_name() == "sqlite"
        and bool(database)
        and database != ":memory:"
        and not Path(database).exists()
    )


def read_registry_lines(url: str, sensor_ids: Sequence[str]) -> dict[str, RegistryLine | None]:
    """The line of each sensor ID in the registry at url, None where it has none."""
    wanted = [sensor_id for sensor_id in sensor_ids if sensor_id]
    lines: dict[str, RegistryLine | None] = dict.fromkeys(sensor_ids)
    if not wanted or url == OFF or _missing_sqlite_file(url):
        return lines
    from ..registry.database import Registry, RegistryError
    from ..registry.fleet import fleet

    try:
        with Registry.open(url) as registry:
            listing = fleet(registry)
    except RegistryError:
        return lines
    known = {line.sensor_id: line for line in listing.lines}
    for sensor_id in wanted:
        if sensor_id in known:
            lines[sensor_id] = line_cells(listing, known[sensor_id])
    return lines


class RegistryLines:
    """read_registry_lines, asked again only when the sensors change or
    LOOKUP_EVERY_S has passed."""

    def __init__(self, url: str | None = None, every_s: float = LOOKUP_EVERY_S) -> None:
        self._url = configured_url(url)
        self._every_s = every_s
        self._lock = threading.Lock()
        self._asked: tuple[tuple[str, ...], float] | None = None
        self._lines: dict[str, RegistryLine | None] = {}

    def __call__(self, sensor_ids: Sequence[str]) -> dict[str, RegistryLine | None]:
        key = tuple(sensor_ids)
        with self._lock:
            now = time.monotonic()
            if self._asked is None or self._asked[0] != key or now - self._asked[1] >= self._every_s:
                self._lines = read_registry_lines(self._url, key)
                self._asked = (key, now)
            return dict(self._lines)
