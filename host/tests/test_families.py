"""``fit --compare-families``: leave-one-position-out CV picks the family
that made the data, and the command writes families.json."""

import json

import numpy as np
import pytest
from test_calibration_fit import ANGLES_DEG, LSB_PER_G, TRUE, cycle, smooth_noise, write_run_log

from thermotilt import cli
from thermotilt.calibration.dataset import Campaign, SetData
from thermotilt.calibration.families import (
    FAMILIES,
    compare_families,
    extrapolating,
    format_families,
    recommend,
    score,
)
from thermotilt.calibration.fit import _POWERS, design


def synthetic_campaign(rate_lsb_per_c_per_min: float, seed: int = 2) -> Campaign:
    """Seven positions, each a staircase-like ramp -10..45 degC at a
    varying rate, drifting as TRUE (poly22) plus an optional dT/dt term."""
    rng = np.random.default_rng(seed)
    rows = 1500
    time_s = np.arange(rows) * 1.0
    # A ramp whose speed changes, so that rate is not a function of temperature.
    temperature = -10.0 + 55.0 * (time_s / time_s[-1]) + 3.0 * np.sin(time_s / 40.0)
    rate = np.gradient(temperature, time_s)
    parts = []
    for index, angle in enumerate(ANGLES_DEG):
        acceleration = np.full(rows, LSB_PER_G * np.sin(np.radians(angle)))
        residual = (
            TRUE.evaluate(temperature, acceleration)
            + rate_lsb_per_c_per_min * rate * 60.0
            + smooth_noise(rng, rows, 2.0, 20)
        )
        parts.append((temperature, acceleration, residual, np.full(rows, index), rate))
    data = SetData(
        np.concatenate([p[0] for p in parts]),
        {"X": np.concatenate([p[1] for p in parts])},
        {"X": np.concatenate([p[2] for p in parts])},
        np.concatenate([p[3] for p in parts]),
        np.concatenate([p[4] for p in parts]),
    )
    return Campaign(tuple(str(angle) for angle in ANGLES_DEG), {"W": data, "C": data}, 0)


def test_the_papers_family_is_fit_py_s_surface():
    assert FAMILIES["poly22"] == tuple((*power, 0) for power in _POWERS)
    assert len(FAMILIES["poly33"]) == 10 and len(set(FAMILIES["poly33"])) == 10


def test_poly22_data_recommend_poly22():
    scores = compare_families(synthetic_campaign(0.0), ("X",))
    assert recommend(scores) == {"X": "poly22"}
    by_family = {s.family: s for s in scores if s.set_name == "W"}
    # The noise is 2 LSB: the right family predicts a left-out position to about that.
    assert by_family["poly22"].cv_rmse_lsb == pytest.approx(2.0, rel=0.25)
    assert by_family["poly11"].cv_rmse_lsb > 2 * by_family["poly22"].cv_rmse_lsb


def test_a_rate_effect_recommends_the_rate_term():
    # 20 LSB per degC/min on a ramp of 2-7 degC/min: tens of LSB against 2 LSB of noise.
    scores = compare_families(synthetic_campaign(20.0), ("X",))
    assert recommend(scores) == {"X": "poly22+rate"}


@pytest.mark.slow
def test_the_fit_command_writes_families_json(tmp_path, capsys):
    temperatures, sets = cycle()
    for angle in ANGLES_DEG:
        write_run_log(tmp_path / "campaign" / f"{angle}.csv", angle, temperatures, sets)
    out = tmp_path / "fit"
    assert cli.main(["fit", str(tmp_path / "campaign"), "--out", str(out), "--compare-families"]) == 0
    assert "recommended for X: " in capsys.readouterr().out
    document = json.loads((out / "families.json").read_text())
    assert set(document["recommended"]) == {"X", "Y"} and set(document["recommended"].values()) <= set(FAMILIES)
    assert {score["family"] for score in document["scores"]} == set(FAMILIES)
    assert "## Model families" in (out / "report.md").read_text()


def test_a_family_the_data_cannot_determine_is_left_out():
    campaign = synthetic_campaign(0.0)
    data = campaign.sets["W"]
    steady = SetData(
        data.temperature_c, data.acceleration, data.residual, data.position, np.full(data.temperature_c.size, 0.01)
    )
    scores = compare_families(Campaign(campaign.positions, {"W": steady, "C": steady}, 0), ("X",))
    undetermined = {s.family for s in scores if not s.determined}
    assert undetermined == {"poly22+rate"}
    assert recommend(scores) == {"X": "poly22"}
    assert any(
        line.startswith("poly22+rate") and "not determined" in line for line in format_families(scores).splitlines()
    )


def test_too_few_inclinations_for_a_quadratic_are_named():
    campaign = synthetic_campaign(0.0)
    data = campaign.sets["W"]
    # Keep three of the seven positions: -45, 0 and +45 deg.
    keep = np.isin(data.position, [0, 3, 6])
    three = SetData(
        data.temperature_c[keep],
        {"X": data.acceleration["X"][keep]},
        {"X": data.residual["X"][keep]},
        data.position[keep],
        data.rate_c_per_s[keep],
    )
    scores = compare_families(Campaign(campaign.positions, {"W": three, "C": three}, 0), ("X",))
    assert extrapolating(scores) == ["X"]
    assert "too few inclinations on X" in format_families(scores)
    assert extrapolating(compare_families(campaign, ("X",))) == []


def test_rmse_and_bic_are_statsmodels_ols():
    import statsmodels.api as sm

    campaign = synthetic_campaign(0.3)
    data = campaign.sets["W"]
    for family in FAMILIES:
        columns = design(data.temperature_c, data.acceleration["X"], FAMILIES[family], data.rate_c_per_s)
        reference = sm.OLS(data.residual["X"], columns).fit(method="qr")
        mine = score(campaign, family, "W", "X")
        assert mine.rmse_lsb == pytest.approx(np.sqrt(reference.ssr / reference.df_resid), rel=1e-9)
        assert mine.bic == pytest.approx(reference.bic, rel=1e-9)
