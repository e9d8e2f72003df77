"""The calibration chain on the twin: `make demo`'s campaign (nine of the
paper's positions, each through the -10 -> 45 -> -10 degC staircase),
fitted with plain OLS, recovers the model's drift surfaces and leaves the
scatter of the paper's fits (Sensors 2018, 18, 2536, Tables 2-3), as
docs/calibration.md ("Comparing") measures them."""

import importlib.util
import json
from importlib import resources
from pathlib import Path

import pytest
from conftest import made_once_per_test_run

from thermotilt import cli
from thermotilt.calibration.compare import compare, read_fit

pytestmark = [pytest.mark.twin, pytest.mark.long]

# A twin campaign subset's RMSE is of the order of Tables 2-3's: within a
# factor of two, as docs/twin.md's table of the paper's features states.
PAPER_FACTOR = 2.0


def demo_settings():
    spec = importlib.util.spec_from_file_location("demo", Path(__file__).parents[1] / "tools" / "demo.py")
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    return demo.POSITIONS, demo.HOLD_SECONDS


def _campaign_and_fit(folder, positions, *options, fit_options=()):
    """The demo's twin campaign settings on these positions, then fit."""
    _, hold_s = demo_settings()
    campaign = ["campaign", "--twin", "--positions", positions, "--hold-seconds", str(hold_s)]
    campaign += ["--rest-seconds", "0", "--jobs", "2", *options, "--out", str(folder / "campaign")]
    assert cli.main(campaign) == 0
    assert cli.main(["fit", str(folder / "campaign"), *fit_options, "--out", str(folder / "fit")]) == 0


@pytest.fixture(scope="session")
def fitted(tmp_path_factory):
    """The demo's campaign, fitted: made once per test run, however many
    pytest-xdist workers take this module's tests."""
    positions, _ = demo_settings()
    # The twin's single-sensor campaign records no sensor ID; `fit` certifies only an identified item.
    made = made_once_per_test_run(
        tmp_path_factory,
        "twin_calibration",
        lambda folder: _campaign_and_fit(folder, positions, fit_options=("--sensor-id", "TT-00")),
    )
    return made / "fit"


@pytest.mark.slow
def test_a_twin_campaign_recovers_the_models_surfaces(fitted):
    document = json.loads((fitted / "coefficients.json").read_text())
    comparisons = compare(read_fit(fitted), str(resources.files("thermotilt") / "models" / "default.toml"))
    assert {c.key for c in comparisons} == {"WX", "CX", "WY", "CY"}
    for comparison in comparisons:
        rmse = document["fits"][comparison.key]["rmse_lsb"]
        low, high = comparison.temperature_range_c
        # Each set spans the staircase to within 3 degC of both ends: the
        # face's settled error (255/350 degC at most), the die's 1 degC
        # offset, and the change of trend the set's switch waits for.
        assert low < -7.0 and high > 42.0, comparison.key
        # The surface is an average over thousands of rows: were it further
        # from the truth than those rows scatter around it (the fit's RMSE),
        # the fit, not the sensor, would be the calibration's largest error.
        assert comparison.rms_lsb < rmse, (comparison.key, comparison.rms_lsb, rmse)


@pytest.mark.slow
def test_a_twin_campaign_leaves_the_scatter_of_tables_2_and_3(fitted):
    # Nine positions are nine draws of drift_repeatability's slopes: seed 1's
    # nine give 0.76-1.55x; with the filter emulated 26 of 40 seeds' nine keep
    # all four within the factor (docs/twin.md). A change to how the model draws
    # can fail this with a worse draw rather than a worse model: check the
    # 37 positions' fit (test_scatter.py) before loosening anything.
    comparisons = compare(read_fit(fitted), "paper")
    assert {c.key for c in comparisons} == {"WX", "CX", "WY", "CY"}
    for comparison in comparisons:
        ratio = comparison.fit_rmse_lsb / comparison.reference_rmse_lsb
        assert 1 / PAPER_FACTOR < ratio < PAPER_FACTOR, (comparison.key, comparison.fit_rmse_lsb)


@pytest.fixture(scope="module")
def field_against_certificate(fitted, tmp_path_factory):
    """A fresh field-alternating run of the sensor, its tilt compensated with
    its own fit: (its change-from-installation p95, the certificate's U at
    the run's own rows, largest), both in degrees."""
    field = tmp_path_factory.mktemp("field") / "field-alternating"
    run = ["simulate", "field-alternating", "--duration", "3600", "--incl-x", "20", "--seed", "7", "--out"]
    assert cli.main([*run, str(field)]) == 0
    assert cli.main(["validate", str(field), "--coefficients", str(fitted)]) == 0
    validation = json.loads((field / "validation.json").read_text())
    u95 = [axis["u95_max_deg"] for axis in validation["tilt_change"]["axes"]]
    return validation["tilt_change_p95_deg"], max(u95)


@pytest.mark.slow
def test_a_field_run_stays_within_the_certificates_uncertainty(field_against_certificate):
    # The claim a certificate makes: the change of tilt a user reads stays
    # within U at the run's conditions.
    p95, u95 = field_against_certificate
    assert p95 <= u95, (p95, u95)


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason="U at the run's conditions is over 3x its p95 change: near the installation temperature the "
    "turnaround row dominates it, keeping about half the sets' difference (the crossing width is read on the "
    "filtered temperature, which trails the die by the Kalman filter's ~10 s lag: 1.1 degC for the twin's 1.5), "
    "and away from it the between-positions component rests on 4 positions at 15-45 deg (docs/calibration.md)",
)
def test_the_certificates_uncertainty_is_not_padded(field_against_certificate):
    p95, u95 = field_against_certificate
    assert u95 <= 3.0 * p95, (p95, u95)


BATCH_POSITIONS = "0,X+30,X-30"


def _batch_campaign_and_fit(folder):
    _campaign_and_fit(folder, BATCH_POSITIONS, "--sensors", "2", fit_options=("--axes", "X"))


@pytest.fixture(scope="session")
def batch_fitted(tmp_path_factory):
    return made_once_per_test_run(tmp_path_factory, "twin_batch", _batch_campaign_and_fit)


@pytest.mark.slow
def test_a_batch_campaign_fits_each_sensor_to_its_own_drift(batch_fitted):
    batch = json.loads((batch_fitted / "campaign" / "batch.json").read_text())
    sensors = batch["sensors"]
    assert sensors == ["TT-01", "TT-02"]
    # The batch the campaign drew, as it kept it.
    truths = str(batch_fitted / "campaign" / batch["model_file"])
    gaps = {}
    for fitted_id in sensors:
        fit_dir = batch_fitted / "fit" / fitted_id
        assert json.loads((fit_dir / "certificate.json").read_text())["sensor_id"] == fitted_id
        campaign = json.loads((batch_fitted / "campaign" / fitted_id / "campaign.json").read_text())
        assert {position["sensor_id"] for position in campaign["positions"]} == {fitted_id}
        assert json.loads((fit_dir / "coefficients.json").read_text())["sensor_id"] == fitted_id
        for truth_id in sensors:
            gaps[fitted_id, truth_id] = max(c.rms_lsb for c in compare(read_fit(fit_dir), truths, truth_id))
    for fitted_id in sensors:
        other = next(s for s in sensors if s != fitted_id)
        assert gaps[fitted_id, fitted_id] < gaps[fitted_id, other]
