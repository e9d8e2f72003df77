"""The calibration certificate (calibration/certificate/): U per axis by
bands of IMU temperature and nominal tilt, its mounting-to-mounting
component out of sample (leave one position out), a budget with the Type B
components, and the fields and files a laboratory's certificate has."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from test_calibration_fit import ANGLES_DEG, TRUE, smooth_noise

from thermotilt.calibration.certificate import NotCertifiable, certify, in_domain, u95_at, write_certificate
from thermotilt.calibration.certificate.budget import two_significant_text, two_significant_up
from thermotilt.calibration.certificate.domain import band_index
from thermotilt.calibration.certificate.errors import left_out_predictions
from thermotilt.calibration.certificate.stability import PreviousCalibration
from thermotilt.calibration.compare import FittedSurface, read_fit
from thermotilt.calibration.dataset import CalibrationDataError, Campaign, SetData
from thermotilt.calibration.fit import design, fit_surface, write_outputs
from thermotilt.calibration.fitting import NO_ID_REASON, SensorFit
from thermotilt.calibration.surface_change import stability_bound, surface_change
from thermotilt.calibration.validate import tilt_deg
from thermotilt.lsm9ds0 import LSB_PER_G
from thermotilt.surfaces import Surface

ROWS = 800
OFFSET_LSB = -1823.0
# Each mounting's drift slope differs by N(0, SLOPE_SPREAD) LSB/degC (the
# twin's drift_repeatability); the sets' offsets are +-SET_OFFSET_LSB about
# the position's reference, as dataset's one reference per position leaves them.
SLOPE_SPREAD = 0.4
SET_OFFSET_LSB = 15.0
TYPE_B = (
    "temperature reading shift",
    "rate and lag",
    "set selection at turnarounds",
    "set offset estimate",
    "resolution",
    "sensitivity tolerance",
    "sensitivity change with temperature",
    "long-term stability",
)


def mounted_set(rng, slopes: np.ndarray, set_offset: float) -> SetData:
    """A set's rows over the paper's 7 X angles: the drift TRUE plus each
    mounting's own slope about 25 degC, the set's offset and filtered noise."""
    temperatures, accelerations, residuals, positions = [], [], [], []
    temperature = np.linspace(-10.0, 45.0, ROWS)
    for index, angle in enumerate(ANGLES_DEG):
        reading = OFFSET_LSB + LSB_PER_G * np.sin(np.radians(angle))
        drift = TRUE.evaluate(temperature, reading) + slopes[index] * (temperature - 25.0) + set_offset
        temperatures.append(temperature)
        accelerations.append(reading + drift)
        residuals.append(drift + smooth_noise(rng, ROWS, 5.0, 40))
        positions.append(np.full(ROWS, index))
    # Y lies level throughout (the fit's report draws both axes; the tests fit X).
    level = {"X": np.concatenate(accelerations), "Y": np.concatenate(residuals) - 126.0}
    return SetData(
        np.concatenate(temperatures),
        level,
        {"X": np.concatenate(residuals), "Y": np.concatenate(residuals)},
        np.concatenate(positions),
    )


def campaign_of(rng) -> Campaign:
    slopes = rng.normal(0.0, SLOPE_SPREAD, len(ANGLES_DEG))
    sets = {"W": mounted_set(rng, slopes, SET_OFFSET_LSB), "C": mounted_set(rng, slopes, -SET_OFFSET_LSB)}
    labels = tuple(f"p{index} (x {angle}.00 deg, y 0.00 deg)" for index, angle in enumerate(ANGLES_DEG))
    return Campaign(labels, sets, 0)


def fitted(seed: int):
    campaign = campaign_of(np.random.default_rng(seed))
    return campaign, [fit_surface(campaign.sets[s], s, "X") for s in ("W", "C")]


@pytest.fixture(scope="module")
def issued(tmp_path_factory):
    """One campaign certified and written, with its coefficients.bin."""
    campaign, fits = fitted(5)
    out = tmp_path_factory.mktemp("fit")
    certification = certify(campaign, fits, out, "TT-A")
    write_outputs(fits, campaign, out, "TT-A")
    write_certificate(out, certification)
    return campaign, fits, certification.document, out


def _flat(nested: list) -> list:
    return [leaf for item in nested for leaf in (_flat(item) if isinstance(item, list) else [item])]


def test_the_headline_is_the_largest_u_of_the_table(issued):
    _, _, document, _ = issued
    values = [v for v in _flat(document["uncertainty_table"]["X"]["u95_deg"]) if v is not None]
    assert document["tilt_u95_deg"] == max(values) == document["u95_max_deg"]["X"]
    assert document["budget"]["X"]["expanded_deg"] == document["tilt_u95_deg"]
    # A bound is not an average: it is not below any band's U.
    assert all(cell["expanded_deg"] <= document["tilt_u95_deg"] for cell in document["cells"])


def test_a_drift_both_readings_share_cancels_in_the_change(issued):
    # The campaign's mountings drift with their own slope in T (SLOPE_SPREAD):
    # installed and read in one band, the change carries almost none of it;
    # installed at one end of the domain and read at the other, all of it.
    _, _, document, _ = issued
    bands = document["uncertainty_table"]["X"]["temperature_bands_c"]

    def between(installed: list, read: list) -> float:
        cell = next(
            c
            for c in document["cells"]
            if c["installation_band_c"] == installed and c["temperature_band_c"] == read and c["tilt_band_deg"][0] > 0
        )
        return cell["contributions_deg"]["between positions (out of sample)"]

    for read in (bands[0], bands[-1]):
        farthest = bands[-1] if read == bands[0] else bands[0]
        assert between(read, read) < 0.25 * between(farthest, read)
    shifts = {
        (tuple(c["installation_band_c"]), tuple(c["temperature_band_c"])): c["contributions_deg"][
            "temperature reading shift"
        ]
        for c in document["cells"]
        if c["tilt_band_deg"][0] > 0
    }
    # One shift of the temperature reading moves both readings: only the change of df/dT between them counts.
    assert shifts[tuple(bands[0]), tuple(bands[0])] < shifts[tuple(bands[-1]), tuple(bands[0])]


def test_the_mounting_component_rests_on_the_positions_of_its_band_less_one(issued):
    _, _, document, _ = issued
    table = document["uncertainty_table"]["X"]
    # 0-15 deg holds 0 and +-15; 15-30 deg only +-30, too few, so it joins 30-45.
    assert table["tilt_bands_deg"] == [[0.0, 15.0], [15.0, 45.0]]
    assert set(_flat(table["positions"])) == {3, 4}
    between = next(c for c in document["budget"]["X"]["components"] if c["name"].startswith("between"))
    assert between["degrees_of_freedom"] == document["budget"]["X"]["positions"] - 1
    assert between["kind"] == "A" and "leave-one-position-out" in between["source"]


def test_the_budget_lists_every_type_b_component_with_its_reason(issued):
    _, _, document, _ = issued
    components = {c["name"]: c for c in document["budget"]["X"]["components"]}
    assert set(TYPE_B) <= set(components)
    for name in TYPE_B:
        component = components[name]
        assert component["source"] and component["distribution"] and component["divisor"] > 0
        assert component["contribution_deg"] >= 0.0
    assert components["resolution"]["divisor"] == pytest.approx(np.sqrt(3.0))
    assert components["set selection at turnarounds"]["value"] == pytest.approx(2 * SET_OFFSET_LSB, rel=0.35)
    # Listed, not added: the surfaces compensate the sensitivity's temperature change.
    assert not components["sensitivity change with temperature"]["added"]
    assert components["sensitivity change with temperature"]["contribution_deg"] == 0.0
    assert components["temperature reading shift"]["degrees_of_freedom"] is None  # a bound: infinite
    # A first calibration: the sensor's change over time is not known yet.
    assert not components["long-term stability"]["added"]
    assert components["long-term stability"]["source"].startswith("not evaluated")


def test_u_is_given_to_two_significant_digits_rounded_up(issued):
    _, _, document, _ = issued
    for value in _flat(document["uncertainty_table"]["X"]["u95_deg"]):
        assert float(two_significant_text(value)) == value
    assert two_significant_up(0.1234) == 0.13 and two_significant_up(0.12) == 0.12
    assert two_significant_up(0.0999) == 0.1 and two_significant_text(0.1) == "0.10"


def test_most_calibration_points_lie_within_u_out_of_sample(issued):
    # A point's 95th percentile of |error| in a band is about its mounting's
    # mean error plus 1.65 of the within scatter; U is k (>= 2) times the
    # root sum of the RMS of those means, the scatter and the Type B bounds,
    # so a point exceeds U only when its mounting is beyond ~2 sigma of the
    # between component: ~5 % of mountings, fewer with the Type B margin.
    _, _, document, _ = issued
    assert document["coverage"]["out_of_sample_within_u95"] >= 0.9
    assert document["coverage"]["as_left_within_u95"] >= document["coverage"]["out_of_sample_within_u95"] - 0.05


def test_fresh_mountings_stay_within_the_type_a_part_of_u_about_95_percent_of_rows(tmp_path):
    # Each campaign's surfaces and its bands' Type A U (between and within
    # positions, k from their nu_eff), then new mountings of every position
    # (new slopes, new noise): the share of their rows within U_A. The
    # out-of-sample between component and Student's k on positions - 1
    # make U_A a little wide (0.989 with these seeds): 0.9 .. 0.995.
    rng = np.random.default_rng(11)
    inside = rows = 0
    for _ in range(8):
        campaign = campaign_of(rng)
        fits = [fit_surface(campaign.sets[s], s, "X") for s in ("W", "C")]
        document = certify(campaign, fits, tmp_path, "TT-A").document
        table = document["uncertainty_table"]["X"]
        # The fresh rows' errors are about their reference at 25 degC: a change from an installation there.
        installed = table["temperature_bands_c"][band_index(np.array([25.0]), table["temperature_bands_c"], False)[0]]
        type_a = {
            (tuple(c["temperature_band_c"]), tuple(c["tilt_band_deg"])): c["type_a_expanded_deg"]
            for c in document["cells"]
            if c["installation_band_c"] == installed
        }
        slopes = rng.normal(0.0, SLOPE_SPREAD, len(ANGLES_DEG))
        for fit, offset in zip(fits, (SET_OFFSET_LSB, -SET_OFFSET_LSB)):
            fresh = mounted_set(rng, slopes, offset)
            reference = fresh.acceleration["X"] - fresh.residual["X"]
            left = fresh.residual["X"] - fit.surface.evaluate(fresh.temperature_c, fresh.acceleration["X"])
            zero = document["zero_reading_lsb"]["X"]
            error = tilt_deg(reference + left - zero) - tilt_deg(reference - zero)
            t_band = band_index(fresh.temperature_c, table["temperature_bands_c"], closed_above=False)
            nominal = np.abs(np.array(ANGLES_DEG, dtype=float))[fresh.position]
            tilt_band = band_index(nominal, table["tilt_bands_deg"], closed_above=True)
            limits = np.array(
                [
                    type_a.get((tuple(table["temperature_bands_c"][i]), tuple(table["tilt_bands_deg"][j])), np.nan)
                    for i, j in zip(t_band, tilt_band)
                ]
            )
            known = np.isfinite(limits)
            inside += int(np.count_nonzero(np.abs(error[known]) <= limits[known]))
            rows += int(np.count_nonzero(known))
    assert 0.9 <= inside / rows <= 0.995, inside / rows


def test_a_left_out_fold_is_the_fit_without_that_position():
    campaign, _ = fitted(3)
    data = campaign.sets["W"]
    predictions = left_out_predictions(data, "X", np.ones(len(ANGLES_DEG), dtype=bool))
    others = data.position != 6
    subset = SetData(
        data.temperature_c[others],
        {"X": data.acceleration["X"][others]},
        {"X": data.residual["X"][others]},
        data.position[others],
    )
    surface = fit_surface(subset, "W", "X").surface
    mine = ~others
    expected = surface.evaluate(data.temperature_c[mine], data.acceleration["X"][mine])
    np.testing.assert_allclose(predictions[mine], expected, atol=1e-6)
    assert design(data.temperature_c[:1], data.acceleration["X"][:1]).shape == (1, 6)


def test_the_certificate_carries_a_labs_fields_and_the_coefficients_sha256(issued):
    _, _, document, out = issued
    written = json.loads((out / "certificate.json").read_text())
    assert written["coefficients_sha256"] == hashlib.sha256((out / "coefficients.bin").read_bytes()).hexdigest()
    number = written["certificate_number"]
    assert number.startswith("CAL-TT-A-") and number.endswith(written["coefficients_sha256"][:8].upper())
    assert written["item"] == {**written["item"], "model": "LSM9DS0", "sensor_id": "TT-A"}
    assert written["procedure"]["software"].startswith("thermotilt ")
    assert "filled in by the laboratory" in written["laboratory"]["name"]
    assert written["domain"]["tilt_deg"]["X"] == [-45.0, 45.0]
    assert written["zero_reading_lsb"]["X"] == pytest.approx(OFFSET_LSB, abs=5.0)
    assert {p["nominal_deg"] for p in written["points"]} == {float(a) for a in ANGLES_DEG}
    point = written["points"][0]
    assert point["as_found_p95_deg"] > point["as_left_p95_deg"] and point["u95_deg"] is not None
    assert "The results relate only to the item calibrated." in written["statements"]
    assert written["end"] == "End of certificate"
    page = (out / "certificate.html").read_text()
    assert number in page and "data:image/png;base64," in page and "End of certificate" in page


def test_the_pdf_is_a_pdf_with_the_number_on_every_page(issued):
    _, _, document, out = issued
    pdf = (out / "certificate.pdf").read_bytes()
    assert pdf.startswith(b"%PDF")
    pypdf = pytest.importorskip("pypdf")
    reader = pypdf.PdfReader(str(out / "certificate.pdf"))
    texts = [page.extract_text() for page in reader.pages]
    assert all(document["certificate_number"] in text for text in texts)
    whole = " ".join(" ".join(texts).split())
    assert "set selection at turnarounds" in whole and "End of certificate" in whole


def test_u95_at_holds_the_calibration_rows_and_is_nan_outside_the_domain(issued):
    campaign, fits, document, _ = issued
    data = campaign.sets["W"]
    compensated = data.acceleration["X"] - fits[0].surface.evaluate(data.temperature_c, data.acceleration["X"])
    inside = (data.temperature_c >= document["domain"]["temperature_c"][0]) & (
        data.temperature_c <= document["domain"]["temperature_c"][1]
    )
    u95 = u95_at(document, "X", data.temperature_c, compensated, 25.0)
    assert np.isfinite(u95[inside]).all() and set(np.unique(u95[inside])) <= set(
        _flat(document["uncertainty_table"]["X"]["u95_deg"])
    )
    level = np.array([OFFSET_LSB, OFFSET_LSB + LSB_PER_G * np.sin(np.radians(60.0))])
    assert np.isnan(u95_at(document, "X", np.array([60.0, 25.0]), level, 25.0)).all()
    # An installation reading outside the domain: no U for any change from it.
    assert np.isnan(u95_at(document, "X", data.temperature_c, compensated, 60.0)).all()
    assert not in_domain(document, "X", np.array([60.0, 25.0]), level).any()


def test_a_position_without_the_tables_angles_cannot_be_certified(tmp_path):
    campaign, fits = fitted(5)
    unlabelled = Campaign(("run.csv (angles unknown)", *campaign.positions[1:]), campaign.sets, 0)
    with pytest.raises(NotCertifiable, match="angles"):
        certify(unlabelled, fits, tmp_path, "TT-A")


def test_a_fit_without_a_sensor_id_writes_no_certificate_and_says_so_in_one_line(tmp_path):
    campaign, fits = fitted(5)
    out = tmp_path / "fit"
    out.mkdir()
    (out / "certificate.json").write_text("{}")  # a previous fit's, for other coefficients
    fit = SensorFit(tmp_path, out, campaign, fits, None, NO_ID_REASON, None, "")
    fit.write()
    assert not any(out.glob("certificate.*"))
    assert (out / "coefficients.bin").is_file()
    lines = [line for line in fit.summary().splitlines() if "certificate" in line]
    assert lines == [f"no certificate issued: {NO_ID_REASON}"]


def test_a_campaign_of_three_angles_rests_its_mounting_component_on_in_sample_errors(tmp_path):
    # Leaving out any of 0, +-30 deg leaves two angles: too few for the
    # quadratic in a, so those positions' errors stay in sample, and say so.
    campaign, _ = fitted(5)
    kept = (1, 3, 5)

    def subset(data: SetData) -> SetData:
        mine = np.isin(data.position, kept)
        return SetData(
            data.temperature_c[mine],
            {axis: values[mine] for axis, values in data.acceleration.items()},
            {axis: values[mine] for axis, values in data.residual.items()},
            data.position[mine],
        )

    three = Campaign(campaign.positions, {name: subset(data) for name, data in campaign.sets.items()}, 0)
    fits = [fit_surface(three.sets[s], s, "X") for s in ("W", "C")]
    document = certify(three, fits, tmp_path, "TT-A").document
    assert document["domain"]["tilt_deg"]["X"] == [-30.0, 30.0]
    assert len(document["not_out_of_sample"]["X"]) == 3
    assert document["uncertainty_table"]["X"]["tilt_bands_deg"] == [[0.0, 30.0]]
    between = next(c for c in document["budget"]["X"]["components"] if c["name"].startswith("between"))
    assert "3 in sample" in between["source"] and between["degrees_of_freedom"] == 2
    assert not any(point["out_of_sample"] for point in document["points"])


def test_a_recalibrations_certificate_adds_the_change_since_the_previous_one(issued, tmp_path):
    _, _, first, first_dir = issued
    campaign, fits = fitted(6)  # the same sensor mounted again: other drift slopes
    previous = PreviousCalibration.read(first_dir, "TT-A")
    document = certify(campaign, fits, tmp_path, "TT-A", previous).document
    alone = certify(campaign, fits, tmp_path, "TT-A").document
    stability = next(c for c in document["budget"]["X"]["components"] if c["name"] == "long-term stability")
    old = read_fit(first_dir)
    expected = stability_bound([surface_change(f"{f.set_name}X", old[f"{f.set_name}X"], f) for f in fits])
    assert stability["added"] and stability["value"] == pytest.approx(expected) and expected > 0.0
    assert stability["contribution_deg"] == pytest.approx(expected / np.sqrt(3.0))
    assert first["certificate_number"] in stability["source"]
    assert document["previous_calibration"]["certificate_number"] == first["certificate_number"]

    # A component more raises every band's u_c. (U = k u_c may still fall:
    # a bound has infinite degrees of freedom, so Welch-Satterthwaite's
    # nu_eff rises and Student's k falls, GUM G.4.1.)
    def combined(cell: dict) -> float:
        return float(np.sqrt(sum(value**2 for value in cell["contributions_deg"].values())))

    for with_it, without in zip(document["cells"], alone["cells"], strict=True):
        assert combined(with_it) > combined(without)
    with pytest.raises(CalibrationDataError, match="fitted for TT-A, not TT-B"):
        PreviousCalibration.read(first_dir, "TT-B")


def _flat_fit(surface: Surface, temperature_c=(-10.0, 45.0)) -> FittedSurface:
    # Near level, where a degree of tilt is LSB_PER_G / 57.3 LSB.
    return FittedSurface(surface, {}, temperature_c, (0.0, 100.0), 1.0)


def test_a_change_the_same_everywhere_cancels_in_the_stability_bound():
    old = _flat_fit(Surface(0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    shifted = [surface_change(key, old, _flat_fit(Surface(20.0, 0.0, 0.0, 0.0, 0.0, 0.0))) for key in ("WX", "CX")]
    assert stability_bound(shifted) == pytest.approx(0.0, abs=1e-12)
    # A slope of 0.2 LSB/degC over 55 degC: 11 LSB between the domain's ends.
    tilted = surface_change("WX", old, _flat_fit(Surface(0.0, 0.2, 0.0, 0.0, 0.0, 0.0)))
    assert stability_bound([tilted]) == pytest.approx(np.degrees(11.0 / LSB_PER_G), rel=1e-3)
    # Sets moved apart: a reading in one and its installation in the other differ by the gap.
    apart = [shifted[0], surface_change("CX", old, _flat_fit(Surface(-20.0, 0.0, 0.0, 0.0, 0.0, 0.0)))]
    assert stability_bound(apart) == pytest.approx(np.degrees(40.0 / LSB_PER_G), rel=1e-3)
