"""`thermotilt fit`: residuals against each position's 25 degC reading,
surfaces fitted with statsmodels, bounds that survive autocorrelated rows,
and bad campaign folders as one readable line."""

from __future__ import annotations

import csv
import json
import sys
from importlib import resources

import numpy as np
import pytest
from child_process import THERMOTILT, run

from thermotilt.calibration.compare import compare, format_comparison, read_fit, reference_surfaces
from thermotilt.calibration.dataset import CalibrationDataError, SetData, load
from thermotilt.calibration.fit import fit_surface
from thermotilt.calibration.paper import PRINTING_ERRORS, TABLES
from thermotilt.run.log import COLUMNS
from thermotilt.surfaces import COEFFICIENT_NAMES, PAPER_DEFAULTS, Surface
from thermotilt.wire.coefficients import BLOCK_SIZE, decode_block

# A drift surface that is zero at 25 degC for every acceleration, as the
# residuals against a 25 degC reading are: Table 2's warming X temperature
# terms with an a-dependent slope.
TRUE = Surface(p00=-25 * -20.23 - 625 * -0.1044, p10=-20.23, p01=25 * 6.936e-5, p20=-0.1044, p11=-6.936e-5, p02=0.0)
ANGLES_DEG = (-45, -30, -15, 0, 15, 30, 45)
LSB_PER_G = 16393.44


def smooth_noise(rng, length: int, sigma: float, correlation_rows: int) -> np.ndarray:
    """Noise with the autocorrelation of a filtered log: a moving average."""
    white = rng.standard_normal(length + correlation_rows)
    kernel = np.ones(correlation_rows) / np.sqrt(correlation_rows)
    return sigma * np.convolve(white, kernel, mode="valid")[:length]


def synthetic_set(rng, rows_per_position: int = 800, correlation_rows: int = 40) -> SetData:
    temperatures, accelerations, residuals, positions = [], [], [], []
    for index, angle in enumerate(ANGLES_DEG):
        temperature = np.linspace(-10.0, 45.0, rows_per_position)
        acceleration = np.full(rows_per_position, LSB_PER_G * np.sin(np.radians(angle)))
        drift = np.array([TRUE.evaluate(t, a) for t, a in zip(temperature, acceleration)])
        temperatures.append(temperature)
        accelerations.append(acceleration)
        residuals.append(drift + smooth_noise(rng, rows_per_position, 5.0, correlation_rows))
        positions.append(np.full(rows_per_position, index))
    return SetData(
        np.concatenate(temperatures),
        {"X": np.concatenate(accelerations)},
        {"X": np.concatenate(residuals)},
        np.concatenate(positions),
    )


def test_hac_bounds_cover_the_truth_where_ols_bounds_do_not():
    # 30 campaigns with moving-average noise over 40 rows (4 s at 10 Hz): the
    # 95 % HAC bounds should hold the true coefficient about 95 % of the
    # time; the OLS bounds, which take the rows as independent, are too
    # narrow by about sqrt(40) and miss most of the time.
    rng = np.random.default_rng(7)
    covered = {"hac": 0, "ols": 0}
    trials = 0
    for _ in range(30):
        fit = fit_surface(synthetic_set(rng), "W", "X")
        for index, value in enumerate(TRUE):
            trials += 1
            covered["hac"] += fit.hac_bounds[index][0] <= value <= fit.hac_bounds[index][1]
            covered["ols"] += fit.ols_bounds[index][0] <= value <= fit.ols_bounds[index][1]
    # Binomial(180, 0.95) falls below 0.85 with probability < 0.01 %.
    assert covered["hac"] / trials >= 0.85
    assert covered["ols"] / trials <= 0.6


def test_fit_reports_the_statistics_cftool_gave_the_paper():
    fit = fit_surface(synthetic_set(np.random.default_rng(3)), "W", "X")
    assert fit.points == 7 * 800
    # The noise's standard deviation is 5 LSB; RMSE = sqrt(SSE / (n - 6)).
    assert fit.rmse == pytest.approx(5.0, rel=0.15)
    assert fit.sse == pytest.approx(fit.rmse**2 * (fit.points - 6))
    assert 0.99 < fit.adjusted_r_squared < fit.r_squared < 1.0
    assert fit.temperature_range_c == (-10.0, 45.0)
    assert fit.hac_lags >= 20
    for index, value in enumerate(TRUE):
        low, high = fit.hac_bounds[index]
        assert low < high
        assert abs(fit.surface[index] - value) <= 3 * (high - low) + 1e-12


