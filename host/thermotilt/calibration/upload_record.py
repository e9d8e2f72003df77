"""What went onto which board: each upload that ended well appends one JSON
line to its fit folder's uploads.jsonl (docs/calibration.md, "Uploading").
The fit folder stays the source of truth, so the registry rebuilds its
uploads from these lines like everything else it holds.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

UPLOADS_FILE = "uploads.jsonl"
COEFFICIENTS_BIN = "coefficients.bin"
STAMP = "%Y-%m-%dT%H:%M:%SZ"


@dataclass(frozen=True)
class UploadRecord:
    uploaded_utc: datetime
    port: str
    sensor_id: str  # "" for a fit made for no sensor
    coefficients_sha256: str | None  # coefficients.bin's as it was when uploaded
    firmware: str
    saved: bool
    coef_source: str  # what the board said it runs after the upload: E from EEPROM, U uploaded to RAM

    def line(self) -> str:
        fields = asdict(self) | {"uploaded_utc": self.uploaded_utc.strftime(STAMP)}
        return json.dumps(fields, sort_keys=True)

    @classmethod
    def parse(cls, line: str) -> UploadRecord:
        """One line of uploads.jsonl; ValueError for one that is not."""
        fields: dict[str, Any] = json.loads(line)
        if not isinstance(fields, dict):
            raise ValueError("not an object")
        try:
            return cls(
                datetime.strptime(fields["uploaded_utc"], STAMP),
                str(fields["port"]),
                str(fields["sensor_id"]),
                fields["coefficients_sha256"],
                str(fields["firmware"]),
                bool(fields["saved"]),
                str(fields["coef_source"]),
            )
        except (KeyError, TypeError) as error:
            raise ValueError(f"missing or wrong field {error}") from None


def record_upload(fit_dir: Path, result: Any, when: datetime | None = None) -> Path:
    """Appends the upload ``result`` (upload.UploadResult) to FIT_DIR's
    uploads.jsonl; OSError when the folder cannot take it."""
    block = fit_dir / COEFFICIENTS_BIN
    record = UploadRecord(
        (when or datetime.now(UTC)).replace(tzinfo=None, microsecond=0),
        result.port,
        result.sensor_id,
        hashlib.sha256(block.read_bytes()).hexdigest() if block.is_file() else None,
        result.firmware_version,
        result.saved,
        result.coef_source,
    )
    path = fit_dir / UPLOADS_FILE
    with path.open("a", encoding="utf-8") as stream:
        stream.write(record.line() + "\n")
    return path


def read_uploads(fit_dir: Path) -> tuple[list[UploadRecord], int]:
    """FIT_DIR's uploads, oldest first, and how many lines were not records
    (skipped: a line cut short by a crash loses only itself)."""
    path = fit_dir / UPLOADS_FILE
    if not path.is_file():
        return [], 0
    records, malformed = [], 0
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.strip():
            continue
        try:
            records.append(UploadRecord.parse(line))
        except ValueError:
            malformed += 1
    return records, malformed
