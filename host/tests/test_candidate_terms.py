"""The discovery workflow's candidate terms: registered sensor terms, off
by default, each checked against its formula as Sensor.step with the term
on minus with it off, every default term (and its seeded draws) running in
both; and the SensorSample fields the replay needs."""

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_physics import CANDIDATES, SENSOR_EFFECTS_OFF

from thermotilt.physics import DECLARATIONS, TERMS, Model, ModelError, Sensor
from thermotilt.physics.terms import REGISTRY, SENSOR_STAGES, SensorContext
from thermotilt.surfaces import PAPER_DEFAULTS

DEFAULT_TOML = Path(__file__).resolve().parents[1] / "thermotilt" / "models" / "default.toml"
PROPERTY = settings(max_examples=60, deadline=None)
SOURCE = "candidate for discovery; no paper value"
REFERENCE_C = 25.0
AXES = "xyz"
# Far below the register's ulp (3.6e-12 LSB at 16384) times the few sums of a step.
EXACT = 1e-8

STAGES = {
    "sensor_lag": "structure",
    "hysteresis": "error",
    "scale_tempco": "scale",
    "cross_axis": "ideal",
}
DEFAULTS = {
    "sensor_lag": {"time_constant_s": 30.0},
    "hysteresis": {"cooling_offset_lsb": {"x": 20.0, "y": 20.0, "z": 0.0}},
    "scale_tempco": {"ppm_per_c": {"x": 100.0, "y": 100.0, "z": 0.0}},
    "cross_axis": {"share": {"x": 0.005, "y": 0.005, "z": 0.0}},
}

temperatures = st.floats(-10.0, 45.0)
angles = st.floats(-90.0, 90.0)
# (chamber temperature degC, incl x deg, incl y deg) per step; a few steps
# hold the table still, so the mounting and the ideal acceleration persist.
paths = st.lists(st.tuples(temperatures, angles, angles), min_size=2, max_size=25).map(
    lambda steps: [step for step in steps for _ in range(3)]
)
seeds = st.integers(0, 2**32 - 1)


def model_with(name, **values):
    """The default model with one candidate switched on and these values."""
    table = {"enabled": True, **DEFAULTS[name], **values}
    return Model.from_document({name: table}, "test")


def run(model, seed, path, dt_s=0.5):
    sensor = Sensor(model, seed, path[0][0])
    return [sensor.step(dt_s, *step) for step in path]


def unrounded(sample):
    return sample.unrounded_ax, sample.unrounded_ay, sample.unrounded_az


def ideal(sample):
    return sample.ideal_ax, sample.ideal_ay, sample.ideal_az


def drift(sample):
    return sample.drift_x, sample.drift_y, sample.drift_z


def errors(sample):
    """What every term after the drift added."""
    return tuple(u - i - d for u, i, d in zip(unrounded(sample), ideal(sample), drift(sample)))


def same_temperatures(on, off):
    for with_term, without in zip(on, off, strict=True):
        assert (
            with_term.die_c,
            with_term.reported_c,
            with_term.rate_c_per_s,
            with_term.drift_set,
            with_term.temperature_raw,
            with_term.mounting,
        ) == (
            without.die_c,
            without.reported_c,
            without.rate_c_per_s,
            without.drift_set,
            without.temperature_raw,
            without.mounting,
        )


def surfaces(sample, temperature_c, acceleration):
    """The paper's drift at the sample's set state: its warming share of the
    way from the cooling surfaces to the warming ones (physics/sensor.py)."""

    def of(set_name):
        return [
            PAPER_DEFAULTS.surface(set_name, axis.upper()).evaluate(temperature_c, a)
            for axis, a in zip(AXES, acceleration)
        ]

    share = sample.warming_share
    return tuple(share * w + (1.0 - share) * c for w, c in zip(of("W"), of("C")))


# --- registration -------------------------------------------------------------


@pytest.mark.parametrize("name", CANDIDATES)
def test_each_candidate_is_a_registered_sensor_term_off_by_default(name):
    assert name in TERMS
    term = REGISTRY[name]
    assert term.enabled_by_default is False
    assert term.stage == STAGES[name] and term.stage in SENSOR_STAGES
    enabled, *parameters = DECLARATIONS[name]
    assert (enabled.name, enabled.default) == ("enabled", False)
    assert {p.name: p.default for p in parameters} == DEFAULTS[name]
    assert all(p.source == SOURCE and p.why for p in parameters)


