"""The calibration certificate's tilt uncertainty (calibration/certificate.py):
honest (fresh data of the same sensor stays within it about 95 % of the
time) and aware of the rows' autocorrelation."""

from __future__ import annotations

import numpy as np
import pytest
from test_calibration_fit import ANGLES_DEG, smooth_noise, synthetic_set

from thermotilt.calibration.certificate import certify, effective_count, write_certificate
from thermotilt.calibration.dataset import Campaign
from thermotilt.calibration.fit import fit_surface
from thermotilt.calibration.validate import tilt_deg

CAMPAIGNS = 20


def campaign_of(rng) -> Campaign:
    sets = {set_name: synthetic_set(rng) for set_name in ("W", "C")}
    return Campaign(tuple(f"{angle} deg" for angle in ANGLES_DEG), sets, 0)


def test_fresh_data_of_the_sensor_stays_within_the_expanded_uncertainty_about_95_percent_of_rows(tmp_path):
    # Each campaign's surfaces and U, then a fresh run of every position with
    # new noise (the same process): the share of its rows whose tilt error is
    # within U. Over 20 campaigns of 2 x 7 x 800 rows (moving-average noise
    # of 40 rows, so ~280 independent values each) a share outside
    # 0.90..0.99 would say U is too narrow or padded.
    rng = np.random.default_rng(11)
    inside = rows = 0
    for _ in range(CAMPAIGNS):
        campaign = campaign_of(rng)
        fits = [fit_surface(campaign.sets[s], s, "X") for s in ("W", "C")]
        document, _ = certify(campaign, fits, tmp_path)
        for fit in fits:
            fresh = synthetic_set(rng)
            temperature, acceleration = fresh.temperature_c, fresh.acceleration["X"]
            at_25 = acceleration - fresh.residual["X"]
            left = fresh.residual["X"] - fit.surface.evaluate(temperature, acceleration)
            error = tilt_deg(at_25 + left) - tilt_deg(at_25)
            inside += int(np.count_nonzero(np.abs(error) <= document["tilt_u95_deg"]))
            rows += len(error)
    assert 0.90 <= inside / rows <= 0.99


def test_the_effective_count_of_autocorrelated_rows_is_far_below_their_count():
    rng = np.random.default_rng(3)
    groups = np.repeat(np.arange(10), 2000)
    white = rng.standard_normal(len(groups))
    # Independent rows: Newey-West's mean variance scatters ~10 % about s^2/n.
    assert effective_count(white, groups) == pytest.approx(len(groups), rel=0.25)
    # A moving average over 40 rows has a long-run variance 40 times its
    # variance: n/40, which the Bartlett window (twice the decorrelation lag)
    # underestimates by up to a fifth, so n/40 .. 1.6 n/40.
    smooth = np.concatenate([smooth_noise(rng, 2000, 1.0, 40) for _ in range(10)])
    assert len(groups) / 40 <= effective_count(smooth, groups) <= 1.6 * len(groups) / 40


def test_the_certificate_states_the_domain_every_point_and_its_method(tmp_path):
    campaign = campaign_of(np.random.default_rng(5))
    fits = [fit_surface(campaign.sets[s], s, "X") for s in ("W", "C")]
    document, errors = certify(campaign, fits, tmp_path, sensor_id="TT-A")
    assert document["sensor_id"] == "TT-A"
    assert document["domain"]["temperature_c"]["warming"] == pytest.approx([-10.0, 45.0])
    assert document["domain"]["tilt_deg"]["X"] == pytest.approx([-45.0, 45.0], abs=0.5)
    assert len(document["points"]) == 2 * len(ANGLES_DEG)
    uncertainty = document["uncertainty"]
    assert uncertainty["effective_rows"] < uncertainty["rows"] / 10
    assert document["tilt_u95_deg"] == pytest.approx(uncertainty["coverage_factor"] * uncertainty["standard_deg"])
    assert "Welch-Satterthwaite" in document["method"]
    json_path, html_path = write_certificate(tmp_path / "fit", document, errors)
    page = html_path.read_text()
    assert "TT-A" in page and "data:image/png;base64," in page and f"{document['tilt_u95_deg']:.4f}" in page