def test_too_little_data_is_refused():
    rng = np.random.default_rng(1)
    tiny = synthetic_set(rng, rows_per_position=5)
    with pytest.raises(CalibrationDataError, match="at least 42 needed"):
        fit_surface(tiny, "W", "X")
    two = synthetic_set(rng)
    first_two = two.position < 2
    with pytest.raises(CalibrationDataError, match="at least 3 inclinations"):
        fit_surface(
            SetData(
                two.temperature_c[first_two],
                {"X": two.acceleration["X"][first_two]},
                {"X": two.residual["X"][first_two]},
                two.position[first_two],
            ),
            "W",
            "X",
        )
    flat = synthetic_set(rng)
    one_angle = SetData(
        flat.temperature_c, {"X": np.full_like(flat.temperature_c, 100.0)}, flat.residual, flat.position
    )
    with pytest.raises(CalibrationDataError, match="do not vary enough"):
        fit_surface(one_angle, "W", "X")


# ---- campaign folders -----------------------------------------------------


def nominal(angle_deg: float) -> tuple[float, float]:
    """The synthetic positions' X and Y accelerations without drift."""
    x = LSB_PER_G * np.sin(np.radians(angle_deg))
    return x, 0.5 * x


def write_run_log(
    path, angle_deg: float, temperatures, sets, drift=TRUE, blank_every: int = 0, chamber=None, cooling_shift=0.0
) -> None:
    """A run.csv of a position: the chamber running, filters settled, both
    axes carrying `drift` on top of offsets of 300 and -400 LSB, and
    cooling_shift more on the cooling rows (the measuring offset's change
    between the sets, paper section 4.1). `chamber`, one (phase,
    setpoint_c, inner_c) a row, writes the chamber's columns; without it the
    phase follows the set and they stay empty."""
    x, y = nominal(angle_deg)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for index, (temperature, set_name) in enumerate(zip(temperatures, sets)):
            row = {column: "" for column in COLUMNS}
            shift = cooling_shift if set_name == "C" else 0.0
            ax = x + 300.0 + shift + drift.evaluate(temperature, x)
            ay = y - 400.0 + shift + drift.evaluate(temperature, y)
            row.update(
                time_s=f"{index / 10:.3f}",
                phase="W" if set_name == "W" else "C",
                imu_temp_c=f"{temperature:.3f}",
                incl_x_deg=f"{angle_deg:.2f}",
                incl_y_deg="0.00",
                since_move_s=f"{200 + index / 10:.2f}",
                ax_filt=f"{ax:.2f}",
                ay_filt=f"{ay:.2f}",
                comp_set=set_name,
            )
            if chamber is not None:
                phase, setpoint, inner = chamber[index]
                row.update(phase=phase, setpoint_c=f"{setpoint:.2f}" if phase != "R" else "", chamber_c=f"{inner:.2f}")
            if blank_every and index % blank_every == 0:
                row["ax_filt"] = ""
            writer.writerow(row)