def test_the_candidates_stages_run_in_order():
    stages = list(SENSOR_STAGES)
    assert stages.index("reported") < stages.index("structure") < stages.index("drift")
    assert stages.index("drift") < stages.index("scale") < stages.index("error")


@pytest.mark.parametrize("name", CANDIDATES)
def test_a_switched_off_candidate_binds_nothing(name):
    context = SensorContext(16393.0, lambda: 0.0, lambda: 0.5, np.zeros, np.zeros, np.random.default_rng)
    term = REGISTRY[name](Model.load().terms[name])
    assert term.bind(context) is None and term.bind_series(context) is None
    switched = REGISTRY[name](Model.load().with_terms({name: True}).terms[name])
    assert callable(switched.bind(context)) and callable(switched.bind_series(context))


# --- model files --------------------------------------------------------------


def test_default_toml_states_each_candidate_switched_off():
    model = Model.load(DEFAULT_TOML)
    for name in CANDIDATES:
        assert model.terms[name] == {"enabled": False, **DEFAULTS[name]}
    assert model.terms == Model.load().terms


def test_a_model_file_without_the_candidate_tables_loads_them_switched_off(tmp_path):
    text = DEFAULT_TOML.read_text(encoding="utf-8")
    before = text[: text.index("# Candidates:")]
    assert all(f"[{name}]" not in before for name in CANDIDATES)
    path = tmp_path / "older.toml"
    path.write_text(before, encoding="utf-8")
    older = Model.load(path)
    assert older.terms == Model.load().terms
    assert not any(older.enabled(name) for name in CANDIDATES)


def test_a_model_file_may_switch_one_candidate_on(tmp_path):
    path = tmp_path / "lagging.toml"
    path.write_text("[sensor_lag]\nenabled = true\ntime_constant_s = 12.5\n", encoding="utf-8")
    model = Model.load(path)
    assert model.terms["sensor_lag"] == {"enabled": True, "time_constant_s": 12.5}
    assert not any(model.enabled(name) for name in CANDIDATES if name != "sensor_lag")
    path.write_text("[sensor_lag]\nenabled = true\n", encoding="utf-8")
    with pytest.raises(ModelError, match=r"\[sensor_lag\] missing parameter 'time_constant_s'"):
        Model.load(path)


@pytest.mark.parametrize(
    ("name", "parameter", "value", "message"),
    [
        ("sensor_lag", "time_constant_s", 0.0, "time_constant_s: must be > 0 and <= 3600 s"),
        ("sensor_lag", "time_constant_s", -1.0, "time_constant_s: must be > 0 and <= 3600 s"),
        ("sensor_lag", "time_constant_s", 3600.5, "time_constant_s: must be > 0 and <= 3600 s"),
        (
            "hysteresis",
            "cooling_offset_lsb",
            {"x": 32768.5, "y": 0.0, "z": 0.0},
            r"cooling_offset_lsb\.x: must be >= -32768 and <= 32768 LSB",
        ),
        (
            "scale_tempco",
            "ppm_per_c",
            {"x": 0.0, "y": -10001.0, "z": 0.0},
            r"ppm_per_c\.y: must be >= -10000 and <= 10000 ppm per degC",
        ),
        ("cross_axis", "share", {"x": 0.0, "y": 0.0, "z": 0.11}, r"share\.z: must be >= -0\.1 and <= 0\.1, got"),
        ("cross_axis", "share", {"x": 0.0, "y": 0.0}, r"share: expected a table"),
    ],
)
def test_the_candidates_bounds_are_enforced(name, parameter, value, message):
    with pytest.raises(ModelError, match=rf"\[{name}\] {message}"):
        model_with(name, **{parameter: value})


