"""What a folder is, from the files the commands write in it (their
writers are the calibration and run modules; nothing here writes them):

- a campaign: ``campaign.json`` (``calibration/campaign/folder.py``); its
  position folders are its own and not read apart;
- a fit: ``coefficients.json`` and ``coefficients.bin`` (``calibration/fit.py``),
  with ``certificate.json`` when it had a sensor ID (``certificate/issue.py``);
- a board run: ``run.csv`` with ``summary.json`` and, in the twin, the
  IMU's EEPROM image (``run/folder.py``), outside any campaign;
- a validation: ``validation.json`` in a run folder (``calibration/validate.py``).

A folder is read into the registry's rows (``schema``), not yet stored;
each row carries the sha256 of the files that define it. A file that
cannot be read or is not what its writer writes is a FolderError of one
line. ``upload`` appends what it put onto which board to the fit folder's
``uploads.jsonl`` (``calibration/upload_record.py``), read with the fit;
``assign-id`` writes no folder: what it leaves is the board's EEPROM, which
a twin run's image shows, and the row the command line records as it
finishes (``recording``).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, date, datetime
from pathlib import Path
from typing import Any

from ..calibration.campaign.folder import BATCH_FILE, CAMPAIGN_FILE, DONE, CampaignError, CampaignFolder
from ..run.folder import IMU_EEPROM_FILE, LOG_FILE, RunFolder
from ..run.summary import SUMMARY_FILE, RunSummaryError
from ..surfaces import sensor_id_problem
from ..wire.coefficients import (
    BLOCK_SIZES,
    SENSOR_ID_RECORD_ADDRESS,
    CoefficientBlockError,
    decode_block,
    encode_sensor_id_record,
)
from .schema import Artefact, BoardRun, Calibration, Campaign, Upload, Validation

# The names thermotilt fit and validate write these under (literals in their writers).
FIT_FILE = "coefficients.json"
COEFFICIENTS_BIN = "coefficients.bin"
VALIDATION_FILE = "validation.json"
DEFINING_FILES = frozenset({CAMPAIGN_FILE, FIT_FILE, VALIDATION_FILE, LOG_FILE})
UTC_STAMP = "%Y-%m-%dT%H:%M:%SZ"
KINDS = {Campaign: "campaign", Calibration: "fit", Validation: "validation", BoardRun: "board run"}


class FolderError(RuntimeError):
    """A folder or file that cannot be read, or a file that is not what its
    writer writes; one readable line."""


@dataclass
class Found:
    """The folders under some roots: those holding an artefact, with their
    file names, and those holding files that are none."""

    artefact_folders: list[tuple[Path, frozenset[str]]] = field(default_factory=list)
    unrecognised: list[Path] = field(default_factory=list)


def find_folders(roots: Sequence[Path], ignored: Iterable[Path] = ()) -> Found:
    """Every folder under roots (themselves included, each once) by what it
    holds. An artefact's subfolders are its own parts (a campaign's
    positions, a run's serial/ and validation/) and not visited, nor hidden
    ones (.partial); files in ignored (the registry's own database) count
    for nothing."""
    ignored = frozenset(ignored)
    found = Found()
    seen: set[Path] = set()
    for root in roots:
        if not root.is_dir():
            raise FolderError(f"{root}: {'not a folder' if root.exists() else 'no such folder'}")
        for folder, names in _walk(root, ignored):
            if folder in seen:
                continue
            seen.add(folder)
            if names & DEFINING_FILES:
                found.artefact_folders.append((folder, names))
            elif BATCH_FILE not in names:
                found.unrecognised.append(folder)
    return found


def _walk(root: Path, ignored: frozenset[Path]) -> Iterator[tuple[Path, frozenset[str]]]:
    def unreadable(error: OSError) -> None:
        raise FolderError(f"cannot read {error.filename}: {error.strerror or error}")

    for path, folders, files in os.walk(root, onerror=unreadable):
        folder = Path(path).resolve()
        names = frozenset(name for name in files if not name.startswith(".") and folder / name not in ignored)
        folders[:] = [] if names & DEFINING_FILES else sorted(name for name in folders if not name.startswith("."))
        if names:
            yield folder, names


def read_folder(folder: Path, names: frozenset[str]) -> list[Artefact]:
    """The artefacts a folder holds, as registry rows (folder resolved)."""
    folder = folder.resolve()
    if CAMPAIGN_FILE in names:
        return [read_campaign(folder)]
    artefacts: list[Artefact] = []
    if FIT_FILE in names:
        artefacts.append(read_fit(folder))
    # A run's board: the twin saves the IMU's EEPROM beside run.csv.
    board = _read_optional(folder / IMU_EEPROM_FILE) if names & {LOG_FILE, VALIDATION_FILE} else None
    if LOG_FILE in names:
        artefacts.append(read_board_run(folder, board))
    if VALIDATION_FILE in names:
        artefacts.append(read_validation(folder, board))
    return artefacts


def read_campaign(folder: Path) -> Campaign:
    # The certificate package loads the fit's statistics: only for a campaign or fit to read.
    from ..calibration.certificate.document import calibration_dates

    data, document = _json_object(folder / CAMPAIGN_FILE)
    positions = document.get("positions")
    if not isinstance(positions, list) or not all(isinstance(entry, dict) for entry in positions):
        raise FolderError(f"{folder / CAMPAIGN_FILE}: not a campaign file (no list of positions)")
    try:
        sensor_id = CampaignFolder(folder).recorded_sensor_id()
        dates = calibration_dates(document)
    except CampaignError as error:
        raise FolderError(str(error)) from None
    except (TypeError, ValueError) as error:
        raise FolderError(f"{folder / CAMPAIGN_FILE}: a position's time is not one ({error})") from None
    path = folder / CAMPAIGN_FILE
    firmware = {version for entry in positions for version in _mapping(entry, "firmware", path).values()}
    return Campaign(
        folder=str(folder),
        source_sha256=_digest({CAMPAIGN_FILE: data}),
        sensor_id=_sensor_id(sensor_id, path),
        rig=_text(document, "rig", path),
        created_utc=_utc(document.get("created_utc"), path),
        started_utc=_utc(dates["started_utc"], path),
        ended_utc=_utc(dates["ended_utc"], path),
        positions_planned=len(positions),
        positions_done=sum(entry.get("status") == DONE for entry in positions),
        program=_mapping(document, "program", path),
        firmware=sorted(str(version) for version in firmware),
        model=_optional_text(document, "model", path),
        seed=_optional_integer(document, "seed", path),
    )


def read_fit(folder: Path) -> Calibration:
    from ..calibration.certificate.issue import CERTIFICATE_JSON

    path = folder / FIT_FILE
    data, document = _json_object(path)
    sources = {FIT_FILE: data}
    coefficients = _read_optional(folder / COEFFICIENTS_BIN)
    if coefficients is not None:
        sources[COEFFICIENTS_BIN] = coefficients
    positions = document.get("positions")
    if not isinstance(positions, list):
        raise FolderError(f"{path}: not a coefficients.json written by thermotilt fit (no list of positions)")
    calibration = Calibration(
        folder=str(folder),
        sensor_id=_sensor_id(_optional_text(document, "sensor_id", path), path),
        coefficients_sha256=_sha256(coefficients) if coefficients is not None else None,
        positions=len(positions),
        domain=_mapping(document, "calibrated_domain", path),
    )
    certificate = folder / CERTIFICATE_JSON
    certificate_data = _read_optional(certificate)
    if certificate_data is not None:
        sources[CERTIFICATE_JSON] = certificate_data
        _add_certificate(calibration, certificate, _parsed_object(certificate_data, certificate))
    calibration.source_sha256 = _digest(sources)
    return calibration


def read_uploads(folder: Path) -> tuple[list[Upload], int]:
    """A fit folder's uploads as rows, and how many of its lines were not
    records (skipped, as a line cut short by a crash)."""
    from ..calibration.upload_record import read_uploads as read_records

    try:
        records, malformed = read_records(folder)
    except (OSError, UnicodeDecodeError) as error:
        raise FolderError(f"cannot read {folder}'s uploads: {getattr(error, 'strerror', None) or error}") from None
    rows = [
        Upload(
            uploaded_utc=record.uploaded_utc,
            sensor_id=record.sensor_id or None,
            port=record.port,
            fit_folder=str(folder),
            coefficients_sha256=record.coefficients_sha256,
            saved=record.saved,
        )
        for record in records
    ]
    return rows, malformed


def _add_certificate(calibration: Calibration, path: Path, certificate: dict[str, Any]) -> None:
    """The certificate's fields, once it is seen to be of these coefficients and this sensor."""
    stated = certificate.get("coefficients_sha256")
    if stated != calibration.coefficients_sha256:
        raise FolderError(
            f"{path}: states coefficients sha256 {stated}, but coefficients.bin beside it has "
            f"{calibration.coefficients_sha256}: the certificate is of other coefficients"
        )
    if _sensor_id(_optional_text(certificate, "sensor_id", path), path) != calibration.sensor_id:
        raise FolderError(f"{path}: its sensor_id is not the one coefficients.json beside it was fitted for")
    dates = _mapping(certificate, "calibration_dates", path)
    calibration.certificate_number = _text(certificate, "certificate_number", path)
    calibration.started_utc = _utc(dates.get("started_utc"), path)
    calibration.ended_utc = _utc(dates.get("ended_utc"), path)
    calibration.issue_date = _date(certificate.get("issue_date"), path)
    calibration.tilt_u95_deg = _optional_number(certificate, "tilt_u95_deg", path)
    calibration.u95_max_deg = _mapping(certificate, "u95_max_deg", path)
    calibration.domain = _mapping(certificate, "domain", path)
    calibration.campaign = _optional_text(certificate, "campaign", path)


def read_board_run(folder: Path, eeprom: bytes | None) -> BoardRun:
    try:
        summary = RunFolder.at(folder).summary()
    except RunSummaryError as error:
        raise FolderError(str(error)) from None
    sources = {SUMMARY_FILE: _read_optional(folder / SUMMARY_FILE) or b"", IMU_EEPROM_FILE: eeprom or b""}
    block = _eeprom_block(eeprom)
    imu = summary.boards.get("imu_reader") if summary is not None else None
    return BoardRun(
        folder=str(folder),
        source_sha256=_digest(sources),
        sensor_id=_board_sensor_id(eeprom),
        source=summary.source if summary else None,
        scenario=summary.scenario if summary else None,
        rows=summary.rows if summary else None,
        end_reason=summary.end_reason if summary else None,
        imu_firmware=imu.firmware if imu else None,
        eeprom_coefficients_sha256=block[0] if block else None,
        eeprom_fitted_for=block[1] if block else None,
    )


def read_validation(folder: Path, eeprom: bytes | None) -> Validation:
    path = folder / VALIDATION_FILE
    data, document = _json_object(path)
    try:
        modified = datetime.fromtimestamp(path.stat().st_mtime, UTC)
    except OSError as error:
        raise FolderError(f"cannot read {path}: {error.strerror or error}") from None
    return Validation(
        folder=str(folder),
        source_sha256=_digest({VALIDATION_FILE: data}),
        sensor_id=_board_sensor_id(eeprom),
        validated_utc=modified.replace(tzinfo=None, microsecond=0),
        tilt_change_p95_deg=_optional_number(document, "tilt_change_p95_deg", path),
        rows_within_u_share=_optional_number(document, "rows_within_u_share", path),
        tilt_error_p95_deg=_optional_number(document, "tilt_error_p95_deg", path),
        compensated_with=_text(document, "after_from", path),
    )


def _board_sensor_id(eeprom: bytes | None) -> str | None:
    """The ID in a twin IMU's EEPROM image (assign-id's record), if it holds one."""
    if eeprom is None:
        return None
    size = len(encode_sensor_id_record("A"))
    record = eeprom[SENSOR_ID_RECORD_ADDRESS : SENSOR_ID_RECORD_ADDRESS + size]
    # The record is its magic byte, the NUL-padded ID and a CRC-16: an ID
    # whose record, encoded again, is these bytes is the one it holds.
    candidate = record[1:-2].rstrip(b"\0").decode("ascii", errors="replace")
    if not candidate or sensor_id_problem(candidate) is not None:
        return None
    return candidate if encode_sensor_id_record(candidate) == record else None


def _eeprom_block(eeprom: bytes | None) -> tuple[str, str | None] | None:
    """The sha256 of the coefficient block an EEPROM image starts with and
    the sensor it was fitted for; None for an image without a valid block."""
    if eeprom is None or len(eeprom) < 2 or eeprom[1] not in BLOCK_SIZES:
        return None
    block = eeprom[: BLOCK_SIZES[eeprom[1]]]
    try:
        decoded = decode_block(block)
    except CoefficientBlockError:
        return None
    return _sha256(block), decoded.sensor_id or None


def _read_optional(path: Path) -> bytes | None:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as error:
        raise FolderError(f"cannot read {path}: {error.strerror or error}") from None


def _json_object(path: Path) -> tuple[bytes, dict[str, Any]]:
    data = _read_optional(path)
    if data is None:
        raise FolderError(f"cannot read {path}: no such file")
    return data, _parsed_object(data, path)


def _parsed_object(data: bytes, path: Path) -> dict[str, Any]:
    try:
        document = json.loads(data.decode("utf-8"))
    except UnicodeDecodeError as error:
        raise FolderError(f"{path}: not UTF-8 text (byte {error.start})") from None
    except ValueError as error:
        raise FolderError(f"{path}: not JSON ({error})") from None
    if not isinstance(document, dict):
        raise FolderError(f"{path}: not a JSON object")
    return document


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _digest(files: dict[str, bytes]) -> str:
    """One sha256 of named files' contents."""
    digest = hashlib.sha256()
    for name, data in sorted(files.items()):
        digest.update(f"{name}\0{_sha256(data)}\0".encode())
    return digest.hexdigest()


def _wrong(path: Path, key: str, value: Any, expected: str) -> FolderError:
    return FolderError(f"{path}: {key} is {value!r}, not {expected}")


def _text(document: dict[str, Any], key: str, path: Path) -> str:
    value = document.get(key)
    if not isinstance(value, str):
        raise _wrong(path, key, value, "text")
    return value


def _optional_text(document: dict[str, Any], key: str, path: Path) -> str | None:
    return None if document.get(key) is None else _text(document, key, path)


def _optional_number(document: dict[str, Any], key: str, path: Path) -> float | None:
    value = document.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _wrong(path, key, value, "a number")
    return float(value)


def _optional_integer(document: dict[str, Any], key: str, path: Path) -> int | None:
    value = document.get(key)
    if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
        raise _wrong(path, key, value, "a whole number")
    return value


def _mapping(document: dict[str, Any], key: str, path: Path) -> dict[str, Any]:
    value = document.get(key)
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise _wrong(path, key, value, "an object")
    return value


def _sensor_id(value: str | None, path: Path) -> str | None:
    """A sensor ID as the registry keeps it: None for none ("" in the files)."""
    if not value:
        return None
    problem = sensor_id_problem(value)
    if problem is not None:
        raise FolderError(f"{path}: {problem}")
    return value


def _utc(value: Any, path: Path) -> datetime | None:
    if value is None:
        return None
    try:
        return datetime.strptime(value, UTC_STAMP)
    except (TypeError, ValueError):
        raise FolderError(f"{path}: {value!r} is not a UTC time ({UTC_STAMP})") from None


def _date(value: Any, path: Path) -> date | None:
    if value is None:
        return None
    try:
        return date.fromisoformat(value)
    except (TypeError, ValueError):
        raise FolderError(f"{path}: {value!r} is not a date (YYYY-MM-DD)") from None
