"""The fields of a calibration certificate a laboratory signs (ISO/IEC
17025:2017 section 7.8.2.1, 7.8.4.1): its number, the laboratory and the
customer, the item, the procedure and software, the dates, the chamber's
program, the references' traceability, the conversion formula, the
validity conditions and the statements every certificate carries.

What only the laboratory knows (its name and address, the customer, the
references' traceability, who authorises the certificate) comes from an
optional ``lab.toml`` beside the campaign (or in its parent folder, for a
batch), and otherwise reads as a field for the laboratory to fill in.
"""

from __future__ import annotations

import hashlib
import json
import re
import time
import tomllib
from datetime import datetime, timedelta
from pathlib import Path

from ... import __version__
from ...lsm9ds0 import LSB_PER_G, MG_PER_LSB

LAB_FILE = "lab.toml"
MODEL = "LSM9DS0"
PROCEDURE_ID = "TT-CAL-TILT-01"
TO_FILL = "(to be filled in by the laboratory)"
LAB_FIELDS = {
    "name": "Laboratory",
    "address": "Laboratory address",
    "customer": "Customer",
    "customer_address": "Customer address",
    "tilt_reference": "Tilt reference and its traceability",
    "temperature_reference": "Temperature reference and its traceability",
    "item_condition": "Condition of the item on receipt",
    "authorised_by": "Authorised by (name, function)",
}
STATEMENTS = (
    "The results relate only to the item calibrated.",
    "This certificate shall not be reproduced except in full without the laboratory's written approval.",
    "The expanded uncertainty U is the standard uncertainty multiplied by the coverage factor k, which for "
    "a t-distribution with the effective degrees of freedom stated corresponds to a coverage probability of "
    "approximately 95 % (JCGM 100:2008).",
)
END_MARKER = "End of certificate"


def laboratory(campaign_dir: Path) -> dict[str, str]:
    """lab.toml's fields (beside the campaign, else in its parent), each
    one it lacks marked for the laboratory to fill in."""
    fields = dict.fromkeys(LAB_FIELDS, TO_FILL)
    for folder in (campaign_dir, campaign_dir.parent):
        path = folder / LAB_FILE
        if path.is_file():
            try:
                found = tomllib.loads(path.read_text(encoding="utf-8"))
            except (OSError, tomllib.TOMLDecodeError):
                break
            fields.update({key: str(value) for key, value in found.items() if key in LAB_FIELDS})
            break
    return fields


def campaign_record(campaign_dir: Path) -> dict:
    """campaign.json, or {} where the folder has none (a logged run)."""
    try:
        return json.loads((campaign_dir / "campaign.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}


def _utc(text: str) -> datetime | None:
    try:
        return datetime.strptime(text, "%Y-%m-%dT%H:%M:%SZ")
    except (TypeError, ValueError):
        return None


def calibration_dates(record: dict) -> dict[str, str | None]:
    """When the first position started and the last one ended (campaign.json)."""
    starts, ends = [], []
    for position in record.get("positions", []):
        start = _utc(position.get("started_utc"))
        if start is not None:
            starts.append(start)
            ends.append(start + timedelta(seconds=float(position.get("wall_seconds") or 0.0)))
    stamp = "%Y-%m-%dT%H:%M:%SZ"
    return {
        "started_utc": min(starts).strftime(stamp) if starts else record.get("created_utc"),
        "ended_utc": max(ends).strftime(stamp) if ends else None,
    }


def chamber_program(record: dict) -> dict:
    """The staircase campaign.json recorded, with one line that says it."""
    program = record.get("program")
    if not program:
        return {"description": "not recorded (no campaign.json): see the run logs' setpoint_c"}
    description = (
        f"{program.get('start_c')} -> {program.get('max_c')} -> {program.get('start_c')} degC in "
        f"{program.get('step_c')} degC steps, each held {program.get('hold_s')} s "
        f"(hold start {program.get('hold_start')}), rest {program.get('rest_s')} s; "
        f"ambient {program.get('ambient_c') if program.get('ambient_c') is not None else 'not recorded'}"
    )
    return {**program, "rig": record.get("rig"), "description": description}


def firmware(record: dict) -> list[str]:
    return sorted(
        {
            f"{board}: {version}"
            for position in record.get("positions", [])
            for board, version in (position.get("firmware") or {}).items()
        }
    )


def item(sensor_id: str, record: dict, lab: dict[str, str], axes: list[str]) -> dict:
    return {
        "model": MODEL,
        "description": f"{MODEL} iNEMO inertial module's accelerometer, axes {', '.join(axes)}, on a ThermoTilt "
        "IMU reader compensating its thermal drift with the surfaces of this calibration",
        "sensor_id": sensor_id,
        "firmware": firmware(record),
        "condition": lab["item_condition"],
    }


def procedure() -> dict:
    return {
        "id": PROCEDURE_ID,
        "software": f"thermotilt {__version__}",
        "description": "thermal-drift calibration after Sensors 2018, 18, 2536 (sections 3-4): a Peltier chamber "
        "on a tilt table runs a temperature staircase at each tilt position; 2nd-order surfaces f(T, a) per "
        "axis, warming and cooling, fitted by OLS; the device compensates a - f(T, a) (docs/calibration.md)",
    }


def conversion(zero_readings: dict[str, float]) -> dict:
    return {
        "formula": "tilt = asin((a_comp - a_zero) / S), S = 1 g = 16393.44 LSB (0.061 mg/LSB at +-2 g), as "
        "lsm9ds0.tilt_deg converts a reading once the zero reading a_zero is taken off",
        "lsb_per_g": LSB_PER_G,
        "mg_per_lsb": MG_PER_LSB,
        "zero_reading_lsb": zero_readings,
        "zero_reading_note": "per axis, the mean over positions of the reference reading less S sin(nominal "
        "angle): the measuring offset (paper section 4.1), estimated from this campaign",
    }


def validity(domain: dict, rate_limit_c_per_min: float) -> list[str]:
    tilts = "; ".join(f"{axis} {low:+g} to {high:+g} deg" for axis, (low, high) in domain["tilt_deg"].items())
    low_c, high_c = domain["temperature_c"]
    return [
        f"IMU-indicated temperature {low_c:.1f} to {high_c:.1f} degC at the installation reading and at the "
        f"reading; nominal tilt {tilts} (the table's angles).",
        "The installation reading taken once the device's set is decided: after the temperature has moved "
        "the set transition one way since power-up.",
        "Static tilt: readings of the Kalman-filtered output at rest, no vibration or shock.",
        f"IMU temperature changing at most {rate_limit_c_per_min:g} degC/min.",
        "The item compensating with the coefficients whose sha256 this certificate states.",
        "Not covered: a change of tilt between readings (the sensitivity's scale over the change), "
        "long-term bias drift, hysteresis beyond the warming/cooling sets, shocks, and the Z axis.",
    ]


def issue_fields(document: dict, coefficients: bytes) -> dict:
    """The fields that exist only once coefficients.bin is written: its
    sha256, the issue date, the certificate number built from both and the
    sensor ID (unique per item, day and coefficient block)."""
    digest = hashlib.sha256(coefficients).hexdigest()
    issued = time.gmtime()
    sensor = re.sub(r"[^A-Za-z0-9_-]", "", document["item"]["sensor_id"]) or "NOID"
    return {
        "certificate_number": f"CAL-{sensor}-{time.strftime('%Y%m%d', issued)}-{digest[:8].upper()}",
        "issue_date": time.strftime("%Y-%m-%d", issued),
        "issued_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", issued),
        "coefficients_sha256": digest,
    }
