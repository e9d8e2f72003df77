"""``thermotilt validate``: the paper's field RMS before and after
compensation (section 4.3), the fitted range warning, the report, bad input
as one line, and the host's surface evaluation against the firmware's."""

import csv
import json

import numpy as np
import pytest
from child_process import THERMOTILT, run

from thermotilt import cli
from thermotilt.calibration.validate import (
    BOARD_DOMAIN,
    AxisResult,
    Validation,
    format_validation,
    load_coefficients,
    range_warnings,
    validate,
)
from thermotilt.run.log import COLUMNS, read_run_log
from thermotilt.surfaces import PAPER_DEFAULTS

WARMING_X = PAPER_DEFAULTS.surface("W", "X")
OFFSET_X, OFFSET_Y = -1823.0, -143.0


def write_field_log(
    path, temperatures, set_name="W", compensated=True, blank_every=0, source="D", flag=None, columns=COLUMNS
):
    """A horizontal sensor whose X drifts as Table 2's warming surface and
    whose Y drifts linearly by -10 LSB/degC; ax_comp as the firmware would
    give it with the paper's coefficients. flag: the board's temp_domain of
    a temperature (None: none written)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns, lineterminator="\n", extrasaction="ignore")
        writer.writeheader()
        for index, temperature in enumerate(temperatures):
            ax = OFFSET_X + WARMING_X.evaluate(temperature, OFFSET_X) - WARMING_X.evaluate(25.0, OFFSET_X)
            ay = OFFSET_Y - 10.0 * (temperature - 25.0)
            row = {column: "" for column in columns}
            row.update(
                time_s=f"{index / 10:.3f}",
                imu_temp_c=f"{temperature:.3f}",
                comp_set=set_name,
                coef_source=source,
                temp_domain=flag(temperature) if flag else "",
                incl_x_deg="0.00",
                incl_y_deg="0.00",
                ax_filt=f"{ax:.1f}",
                ay_filt=f"{ay:.1f}",
                ax_comp=f"{OFFSET_X if compensated else ax:.1f}",
                ay_comp=f"{OFFSET_Y if compensated else ay:.1f}",
            )
            if blank_every and index % blank_every == 0:
                row["ax_filt"] = ""
            writer.writerow(row)


def test_rms_is_taken_about_the_25c_reading(tmp_path):
    temperatures = np.linspace(9.0, 48.0, 2000)
    write_field_log(tmp_path / "run.csv", temperatures)
    validation = validate(tmp_path)
    x, y = validation.result("W", "X"), validation.result("W", "Y")
    relative = temperatures - 25.0
    # Y is a line: its 25 degC reading is exact, its RMS that of -10 (T - 25).
    # The cells hold 0.1 LSB, so the RMS is known to 0.05 LSB.
    assert y.rms_before_lsb == pytest.approx(10.0 * np.sqrt(np.mean(relative**2)), abs=0.05)
    expected_x = np.sqrt(
        np.mean((WARMING_X.evaluate(temperatures, OFFSET_X) - WARMING_X.evaluate(25.0, OFFSET_X)) ** 2)
    )
    # X is curved: a line through +-1.5 degC reads p20 * 1.5^2 / 3 = 0.08 LSB off at 25 degC on average.
    assert x.rms_before_lsb == pytest.approx(expected_x, abs=0.3)
    assert x.rms_after_lsb == pytest.approx(0.0, abs=0.05)
    assert y.rms_after_lsb == pytest.approx(0.0, abs=0.05)
    # Table 2's surface fits -10..45 degC: 9..48 degC leaves 3 / 39 of the rows above it.
    assert x.outside_rows == pytest.approx(2000 * 3 / 39, abs=2)


def test_coefficients_from_eeprom_are_checked_against_the_boards_own_range(tmp_path):
    """The host knows no range for a block the board loaded; the board flags
    each row (temp_domain, docs/protocol.md), and those flags are counted."""
    temperatures = np.linspace(9.0, 48.0, 2000)
    write_field_log(tmp_path / "run.csv", temperatures, source="E", flag=lambda t: "O" if t > 40.0 else "I")
    validation = validate(tmp_path)
    outside = int(np.count_nonzero(temperatures > 40.0))
    assert validation.domain_source == BOARD_DOMAIN
    assert [result.outside_rows for result in validation.results] == [outside, outside]
    assert f"{outside} of 2000 warming rows" in range_warnings(validation)[0]


@pytest.mark.parametrize("log", ["flags unknown", "log from before temp_domain"])
def test_without_the_boards_flags_the_range_of_eeprom_coefficients_is_unknown(tmp_path, log):
    temperatures = np.linspace(9.0, 48.0, 200)
    if log == "flags unknown":
        write_field_log(tmp_path / "run.csv", temperatures, source="E", flag=lambda t: "U")
    else:
        before = tuple(column for column in COLUMNS if column != "temp_domain")
        write_field_log(tmp_path / "run.csv", temperatures, source="E", columns=before)
    validation = validate(tmp_path)
    assert validation.domain_source is None
    assert "fitted range is unknown" in range_warnings(validation)[0]


def test_the_tilt_error_is_in_degrees_about_the_25c_tilt(tmp_path, capsys):
    temperatures = np.linspace(9.0, 48.0, 2000)
    write_field_log(tmp_path / "run.csv", temperatures)
    validation = validate(tmp_path)
    # Y alone: a line about -143 LSB, so its 25 degC tilt is asin(-143 / 16393)
    # (0.061 mg/LSB, the LSM9DS0 at +-2 g) and each row's that of its reading.
    g = 1000.0 / 0.061
    error = np.degrees(np.arcsin((OFFSET_Y - 10.0 * (temperatures - 25.0)) / g) - np.arcsin(OFFSET_Y / g))
    # Rows above the paper's 45 degC lie outside the coefficients' domain and
    # out of every percentile. The cells hold 0.1 LSB: 0.05 LSB is 0.0002 deg.
    inside = temperatures <= 45.0
    assert validation.result("W", "Y").tilt_error_p95_before_deg == pytest.approx(
        np.percentile(np.abs(error[inside]), 95), abs=2e-4
    )
    assert validation.tilt_error_p95_deg == pytest.approx(0.0, abs=2e-4)
    assert cli.main(["validate", str(tmp_path), "--paper", "--out", str(tmp_path / "v")]) == 0
    document = json.loads((tmp_path / "validation.json").read_text())
    assert document["tilt_error_p95_deg"] == pytest.approx(0.0, abs=2e-4)
    y = next(r for r in document["results"] if r["axis"] == "Y")
    assert y["rms_before_mg"] == pytest.approx(0.061 * y["rms_before_lsb"])
    assert "tilt error after compensation, X and Y" in capsys.readouterr().out


def test_coefficients_given_are_applied_here(tmp_path):
    temperatures = np.linspace(9.0, 48.0, 2000)
    write_field_log(tmp_path / "run.csv", temperatures, compensated=False)
    assert validate(tmp_path).result("W", "X").rms_after_lsb > 100
    here = validate(tmp_path, load_coefficients("paper"))
    # The log's X is Table 2's drift, so Table 2 removes it, but evaluated at
    # the measured acceleration, which carries the drift itself (<= 420 LSB
    # here): |df/da| = |p01 + p11 T| <= 0.0018 over 9..48 degC gives <= 0.76
    # LSB, plus the 25 degC reference line's 0.3 (the test above).
    assert here.result("W", "X").rms_after_lsb < 0.76 + 0.3
    assert "compensated here with paper" in here.after_from


def test_a_set_that_never_nears_25c_has_no_rms_but_has_a_change(tmp_path, capsys):
    # A winter site: no 25 degC reading for the paper's measure, but the
    # change from the installation reading is there (the firmware's output
    # is constant here, so it is zero).
    write_field_log(tmp_path / "run.csv", np.linspace(5.0, 15.0, 3000))
    assert cli.main(["validate", str(tmp_path / "run.csv"), "--paper", "--out", str(tmp_path / "v")]) == 0
    stdout = capsys.readouterr().out
    assert "n/a" in stdout and "never come within 1.5 degC of 25 degC" in stdout
    document = json.loads((tmp_path / "validation.json").read_text())
    assert document["tilt_change_p95_deg"] == 0.0
    assert document["tilt_change"]["installation"]["start_s"] == 120.0


def test_the_report_has_the_table_and_the_figure(tmp_path, capsys):
    write_field_log(tmp_path / "run" / "run.csv", np.linspace(9.0, 48.0, 800), blank_every=100)
    assert cli.main(["validate", str(tmp_path / "run")]) == 0
    stdout = capsys.readouterr().out
    assert "8 rows with empty cells skipped" in stdout
    assert "warning: X: " in stdout and "the surface is extrapolated there" in stdout
    report = (tmp_path / "run" / "validation" / "report.md").read_text()
    assert "RMS about each set's 25 degC reading" in report and "![before and after compensation](field.png)" in report
    assert (tmp_path / "run" / "validation" / "field.png").read_bytes().startswith(b"\x89PNG")


@pytest.mark.slow
@pytest.mark.parametrize(
    "make, arguments, status, message",
    [
        # A run without a log is an argument error, found before anything heavy is imported.
        (lambda folder: None, [], 2, "no run log"),
        (lambda folder: (folder / "run.csv").write_text("time_s,ax\n1,2\n"), [], 1, "the header is not run.csv's"),
        (lambda folder: (folder / "run.csv").write_text(",".join(COLUMNS) + "\n1,2\n"), [], 1, "row 1 has 2 cells"),
        (lambda folder: write_field_log(folder / "run.csv", [20.0, 25.0], set_name=""), [], 1, "no row with"),
        (
            lambda folder: write_field_log(folder / "run.csv", [20.0, 25.0]),
            ["--coefficients", "nofit"],
            1,
            "nofit/coefficients.json: cannot read",
        ),
    ],
)
def test_bad_validate_input_is_one_line(tmp_path, make, arguments, status, message):
    folder = tmp_path / "run"
    folder.mkdir()
    make(folder)
    result = run(
        [*THERMOTILT, "validate", str(folder), *arguments],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=tmp_path,
    )
    assert result.returncode == status
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    assert message in result.stderr


@pytest.mark.slow
@pytest.mark.twin
def test_host_compensation_equals_the_firmwares(tmp_path):
    """One surface evaluation, two implementations: the twin's firmware
    (lib/Compensation, float32, with the paper's defaults) and the host's
    (float64) on the same printed rows."""
    out = tmp_path / "field"
    result = run(
        [*THERMOTILT, "simulate", "field-warming", "--duration", "300", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    firmware = validate(out)
    host = validate(out, load_coefficients("paper"))
    rows = read_run_log(str(out / "run.csv"))
    assert {row["coef_source"] for row in rows} == {"D"}
    for axis in ("X", "Y"):
        difference = host.series[f"{axis} after"] - firmware.series[f"{axis} after"]
        # The host starts from the printed filtered value (0.05 LSB) and
        # temperature (0.0005 degC x ~25 LSB/degC), the firmware's output is
        # printed to 0.05 LSB, and float32 adds < 0.01 LSB (Compensation.cpp).
        assert np.nanmax(np.abs(difference)) <= 0.05 + 0.0125 + 0.05 + 0.01, axis
        assert host.result("W", axis).rms_after_lsb == pytest.approx(firmware.result("W", axis).rms_after_lsb, abs=0.1)
    assert host.firmware_difference_lsb <= 0.05 + 0.0125 + 0.05 + 0.01
    assert host.sources == "coef_source D"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scenario"] == "field-warming"


def test_the_papers_figures_stand_beside_the_set_its_test_used():
    results = [AxisResult("W", "X", 200, 7.8, 26.1, 0, 0.02, 0.09), AxisResult("C", "X", 3000, 121.8, 2.1, 0)]
    validation = Validation("run.csv", 3200, 0, (16.0, 26.0), "the firmware's output", "coef_source E", None, results)
    table = format_validation(validation, {("C", "X"): (122.0, 4.0)}).splitlines()
    warming = next(line for line in table if line.startswith("warming"))
    cooling = next(line for line in table if line.startswith("cooling"))
    assert warming.split() == ["warming", "X", "200", "7.8", "26.1", "0.0200", "0.0900"]
    assert cooling.split() == ["cooling", "X", "3000", "121.8", "2.1", "n/a", "n/a", "122", "4"]


def test_a_switch_between_the_sets_is_measured_as_the_step_of_the_compensated_reading(tmp_path):
    # 10 Hz: warming until 300 s, cooling until 340 s (too close to the next
    # switch to be measured), warming again until 700 s, then cooling to
    # 900 s. The compensated X reads 5 LSB more while cooling; Y the same.
    rows = []
    for index in range(9000):
        time_s = index / 10
        cooling = 300 <= time_s < 340 or time_s >= 700
        rows.append((time_s, "C" if cooling else "W", OFFSET_X + (5.0 if cooling else 0.0), OFFSET_Y))
    with open(tmp_path / "run.csv", "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=COLUMNS, lineterminator="\n", extrasaction="ignore")
        writer.writeheader()
        for time_s, set_name, ax, ay in rows:
            row = {column: "" for column in COLUMNS}
            row.update(
                time_s=f"{time_s:.3f}",
                imu_temp_c="25.000",
                comp_set=set_name,
                coef_source="E",
                ax_filt=f"{ax:.1f}",
                ay_filt=f"{ay:.1f}",
                ax_comp=f"{ax:.1f}",
                ay_comp=f"{ay:.1f}",
            )
            writer.writerow(row)
    validation = validate(tmp_path)
    assert [(switch.time_s, switch.to_set) for switch in validation.switches] == [(700.0, "C")]
    (switch,) = validation.switches
    assert switch.step_lsb == {"X": pytest.approx(5.0), "Y": pytest.approx(0.0)}
    # 5 LSB at -1823 LSB (-6.4 deg): 5 / (16393.4 cos 6.4 deg) rad.
    assert switch.step_deg["X"] == pytest.approx(
        np.degrees(5.0 / (16393.44 * np.cos(np.arcsin(1823 / 16393.44)))), rel=1e-3
    )
    document = validation.document()["set_switches"]
    assert document["count"] == 1 and document["largest_step_lsb"] == {"X": pytest.approx(5.0), "Y": pytest.approx(0.0)}