def cycle(rows: int = 1200):
    up = np.linspace(-10.0, 45.0, rows // 2)
    return np.concatenate([up, up[::-1]]), ["W"] * (rows // 2) + ["C"] * (rows // 2)


def test_residuals_are_taken_against_each_positions_25c_reading(tmp_path):
    temperatures, sets = cycle()
    for angle in ANGLES_DEG:
        write_run_log(tmp_path / f"pos{angle}" / "run.csv", angle, temperatures, sets)
    campaign = load(tmp_path)
    assert len(campaign.positions) == len(ANGLES_DEG)
    warming = campaign.sets["W"]
    # Offsets and tilt are gone, the drift is left (it is 0 at 25 degC).
    # Sorted by folder name: pos-15, pos-30, pos-45, pos0, pos15, ...
    angles = sorted(ANGLES_DEG, key=lambda angle: f"pos{angle}")
    for axis, offset in (("X", 0), ("Y", 1)):
        expected = np.array(
            [
                TRUE.evaluate(t, nominal(angles[index])[offset])
                for t, index in zip(warming.temperature_c, warming.position)
            ]
        )
        # The 25 degC reading is a line through +-1.5 degC of a curved drift:
        # p20 * 1.5^2 = 0.23 LSB off at most, plus the cells' 0.01 LSB.
        assert np.max(np.abs(warming.residual[axis] - expected)) < 0.3, axis


def test_both_sets_are_taken_against_one_reading_of_the_position(tmp_path):
    # Section 4.1's set offsets differ by ~34 LSB; referenced together, the
    # warming surface carries half of that below the position's reading and
    # the cooling surface half above, so the compensated reading is the same
    # whichever set the device is in.
    temperatures, sets = cycle()
    shift = 34.0
    for angle in ANGLES_DEG:
        write_run_log(tmp_path / f"pos{angle}" / "run.csv", angle, temperatures, sets, cooling_shift=shift)
    campaign = load(tmp_path)
    angles = sorted(ANGLES_DEG, key=lambda angle: f"pos{angle}")
    for set_name, half in (("W", -shift / 2), ("C", shift / 2)):
        data = campaign.sets[set_name]
        for axis, offset in (("X", 0), ("Y", 1)):
            expected = np.array(
                [
                    TRUE.evaluate(t, nominal(angles[index])[offset])
                    for t, index in zip(data.temperature_c, data.position)
                ]
            )
            # As above: 0.3 LSB for the 25 degC line through a curved drift.
            assert np.max(np.abs(data.residual[axis] - expected - half)) < 0.3, (set_name, axis)


def test_rows_before_the_chamber_first_reaches_its_setpoint_are_not_fitted(tmp_path):
    # Two programs in one log, as `simulate campaign` writes them: each first
    # pulls the face down from where it was (the lab, then a rest) at full
    # drive, while the program's warming half waits at -10 degC and the
    # cooling die puts the rows in the C set.
    temperatures, sets = cycle()
    staircase = [("W" if set_name == "W" else "C", t, t) for t, set_name in zip(temperatures, sets)]

    def program(from_c: float):
        pulldown = np.linspace(from_c, -9.5, 300)
        return [("W", -10.0, inner) for inner in pulldown], list(pulldown), ["C"] * len(pulldown)

    first, first_t, first_sets = program(22.0)
    second, second_t, second_sets = program(5.0)
    rest = [("R", 0.0, -5.0)] * 50
    chamber = first + staircase + rest + second + staircase
    write_run_log(
        tmp_path / "0" / "run.csv",
        0.0,
        [*first_t, *temperatures, *[-5.0] * len(rest), *second_t, *temperatures],
        [*first_sets, *sets, *["C"] * len(rest), *second_sets, *sets],
        chamber=chamber,
    )
    campaign = load(tmp_path)
    # Each program keeps its rows from the first within 1 degC of -10 degC on:
    # the pulldown's last rows (-9 .. -9.5 degC) and the staircase.
    arrived = int(np.count_nonzero(np.linspace(22.0, -9.5, 300) <= -9.0))
    arrived_second = int(np.count_nonzero(np.linspace(5.0, -9.5, 300) <= -9.0))
    assert 0 < arrived < arrived_second < 20
    assert len(campaign.sets["W"].temperature_c) == 2 * sets.count("W")
    assert len(campaign.sets["C"].temperature_c) == 2 * sets.count("C") + arrived + arrived_second
    assert campaign.stabilizing_rows == 2 * 300 - arrived - arrived_second


@pytest.mark.slow
def test_the_fit_command_writes_coefficients_block_and_header(tmp_path):
    temperatures, sets = cycle()
    campaign = tmp_path / "campaign"
    for angle in ANGLES_DEG:
        write_run_log(campaign / f"{angle}.csv", angle, temperatures, sets, blank_every=50)
    out = tmp_path / "fit"
    result = run(
        [*THERMOTILT, "fit", str(campaign), "--out", str(out)], capture_output=True, text=True, timeout=120, check=False
    )
    assert result.returncode == 0, result.stderr
    assert "7 positions" in result.stdout and "rows with empty cells skipped" in result.stdout
    assert "p11" in result.stdout and "RMSE" in result.stdout
    document = json.loads((out / "coefficients.json").read_text())
    fitted = document["fits"]["WX"]["coefficients"]
    # The regressor is the measured acceleration, which carries the 300 LSB
    # offset and the drift itself, so the fitted p11 of this noise-free log
    # sits ~0.1 % from the truth written in the nominal acceleration.
    assert fitted["p11"]["value"] == pytest.approx(TRUE.p11, rel=3e-3)
    assert set(fitted["p10"]) == {"value", "ols_95", "hac_95"}
    block = (out / "coefficients.bin").read_bytes()
    assert len(block) == BLOCK_SIZE
    stored = decode_block(block)
    table = stored.table
    assert table.surfaces[("W", "X")].p10 == pytest.approx(fitted["p10"]["value"], rel=1e-6)
    # No campaign.json: fitted for no particular sensor.
    assert stored.sensor_id == document["sensor_id"] == "" and "no particular sensor" in result.stdout
    # The calibrated domain: the fitted rows' ranges, rounded outwards to 0.01 degC and 1 LSB.
    for set_name in ("W", "C"):
        low, high = document["fits"][f"{set_name}X"]["temperature_range_c"]
        domain = stored.domain[set_name]
        assert low - 0.01 < domain.temperature_c[0] <= low and high <= domain.temperature_c[1] < high + 0.01
        for axis in ("X", "Y"):
            a_low, a_high = document["fits"][f"{set_name}{axis}"]["acceleration_range_lsb"]
            a_domain = domain.acceleration_lsb[axis]
            assert a_low - 1 < a_domain[0] <= a_low and a_high <= a_domain[1] < a_high + 1
        assert domain.acceleration_lsb["Z"] is None
        written = document["calibrated_domain"][set_name]
        assert tuple(written["temperature_c"]) == domain.temperature_c
        assert written["acceleration_lsb"] == {
            axis: list(bounds) if bounds else None for axis, bounds in domain.acceleration_lsb.items()
        }
    assert table.surfaces[("C", "Z")] == Surface(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    header = (out / "coefficients.h").read_text()
    assert "FITTED_COEFFICIENTS[2][3][6]" in header and f"{table.surfaces[('W', 'X')].p10:.9g}f" in header
    report = (out / "report.md").read_text()
    assert "RMSE" in report and "(drift.png)" in report and "(surfaces.png)" in report
    for figure in ("drift.png", "surfaces.png"):
        assert (out / figure).read_bytes().startswith(b"\x89PNG")
    # No sensor ID, no identified item: no certificate, and one line says so.
    assert not any(out.glob("certificate.*"))
    assert [line for line in result.stdout.splitlines() if "certificate" in line] == [
        "no certificate issued: the item has no sensor ID (a campaign.json that records it, or --sensor-id, gives one)"
    ]


def write_campaign_file(folder, sensor_ids):
    positions = [
        {"label": str(index), "status": "done", "sensor_id": sensor_id} for index, sensor_id in enumerate(sensor_ids)
    ]
    (folder / "campaign.json").write_text(json.dumps({"format": 1, "positions": positions}))


@pytest.mark.slow
def test_the_fit_is_for_the_sensor_the_campaign_recorded(tmp_path):
    temperatures, sets = cycle()
    campaign = tmp_path / "campaign"
    for angle in ANGLES_DEG[:4]:
        write_run_log(campaign / f"{angle}.csv", angle, temperatures, sets)
    write_campaign_file(campaign, ["NODE-07", "NODE-07", None])

    def fit(*options):
        out = tmp_path / f"fit{len(options)}"
        result = run([*THERMOTILT, "fit", str(campaign), "--out", str(out), *options], capture_output=True, text=True)
        return result, out

    result, out = fit()
    assert result.returncode == 0, result.stderr
    assert "fitted for sensor NODE-07" in result.stdout
    assert json.loads((out / "coefficients.json").read_text())["sensor_id"] == "NODE-07"
    assert decode_block((out / "coefficients.bin").read_bytes()).sensor_id == "NODE-07"

    result, _ = fit("--sensor-id", "NODE-08")
    assert result.returncode == 1 and len(result.stderr.splitlines()) == 1
    assert "--sensor-id NODE-08" in result.stderr and "NODE-07" in result.stderr

    result, _ = fit("--sensor-id", "NODE 8")
    assert result.returncode == 2 and "only letters, digits" in result.stderr.splitlines()[-1]

    write_campaign_file(campaign, ["NODE-07", "NODE-09"])
    result, _ = fit()
    assert result.returncode == 1 and len(result.stderr.splitlines()) == 1
    assert "'NODE-07', 'NODE-09'" in result.stderr

    # A campaign that recorded no ID (the twin's): --sensor-id names the sensor.
    write_campaign_file(campaign, [None])
    result, out = fit("--sensor-id", "NODE-08")
    assert result.returncode == 0, result.stderr
    assert decode_block((out / "coefficients.bin").read_bytes()).sensor_id == "NODE-08"

    # A recalibration names the sensor's previous fit; another sensor's is refused.
    first = tmp_path / "fit0"
    result, out = fit("--sensor-id", "NODE-07", "--previous-fit", str(first))
    assert result.returncode == 0, result.stderr
    previous = json.loads((out / "certificate.json").read_text())["previous_calibration"]
    assert previous["fit"] == str(first)
    result, _ = fit("--sensor-id", "NODE-08", "--previous-fit", str(first), "--axes", "X")
    assert result.returncode == 1 and len(result.stderr.splitlines()) == 1
    assert f"--previous-fit {first}: its fits are of NODE-07, not of NODE-08" in result.stderr


@pytest.mark.slow
@pytest.mark.parametrize(
    "make, message",
    [
        (lambda folder: folder.mkdir(), "no run log"),
        (
            lambda folder: write_run_log(folder / "warming.csv", 0.0, np.linspace(10, 45, 600), ["W"] * 600),
            "no settled rows of the C set",
        ),
        (lambda folder: write_run_log(folder / "warm.csv", 0.0, *cycle_without_25c()), "never crosses 25 degC"),
        (
            lambda folder: write_run_log(folder / "stuck.csv", 0.0, *cycle(), chamber=[("W", -10.0, 20.0)] * 1200),
            "never came within 1 degC of its program's setpoint",
        ),
        (
            lambda folder: (folder.mkdir(), (folder / "bad.csv").write_text("time_s,ax\n1,2\n")),
            "the header is not run.csv's",
        ),
    ],
    ids=["empty", "one-set", "no-25c", "never-reached", "not-a-run-log"],
)
def test_bad_campaign_folders_are_one_line(tmp_path, make, message):
    folder = tmp_path / "campaign"
    make(folder)
    result = run(
        [*THERMOTILT, "fit", str(folder), "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    assert message in result.stderr


def cycle_without_25c():
    temperatures, sets = cycle()
    return np.where(np.abs(temperatures - 25.0) < 3.0, 30.0, temperatures), sets


def test_the_papers_tables_are_the_firmwares_defaults():
    # Tables 2 and 3 as printed are what the firmware compensates with,
    # except Table 2's misprinted cooling p01, which the firmware takes as
    # printed too (docs/calibration.md).
    for (axis, set_name), published in TABLES.items():
        if axis not in ("X", "Y"):
            continue
        surface = PAPER_DEFAULTS.surfaces[(set_name, axis)]
        for term in COEFFICIENT_NAMES:
            assert getattr(surface, term) == pytest.approx(published.coefficients[term].value, rel=1e-6)
    printed = TABLES[("X", "C")].coefficients["p01"]
    assert not printed.lower <= printed.value <= printed.upper
    assert printed.lower <= PRINTING_ERRORS[("X", "C", "p01", "value")] <= printed.upper


# ---- thermotilt compare ---------------------------------------------------


def model_with_drift(path, surface: Surface) -> None:
    """The default model with `surface` as every X and Y drift surface."""
    text = resources.files("thermotilt").joinpath("models/default.toml").read_text()
    rows = ", ".join(f"{value!r}" for value in surface)
    table = (
        "{ "
        + ", ".join(
            f"{set_name} = {{ X = [{rows}], Y = [{rows}], Z = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0] }}"
            for set_name in ("W", "C")
        )
        + " }"
    )
    path.write_text(text.replace('coefficients = "paper"', f"coefficients = {table}", 1))


@pytest.mark.slow
def test_compare_against_the_model_that_made_the_data_finds_no_gap(tmp_path):
    temperatures, sets = cycle()
    campaign = tmp_path / "campaign"
    for angle in ANGLES_DEG:
        write_run_log(campaign / f"{angle}.csv", angle, temperatures, sets)
    fit_dir = tmp_path / "fit"
    assert (
        run(
            [*THERMOTILT, "fit", str(campaign), "--out", str(fit_dir)], capture_output=True, text=True, timeout=120
        ).returncode
        == 0
    )
    model = tmp_path / "model.toml"
    model_with_drift(model, TRUE)
    comparisons = {c.key: c for c in compare(read_fit(fit_dir), str(model))}
    assert set(comparisons) == {"WX", "CX", "WY", "CY"}
    # Noise-free data: only the regressor separates the fitted surface from
    # the truth. The fit is a function of the measured acceleration, which
    # carries the 300 LSB offset and the drift g (up to ~600 LSB); the truth
    # is written in the nominal one: p11 * T * (300 + g) = 7e-5 * 45 * 900,
    # at most ~2.8 LSB, about 1 LSB RMS over the domain.
    assert all(c.rms_lsb < 1.5 and c.max_lsb < 3.0 for c in comparisons.values())
    assert comparisons["WX"].temperature_range_c == (-10.0, 45.0)
    # Against the paper, whose X surface differs from TRUE in its terms in a.
    paper = {c.key: c for c in compare(read_fit(fit_dir), "paper")}
    assert paper["WX"].rms_lsb > 1.0 and paper["WX"].half_width_from == "paper"
    # The scatter beside Tables 2-3's RMSE; a model gives none to set it against.
    fitted = json.loads((fit_dir / "coefficients.json").read_text())["fits"]
    assert paper["CY"].fit_rmse_lsb == fitted["CY"]["rmse_lsb"] and paper["CY"].reference_rmse_lsb == 10.03
    assert comparisons["CY"].reference_rmse_lsb is None
    assert f"CY {fitted['CY']['rmse_lsb']:.2f} / 10.03 (" in format_comparison(list(paper.values()), "paper")
    assert "Tables 2-3" not in format_comparison(list(comparisons.values()), str(model))


def test_compare_uses_the_consistent_reading_of_table_2s_misprints():
    surfaces, widths = reference_surfaces("paper")
    assert surfaces["CX"].p01 == PRINTING_ERRORS[("X", "C", "p01", "value")]
    assert widths["CX"]["p02"] == pytest.approx((-7.144e-8 - -7.563e-8) / 2)


def test_a_batch_model_is_compared_through_the_fitted_sensor(tmp_path):
    from thermotilt.physics import Model
    from thermotilt.physics.document import write_model
    from thermotilt.physics.terms.sensor import coefficient_table_of

    drawn = Model.load().with_population(2, seed=2)
    write_model(drawn, tmp_path / "batch.toml")
    for sensor_id in drawn.sensor_ids:
        surfaces, widths = reference_surfaces(str(tmp_path / "batch.toml"), sensor_id)
        own = coefficient_table_of(drawn.for_sensor(sensor_id).terms["drift"]["coefficients"])
        assert surfaces["WX"] == own.surfaces[("W", "X")] and widths is None
    with pytest.raises(CalibrationDataError, match=r"lists a batch \(TT-01, TT-02\) and the fit names no sensor"):
        reference_surfaces(str(tmp_path / "batch.toml"))
    with pytest.raises(CalibrationDataError, match="no sensor 'NODE-07'"):
        reference_surfaces(str(tmp_path / "batch.toml"), "NODE-07")


def test_compare_refuses_what_fit_did_not_write(tmp_path):
    (tmp_path / "coefficients.json").write_text('{"fits": {"WX": {}}}')
    result = run([*THERMOTILT, "compare", str(tmp_path)], capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 1 and result.stderr.count("\n") == 1
    assert "not a coefficients.json written by thermotilt fit" in result.stderr


def test_many_short_positions_keep_their_hac_bounds(monkeypatch):
    # 38 positions of 50 rows: the lag window of a tenth of all rows (190)
    # would exceed every position's rows, which Newey-West within positions
    # cannot take (statsmodels: "all groups are empty taking lags").
    monkeypatch.setattr(sys.modules[__name__], "ANGLES_DEG", tuple(range(-45, 46, 5)) * 2)
    fit = fit_surface(synthetic_set(np.random.default_rng(1), rows_per_position=50), "W", "X")
    assert fit.hac_lags == 49
    assert all(low < high for low, high in fit.hac_bounds)
