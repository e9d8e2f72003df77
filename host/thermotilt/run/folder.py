"""A run folder and the names of what it holds (docs/run-log.md):

- ``run.csv``: one row per IMU frame (``thermotilt.run.log``);
- ``summary.json``: how the run was made and how it ended (``thermotilt.run.summary``);
- ``serial/``: every byte each board sent, one file per board;
- ``imu_reader_eeprom.bin``: the IMU's EEPROM at the end of a twin run.

Commands take a run as the folder or as its run.csv; both name the same run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .summary import SUMMARY_FILE, RunSummary, read_summary

LOG_FILE = "run.csv"
SERIAL_DIR = "serial"
IMU_EEPROM_FILE = "imu_reader_eeprom.bin"
# The boards, by the names their serial captures and summary reports carry.
IMU_BOARD = "imu_reader"
CHAMBER_BOARD = "thermal_chamber"


class RunFolderError(ValueError):
    """A path that holds no run; one readable line."""


@dataclass(frozen=True)
class RunFolder:
    """A run: its folder and its log (the folder's run.csv, or for a log
    kept under another name, e.g. a campaign's x15.csv, that file)."""

    path: Path
    log: Path

    @classmethod
    def at(cls, folder: Path | str) -> RunFolder:
        """The run a producer writes in folder."""
        folder = Path(folder)
        return cls(folder, folder / LOG_FILE)

    @classmethod
    def of(cls, path: Path | str) -> RunFolder:
        """The run a folder or its log names; RunFolderError when there is no run log."""
        path = Path(path)
        run = cls.at(path) if path.is_dir() else cls(path.parent, path)
        if not run.log.is_file():
            raise RunFolderError(f"{run.log}: no run log (a run folder with {LOG_FILE}, or a {LOG_FILE})")
        return run

    @property
    def name(self) -> str:
        """The folder's name for its run.csv, else the log's own name."""
        return self.path.name if self.log.name == LOG_FILE else self.log.stem

    @property
    def summary_path(self) -> Path:
        return self.path / SUMMARY_FILE

    @property
    def serial_dir(self) -> Path:
        return self.path / SERIAL_DIR

    @property
    def imu_eeprom(self) -> Path:
        return self.path / IMU_EEPROM_FILE

    def capture(self, board: str) -> Path:
        """The serial capture of IMU_BOARD or CHAMBER_BOARD."""
        return self.serial_dir / f"{board}.txt"

    def summary(self) -> RunSummary | None:
        """summary.json (read_summary), or None for a run without one (a
        log written by another tool, a run killed, a log under another
        name); RunSummaryError for one that cannot be read."""
        if self.log.name != LOG_FILE or not self.summary_path.exists():
            return None
        return read_summary(self.path)