@pytest.mark.parametrize(
    ("name", "parameter", "value"),
    [
        ("sensor_lag", "time_constant_s", 3600.0),
        ("sensor_lag", "time_constant_s", 1e-3),
        ("hysteresis", "cooling_offset_lsb", {"x": -32768.0, "y": 32768.0, "z": 0.0}),
        ("scale_tempco", "ppm_per_c", {"x": -10000.0, "y": 10000.0, "z": 0.0}),
        ("cross_axis", "share", {"x": -0.1, "y": 0.1, "z": 0.0}),
    ],
)
def test_the_candidates_bounds_are_inclusive_where_stated(name, parameter, value):
    model = model_with(name, **{parameter: value})
    sample = Sensor(model, 1, 22.0).step(0.01, 23.0, 45.0, -45.0)
    assert all(map(math.isfinite, unrounded(sample)))


# --- the new SensorSample fields ----------------------------------------------


@PROPERTY
@given(seed=seeds, path=paths)
def test_the_registers_are_the_unrounded_acceleration_rounded(seed, path):
    for sample in run(Model.load(), seed, path):
        for register, value in zip((sample.ax, sample.ay, sample.az), unrounded(sample)):
            assert register == max(-32768, min(32767, math.floor(value + 0.5)))
        # Without sensor_lag the drift is evaluated at the reported temperature.
        assert sample.drift_temperature_c == sample.reported_c


# --- each candidate, on minus off ---------------------------------------------


@PROPERTY
@given(seed=seeds, path=paths, tau=st.floats(1e-3, 3600.0), dt_s=st.sampled_from([0.01, 0.5, 2.0]))
def test_sensor_lag_evaluates_the_drift_at_a_lagged_reported_temperature(seed, path, tau, dt_s):
    on = run(model_with("sensor_lag", time_constant_s=tau), seed, path, dt_s)
    off = run(Model.load(), seed, path, dt_s)
    same_temperatures(on, off)
    # The structure starts at the first reported temperature: the die starts
    # at the chamber's, the sensor reports it 1 degC low.
    offset = Model.load().terms["temperature_offset"]["offset_c"]
    structure = path[0][0] + offset
    fraction = -math.expm1(-dt_s / tau)
    for with_lag, without in zip(on, off):
        structure += fraction * (with_lag.reported_c - structure)
        assert with_lag.drift_temperature_c == pytest.approx(structure, abs=1e-9)
        assert without.drift_temperature_c == without.reported_c
        assert ideal(with_lag) == ideal(without)
        expected = surfaces(with_lag, with_lag.drift_temperature_c, ideal(with_lag))
        assert drift(with_lag) == pytest.approx(expected, rel=1e-12, abs=EXACT)
        added = tuple(a - b for a, b in zip(unrounded(with_lag), unrounded(without)))
        lagged_minus_reported = tuple(
            a - b for a, b in zip(expected, surfaces(with_lag, with_lag.reported_c, ideal(with_lag)))
        )
        assert added == pytest.approx(lagged_minus_reported, rel=1e-9, abs=EXACT)
        assert errors(with_lag) == pytest.approx(errors(without), abs=EXACT)


def test_sensor_lag_is_first_order_and_leaves_the_register_alone():
    quiet = Model.load().with_terms(SENSOR_EFFECTS_OFF | {"drift": True, "sensor_lag": True})
    sensor = Sensor(quiet, seed=1, environment_c=20.0)
    for _ in range(3000):  # 30 s, one time constant
        sample = sensor.step(0.01, 30.0, 0.0, 0.0)
    assert sample.reported_c == 30.0 and sample.temperature_raw == 72
    assert sample.drift_temperature_c == pytest.approx(20.0 + 10.0 * (1 - math.exp(-1)), abs=1e-6)


@PROPERTY
@given(seed=seeds, path=paths, offset=st.fixed_dictionaries({axis: st.floats(-32768.0, 32768.0) for axis in AXES}))
def test_hysteresis_adds_its_offset_as_far_as_the_sensor_is_cooling(seed, path, offset):
    on = run(model_with("hysteresis", cooling_offset_lsb=offset), seed, path)
    off = run(Model.load(), seed, path)
    same_temperatures(on, off)
    for with_term, without in zip(on, off):
        assert (ideal(with_term), drift(with_term)) == (ideal(without), drift(without))
        added = tuple(a - b for a, b in zip(unrounded(with_term), unrounded(without)))
        expected = tuple((1.0 - with_term.warming_share) * offset[axis] for axis in AXES)
        assert added == pytest.approx(expected, rel=1e-12, abs=EXACT)


