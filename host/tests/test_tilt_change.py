"""The change of tilt from the installation reading (calibration/tilt_change)
and `validate`'s use of it: the reading a monitoring user takes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_validate import write_field_log

from thermotilt import cli
from thermotilt.calibration.dataset import CalibrationDataError
from thermotilt.calibration.tilt_change import format_tilt_change, tilt_change
from thermotilt.lsm9ds0 import LSB_PER_G, MG_PER_LSB, tilt_deg

TIME_S = np.arange(0.0, 600.0, 0.1)
TEMPERATURE_C = 20.0 + TIME_S / 60.0


def change_of(compensated, outside=None, baseline_s=None, u95=None):
    outside = outside or {axis: np.zeros(len(TIME_S), dtype=bool) for axis in "XY"}
    return tilt_change(TIME_S, TEMPERATURE_C, compensated, outside, baseline_s, u95, "test")


def test_the_change_is_taken_from_the_first_settled_minute():
    # X steps by 100 LSB at 300 s; Y is still. The installation minute is
    # 120..180 s (run.SETTLE_S after the first row), before the step.
    x = np.where(TIME_S < 300.0, -1823.0, -1723.0)
    change = change_of({"X": x, "Y": np.full(len(TIME_S), -143.0)})
    assert change.installation.start_s == 120.0 and change.installation.reading_lsb["X"] == -1823.0
    assert change.axis("X").p95_lsb == pytest.approx(100.0)
    assert change.axis("X").p95_mg == pytest.approx(100.0 * MG_PER_LSB)
    expected = float(tilt_deg(np.array(-1723.0)) - tilt_deg(np.array(-1823.0)))
    assert change.axis("X").p95_deg == pytest.approx(expected) and change.axis("X").max_deg == pytest.approx(expected)
    assert change.axis("Y").p95_deg == 0.0
    # Half the rows (300..600 s) changed by `expected`, so the pooled p95 is it.
    assert change.p95_deg == pytest.approx(expected)


def test_the_installation_reading_waits_until_the_sensors_set_is_known():
    # Still for 300 s, then 0.01 degC/s: a sensor that was in the cooling set
    # has crossed to the warming one 1.5 degC (COMP_SET_TRANSITION_C) later,
    # at 450 s; the device's blend, halfway at power-up, was there at 375 s.
    temperature = 20.0 + np.clip(TIME_S - 300.0, 0.0, None) * 0.01
    still = {"X": np.zeros(len(TIME_S)), "Y": np.zeros(len(TIME_S))}
    outside = {axis: np.zeros(len(TIME_S), dtype=bool) for axis in "XY"}
    change = tilt_change(TIME_S, temperature, still, outside, None, None, "test")
    assert change.installation.start_s == pytest.approx(450.0, abs=0.1) and change.installation.set_decided
    flat = tilt_change(TIME_S, np.full(len(TIME_S), 20.0), still, outside, None, None, "test")
    assert flat.installation.start_s == 120.0 and not flat.installation.set_decided
    assert "it was not: the temperature had not moved 1.5 degC one way" in format_tilt_change(flat)


def test_a_named_baseline_moves_the_installation_reading():
    # X reads -1723 from 300 s to 500 s; rows before the named 400 s are no change.
    x = np.where((TIME_S >= 300.0) & (TIME_S < 500.0), -1723.0, -1823.0)
    change = change_of({"X": x, "Y": np.zeros(len(TIME_S))}, baseline_s=400.0)
    assert change.installation.reading_lsb["X"] == -1723.0 and change.installation.named
    assert change.before_rows == np.count_nonzero(TIME_S < 400.0)
    assert change.axis("X").rows == np.count_nonzero(TIME_S >= 400.0)
    assert change.axis("X").p95_lsb == pytest.approx(100.0)
    with pytest.raises(CalibrationDataError, match=r"--baseline 900: 0 rows in 900\.\.960 s"):
        change_of({"X": x, "Y": x}, baseline_s=900.0)


def test_rows_outside_the_domain_are_apart_and_out_of_every_percentile():
    # The last 100 s read 1000 LSB off but lie outside the domain.
    far = TIME_S >= 500.0
    x = np.where(far, 0.0, -1823.0)
    change = change_of({"X": x, "Y": np.zeros(len(TIME_S))}, outside={"X": far, "Y": np.zeros(len(TIME_S), bool)})
    assert change.axis("X").outside_rows == np.count_nonzero(far)
    assert change.axis("X").rows == np.count_nonzero(TIME_S >= 120.0) - np.count_nonzero(far)
    assert change.axis("X").p95_lsb == 0.0 and change.p95_deg == 0.0


def test_the_share_within_u_is_held_row_by_row_at_its_own_u():
    # X drifts linearly by 0..0.1 deg of tilt near level; the certificate's U
    # is 0.05 deg: the rows after the drift passes 0.05 deg are outside it.
    drift_deg = np.linspace(0.0, 0.1, len(TIME_S))
    x = LSB_PER_G * np.sin(np.radians(drift_deg))
    asked = []

    def u95_for(installation_c: float) -> dict[str, np.ndarray]:
        asked.append(installation_c)
        return {axis: np.full(len(TIME_S), 0.05) for axis in "XY"}

    change = change_of({"X": x, "Y": np.zeros(len(TIME_S))}, u95=u95_for)
    installed = TIME_S >= 120.0
    # U is the certificate's for a change from an installation reading at the installation minute's temperature.
    assert asked == [pytest.approx(np.median(TEMPERATURE_C[installed & (TIME_S < 180.0)]))]
    held = np.abs(tilt_deg(x) - tilt_deg(np.array(np.median(x[installed & (TIME_S < 180)])))) <= 0.05
    held = held[installed]
    assert change.axis("X").within_u_share == pytest.approx(np.mean(held))
    assert change.axis("Y").within_u_share == 1.0
    assert change.within_u_share == pytest.approx((np.mean(held) + 1.0) / 2.0)


def test_an_installation_the_certificate_states_no_u_for_is_held_to_none_and_said():
    change = change_of(
        {"X": np.zeros(len(TIME_S)), "Y": np.zeros(len(TIME_S))},
        u95=lambda installation_c: {axis: np.full(len(TIME_S), np.nan) for axis in "XY"},
    )
    assert change.within_u_share is None and change.axis("X").u95_max_deg is None
    assert "the certificate states no U for an installation reading at 22.5 degC" in format_tilt_change(change)


def test_validate_writes_the_change_and_the_cli_refuses_a_baseline_without_rows(tmp_path, capsys):
    write_field_log(tmp_path / "run.csv", np.linspace(5.0, 15.0, 3000))
    assert cli.main(["validate", str(tmp_path / "run.csv"), "--baseline", "60", "--out", str(tmp_path / "v")]) == 0
    out = capsys.readouterr().out
    assert "change of tilt from the installation reading (named: 60..120 s" in out
    assert "paper's measure" not in out
    document = json.loads((tmp_path / "validation.json").read_text())
    assert document["tilt_change"]["installation"]["named"] is True
    assert document["set_switches"]["count"] == 0
    assert cli.main(["validate", str(tmp_path / "run.csv"), "--baseline", "5000"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--baseline 5000: 0 rows" in err[0]


def test_a_certificate_that_is_not_one_is_one_line(tmp_path, capsys):
    write_field_log(tmp_path / "run.csv", np.linspace(5.0, 15.0, 3000))
    (tmp_path / "cert.json").write_text("{}")
    assert cli.main(["validate", str(tmp_path / "run.csv"), "--certificate", str(tmp_path / "cert.json")]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a certificate with a U table" in err[0]
