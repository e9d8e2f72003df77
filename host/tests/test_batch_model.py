"""A batch of sensors in one model file ([[sensors]], physics/batch.py) and
a drawn population of them."""

from __future__ import annotations

import numpy as np
import pytest

from thermotilt.physics import Model, ModelError
from thermotilt.physics.batch import (
    DRIFT_SHAPE_SPREAD,
    TEMPCO_SPREAD_MG_PER_C,
    TEMPERATURE_OFFSET_SPREAD_C,
    ZERO_G_SPREAD_MG,
)
from thermotilt.physics.terms.sensor import coefficient_table_of


def batch(*sensors: dict) -> Model:
    return Model.from_document({"sensors": list(sensors)}, "batch.toml")


def test_a_sensor_table_overrides_the_top_level_for_that_sensor_alone():
    model = batch(
        {"id": "TT-A", "drift": {"schmitt_band_c": 0.8}, "noise": {"sigma_lsb": {"x": 1.0, "y": 2.0, "z": 3.0}}},
        {"id": "TT-B"},
    )
    assert model.sensor_ids == ("TT-A", "TT-B")
    a, b = model.for_sensor("TT-A"), model.for_sensor("TT-B")
    assert a.terms["drift"]["schmitt_band_c"] == 0.8 and a.terms["noise"]["sigma_lsb"]["y"] == 2.0
    # What a sensor's table leaves out is the top level's.
    assert a.terms["drift"]["coefficients"] == model.terms["drift"]["coefficients"]
    assert b.terms == model.terms and a.sensors == () and "TT-A" in a.source


@pytest.mark.parametrize(
    "sensors, message",
    [
        ([{"id": "TOO-LONG-1"}], "has 10 characters, at most 8"),
        ([{"id": "TT A"}], "only letters, digits"),
        ([{"drift": {}}], "needs an id, got None"),
        ([{"id": "A"}, {"id": "A"}], "[[sensors]] A: listed twice"),
        ([{"id": "A", "heatsink": {"enabled": False}}], "overrides sensor terms only"),
        ([{"id": "A", "drift": {"band": 1}}], "[drift] unknown parameter 'band'"),
        ([{"id": "A", "drift": {"schmitt_band_c": 99.0}}], "schmitt_band_c"),
    ],
)
def test_a_bad_sensor_table_is_one_line_naming_it(sensors, message):
    with pytest.raises(ModelError) as error:
        batch(*sensors)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_asking_for_a_sensor_the_batch_lacks_names_the_ones_it_has():
    with pytest.raises(ModelError, match=r"no sensor 'TT-C' \(its sensors: TT-A\)"):
        batch({"id": "TT-A"}).for_sensor("TT-C")


def test_a_drawn_population_is_seeded_and_keeps_the_drift_zero_at_25c():
    model = Model.load()
    drawn = model.with_population(4, seed=3)
    assert drawn.sensor_ids == ("TT-01", "TT-02", "TT-03", "TT-04")
    assert drawn.sensors == model.with_population(4, seed=3).sensors
    assert drawn.sensors != model.with_population(4, seed=4).sensors
    base = coefficient_table_of(model.terms["drift"]["coefficients"])
    for sensor_id in drawn.sensor_ids:
        table = coefficient_table_of(drawn.for_sensor(sensor_id).terms["drift"]["coefficients"])
        for key, surface in table.surfaces.items():
            for acceleration in (-16000.0, 0.0, 11000.0):
                assert surface.evaluate(25.0, acceleration) == pytest.approx(
                    base.surfaces[key].evaluate(25.0, acceleration), abs=1e-6
                )


def test_a_drawn_population_has_the_stated_spreads():
    model = Model.load()
    lsb_per_mg = model.constants["sensor"]["lsb_per_g"] / 1000.0
    drawn = model.with_population(400, seed=1)
    sensors = [drawn.for_sensor(sensor_id) for sensor_id in drawn.sensor_ids]
    offsets = np.array([s.terms["measuring_offset"]["warming_lsb"]["x"] for s in sensors])
    offsets -= model.terms["measuring_offset"]["warming_lsb"]["x"]
    temperatures = np.array([s.terms["temperature_offset"]["offset_c"] for s in sensors])
    temperatures -= model.terms["temperature_offset"]["offset_c"]
    base = coefficient_table_of(model.terms["drift"]["coefficients"]).surface("W", "Y")
    slopes = np.array([coefficient_table_of(s.terms["drift"]["coefficients"]).surface("W", "Y").p10 for s in sensors])
    # A sample SD of 400 normal draws is within 4 of its standard errors
    # (SD / sqrt(800), 3.5 %) of the truth, barring 1 in 15 000.
    tolerance = 4.0 / np.sqrt(800)
    assert np.std(offsets) == pytest.approx(ZERO_G_SPREAD_MG * lsb_per_mg, rel=tolerance)
    assert np.std(temperatures) == pytest.approx(TEMPERATURE_OFFSET_SPREAD_C, rel=tolerance)
    # Y's slope spread: the tempco's and the shape's (DRIFT_SHAPE_SPREAD of p10) in quadrature.
    expected = np.hypot(TEMPCO_SPREAD_MG_PER_C * lsb_per_mg, DRIFT_SHAPE_SPREAD * base.p10)
    assert np.std(slopes) == pytest.approx(expected, rel=tolerance)


def test_a_batch_model_written_and_read_back_is_the_same_batch(tmp_path):
    from thermotilt.physics.document import write_model

    drawn = Model.load().with_population(2, seed=3)
    write_model(drawn, tmp_path / "batch.toml")
    again = Model.load(str(tmp_path / "batch.toml"))
    assert again.sensor_ids == drawn.sensor_ids
    for sensor_id in drawn.sensor_ids:
        assert again.for_sensor(sensor_id).terms == drawn.for_sensor(sensor_id).terms


def test_switching_a_term_reaches_every_sensor_of_the_batch():
    drawn = Model.load().with_population(2, seed=3)
    switched = drawn.with_terms({"drift": False})
    assert not switched.enabled("drift")
    assert not any(switched.for_sensor(sensor_id).enabled("drift") for sensor_id in drawn.sensor_ids)
    assert all(drawn.for_sensor(sensor_id).enabled("drift") for sensor_id in drawn.sensor_ids)