def test_hysteresis_follows_the_sets_of_a_warming_then_cooling_path():
    # 25 -> 26 warms; 25.25 is 0.75 degC below the peak, half of
    # set_transition_c (1.5 degC): half the offset; 24 is past it.
    quiet = Model.load().with_terms(SENSOR_EFFECTS_OFF | {"hysteresis": True})
    sensor = Sensor(quiet, 1, 25.0)
    samples = [sensor.step(0.01, t, 0.0, 0.0) for t in (25.0, 26.0, 25.25, 24.0)]
    assert [s.warming_share for s in samples] == [1.0, 1.0, 0.5, 0.0]
    assert [(s.ax, s.ay, s.az) for s in samples] == [(0, 0, 16393), (0, 0, 16393), (10, 10, 16393), (20, 20, 16393)]


@PROPERTY
@given(seed=seeds, path=paths, ppm=st.fixed_dictionaries({axis: st.floats(-10000.0, 10000.0) for axis in AXES}))
def test_scale_tempco_adds_c_times_the_excursion_from_25_c_times_the_ideal(seed, path, ppm):
    on = run(model_with("scale_tempco", ppm_per_c=ppm), seed, path)
    off = run(Model.load(), seed, path)
    same_temperatures(on, off)
    for with_term, without in zip(on, off):
        assert (ideal(with_term), drift(with_term)) == (ideal(without), drift(without))
        added = tuple(a - b for a, b in zip(unrounded(with_term), unrounded(without)))
        expected = tuple(
            ppm[axis] * 1e-6 * (with_term.reported_c - REFERENCE_C) * a for axis, a in zip(AXES, ideal(without))
        )
        assert added == pytest.approx(expected, rel=1e-9, abs=EXACT)


def test_scale_tempco_uses_the_reported_temperature_not_the_lagged_one():
    quiet = Model.load().with_terms(SENSOR_EFFECTS_OFF | {"scale_tempco": True, "sensor_lag": True})
    # X pointing down reads 1 g; the structure has barely left 0 degC.
    sample = Sensor(quiet, 1, 0.0).step(0.01, 45.0, 90.0, 0.0)
    assert sample.reported_c == 45.0 and sample.drift_temperature_c < 1.0
    g = sample.ideal_ax
    assert sample.unrounded_ax - g == pytest.approx(100e-6 * (45.0 - 25.0) * g)


@PROPERTY
@given(seed=seeds, path=paths, share=st.fixed_dictionaries({axis: st.floats(-0.1, 0.1) for axis in AXES}))
def test_cross_axis_mixes_in_a_share_of_another_axis(seed, path, share):
    on = run(model_with("cross_axis", share=share), seed, path)
    off = run(Model.load(), seed, path)
    same_temperatures(on, off)
    for with_term, without in zip(on, off):
        x, y, z = ideal(without)  # after sensitivity_loss, before cross_axis
        expected = (x + share["x"] * y, y + share["y"] * x, z + share["z"] * x)
        assert ideal(with_term) == pytest.approx(expected, rel=1e-15, abs=1e-9)
        # The drift sees the mixed acceleration; what follows it is unchanged.
        assert drift(with_term) == pytest.approx(
            surfaces(with_term, with_term.reported_c, ideal(with_term)), rel=1e-12, abs=EXACT
        )
        assert errors(with_term) == pytest.approx(errors(without), abs=EXACT)


def test_cross_axis_reads_a_share_of_x_on_y():
    quiet = Model.load().with_terms(SENSOR_EFFECTS_OFF | {"cross_axis": True})
    sample = Sensor(quiet, 1, 25.0).step(0.01, 25.0, 30.0, 0.0)
    g = Model.load().constants["sensor"]["lsb_per_g"]
    # 0.005 * g sin 30 = 40.98 LSB on Y; Z takes no share by default.
    assert sample.ideal_ay == pytest.approx(0.005 * g * 0.5, abs=1e-9)
    assert sample.ideal_az == pytest.approx(g * math.cos(math.radians(30.0)), abs=1e-9)
    assert sample.ay == 41
