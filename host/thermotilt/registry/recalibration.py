"""A recalibration's previous calibration, from the registry: ``fit``
asks, for each sensor it certifies without ``--previous-fit``, for that
sensor's latest calibration whose campaign ended before this campaign
started; its certificate then carries the long-term stability component
(docs/calibration.md). A registry that cannot answer costs a warning and
the component, never the fit.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

from ..options import PROGRAM
from . import OFF, configured_url

if TYPE_CHECKING:
    from .database import Registry


def previous_fit_finder(args: argparse.Namespace) -> Callable[[str, datetime | None], Path | None] | None:
    """What ``fit`` asks for a sensor's previous calibration (None with
    the registry off); the database is opened only when asked."""
    url = configured_url(args.registry)
    if url == OFF:
        return None

    def find(sensor_id: str, started: datetime | None) -> Path | None:
        from .database import Registry, RegistryError, registry_url, shown

        try:
            with Registry.open(registry_url(args.registry)) as registry:
                return latest_fit_before(registry, sensor_id, started)
        except RegistryError as error:
            print(
                f"{PROGRAM}: warning: {sensor_id}'s previous calibration not looked up in the registry "
                f"{shown(url)}: {error.reason}",
                file=sys.stderr,
            )
            return None

    return find


def latest_fit_before(registry: Registry, sensor_id: str, started: datetime | None) -> Path | None:
    """The fit folder of sensor_id's latest calibration that ended before
    started (of any, without a start), whose folder still holds its fit."""
    from sqlalchemy import select

    from .schema import Calibration

    query = select(Calibration).where(Calibration.sensor_id == sensor_id, Calibration.ended_utc.is_not(None))
    if started is not None:
        query = query.where(Calibration.ended_utc < started)
    with registry.reading() as session:
        folders = [row.folder for row in session.scalars(query.order_by(Calibration.ended_utc.desc()))]
    return next((Path(folder) for folder in folders if (Path(folder) / "coefficients.json").is_file()), None)
