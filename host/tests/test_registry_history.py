"""``thermotilt history ID`` (thermotilt.registry.history, docs/registry.md):
a sensor's calibrations in the order they were made and, between
consecutive ones, the change of its drift surfaces over the domain both
calibrated, in LSB and degrees of tilt; one calibration, an unknown sensor
and a fit folder gone each answered in one line.

The second calibration is the first with every surface raised by a known
2 LSB and fitted over 0..40 degC only, written by the project's own
writers (fit.write_outputs, certify, write_certificate), so the expected
change is known without evaluating a surface here."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from test_certificate import fitted
from test_registry import JANUARY, JUNE, assert_one_line_error, url_of, write_campaign, write_fit

from thermotilt.calibration.certificate import certify, write_certificate
from thermotilt.calibration.compare import FittedSurface
from thermotilt.calibration.fit import write_outputs
from thermotilt.calibration.surface_change import surface_change
from thermotilt.calibration.upload_record import record_upload
from thermotilt.lsm9ds0 import LSB_PER_G
from thermotilt.registry.database import Registry
from thermotilt.registry.recalibration import latest_fit_before, previous_fit_finder
from thermotilt.surfaces import Surface

RAISED_LSB = 2.0
JUNE_FITTED_C = (0.0, 40.0)


@pytest.fixture(scope="module")
def history_lab(tmp_path_factory) -> Path:
    """TT-H calibrated in January and again in June (each campaign fitted
    and certified), June's surfaces January's raised by RAISED_LSB and
    fitted over JUNE_FITTED_C; TT-S fitted once, without a certificate."""
    lab = tmp_path_factory.mktemp("history-lab")
    campaign, january = fitted(5)
    june = [
        replace(fit, surface=fit.surface._replace(p00=fit.surface.p00 + RAISED_LSB), temperature_range_c=JUNE_FITTED_C)
        for fit in january
    ]
    for month, started, fits in (("january", JANUARY, january), ("june", JUNE, june)):
        campaign_dir, fit_dir = lab / "campaigns" / f"TT-H-{month}", lab / "fits" / f"TT-H-{month}"
        write_campaign(campaign_dir, "TT-H", started)
        write_outputs(fits, campaign, fit_dir, "TT-H")
        write_certificate(fit_dir, certify(campaign, fits, campaign_dir, "TT-H"))
    write_fit(lab / "fits" / "TT-S", "TT-S", None)
    return lab


@pytest.fixture
def recorded_lab(history_lab, tmp_path, cli_in_process) -> tuple[Path, str]:
    """A copy of the lab rebuilt into a registry of its own: (lab, --registry URL)."""
    lab, url = tmp_path / "lab", url_of(tmp_path / "registry.sqlite3")
    shutil.copytree(history_lab, lab)
    assert cli_in_process("registry", "rebuild", lab, "--registry", url).returncode == 0
    return lab, url


def test_history_shows_each_calibration_and_the_change_of_the_surfaces_between_them(
    recorded_lab, tmp_path, cli_in_process
):
    lab, url = recorded_lab
    result = cli_in_process("history", "TT-H", "--registry", url, "--out", tmp_path / "history")
    assert result.returncode == 0 and result.stderr == "", result.stderr
    lines = result.stdout.splitlines()
    assert lines[0] == "sensor TT-H: 2 calibrations"
    assert lines[2].startswith("2026-01-10  CAL-TT-H-") and lines[2].endswith(str(lab / "fits" / "TT-H-january"))
    assert lines[3].startswith("2026-06-02  CAL-TT-H-") and lines[3].endswith(str(lab / "fits" / "TT-H-june"))
    changes = [line.split() for line in lines if line.startswith("2026-01-10  2026-06-02")]
    # Only X was fitted: W X and C X, over June's 0..40 degC, by exactly the 2 LSB raised.
    assert [cells[2:5] + cells[6:8] for cells in changes] == [
        ["W", "X", "0..40"] + ["2", "+2"],
        ["C", "X", "0..40"] + ["2", "+2"],
    ]
    document = json.loads((tmp_path / "history" / "history.json").read_text())
    assert [entry["calibrated"] for entry in document["calibrations"]] == ["2026-01-10", "2026-06-02"]
    (change,) = document["changes"]
    assert set(change["surfaces"]) == {"WX", "CX"} and change["not_compared"] == {}
    january = json.loads((lab / "fits" / "TT-H-january" / "coefficients.json").read_text())["fits"]
    for key, surface in change["surfaces"].items():
        assert surface["temperature_c"] == list(JUNE_FITTED_C)
        assert surface["acceleration_lsb"] == january[key]["acceleration_range_lsb"]
        assert surface["rms_lsb"] == pytest.approx(RAISED_LSB) and surface["largest_lsb"] == pytest.approx(RAISED_LSB)
        # d tilt / d a = 1 / sqrt(LSB_PER_G^2 - a^2) rad per LSB: least level, most at the widest reading.
        widest = max(abs(bound) for bound in surface["acceleration_lsb"])
        level, steepest = (np.degrees(RAISED_LSB / np.sqrt(LSB_PER_G**2 - a**2)) for a in (0.0, widest))
        assert level < surface["rms_deg"] < surface["largest_deg"] == pytest.approx(steepest, rel=1e-3)
    assert (tmp_path / "history" / "history.png").read_bytes().startswith(b"\x89PNG")


def test_a_sensor_with_one_calibration_says_so_in_one_line(recorded_lab, cli_in_process):
    lab, url = recorded_lab
    result = cli_in_process("history", "TT-S", "--registry", url)
    assert (result.returncode, result.stderr) == (0, "")
    assert result.stdout == (
        f"sensor TT-S has one calibration (undated, no certificate, no U, fit {lab / 'fits' / 'TT-S'}): "
        "the change of its drift surfaces needs a second\n"
    )


def test_an_unknown_sensor_or_a_fit_folder_gone_is_one_line(recorded_lab, cli_in_process):
    lab, url = recorded_lab
    assert_one_line_error(cli_in_process("history", "TT-X", "--registry", url), "no sensor TT-X in the registry")
    shutil.rmtree(lab / "fits" / "TT-H-june")
    result = cli_in_process("history", "TT-H", "--registry", url)
    assert_one_line_error(result, f"{lab / 'fits' / 'TT-H-june' / 'coefficients.json'}: cannot read")
    assert "`thermotilt registry rebuild` records the folders as they are" in result.stderr


def test_the_change_is_taken_only_where_both_fits_calibrated():
    def fit(temperature_c, acceleration_lsb, p00=0.0):
        return FittedSurface(Surface(p00, 0.0, 0.0, 0.0, 0.0, 0.0), {}, temperature_c, acceleration_lsb, 1.0)

    change = surface_change("WX", fit((-20.0, 30.0), (-900.0, 500.0)), fit((5.0, 60.0), (-400.0, 800.0), 1.0))
    # compare's calibrated range is -10..45 degC at most.
    assert (change.temperature_c, change.acceleration_lsb) == ((5.0, 30.0), (-400.0, 500.0))
    assert change.rms_lsb == change.largest_lsb == 1.0
    assert surface_change("WX", fit((-10.0, 10.0), (0.0, 100.0)), fit((10.0, 45.0), (0.0, 100.0))) is None


def _uploaded(fit_dir: Path, when: datetime, saved: bool = True) -> None:
    """upload's record of fit_dir going onto TT-H's board (upload_record's line, as the command writes it)."""
    result = SimpleNamespace(port="/dev/ttyUSB0", sensor_id="TT-H", firmware_version="0.4.1", saved=saved)
    record_upload(fit_dir, SimpleNamespace(**vars(result), coef_source="E" if saved else "U"), when)


def test_the_fleet_shows_the_fit_each_board_runs_and_whether_it_is_the_latest(recorded_lab, cli_in_process):
    lab, url = recorded_lab

    def board_cell() -> str:
        listing = cli_in_process("sensors", "--registry", url).stdout.splitlines()
        header, line = listing[0], next(line for line in listing if line.startswith("TT-H "))
        start = header.index("fit on its board")
        return line[start : header.index("last validation")].strip()

    assert board_cell() == "-"
    _uploaded(lab / "fits" / "TT-H-january", datetime(2026, 1, 12))
    assert cli_in_process("registry", "ingest", lab / "fits", "--registry", url).returncode == 0
    assert board_cell() == f"{lab / 'fits' / 'TT-H-january'} (not the latest)"
    _uploaded(lab / "fits" / "TT-H-june", datetime(2026, 6, 3), saved=False)
    assert cli_in_process("registry", "ingest", lab / "fits", "--registry", url).returncode == 0
    assert board_cell() == f"{lab / 'fits' / 'TT-H-june'} (latest, RAM only)"


def test_a_recalibration_s_previous_fit_is_the_latest_that_ended_before_its_campaign_started(recorded_lab):
    lab, url = recorded_lab
    january, june = (lab / "fits" / f"TT-H-{month}" for month in ("january", "june"))
    june_started = datetime.strptime(
        json.loads((june / "certificate.json").read_text())["calibration_dates"]["started_utc"], "%Y-%m-%dT%H:%M:%SZ"
    )
    with Registry.open(url) as registry:
        assert latest_fit_before(registry, "TT-H", june_started) == january
        assert latest_fit_before(registry, "TT-H", datetime(2025, 1, 1)) is None
        assert latest_fit_before(registry, "TT-H", None) == june
        assert latest_fit_before(registry, "TT-X", None) is None
    # The registry off: fit asks nothing.
    assert previous_fit_finder(SimpleNamespace(registry="off")) is None
