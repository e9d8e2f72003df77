"""The twin's physics model against the paper, the datasheets and hand-worked
numbers (Sensors 2018, 18, 2536: "the paper")."""

import math
import statistics
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from thermotilt import native
from thermotilt.physics import (
    DECLARATIONS,
    FAULT_NAMES,
    TERMS,
    Chamber,
    Fault,
    Model,
    ModelError,
    Sensor,
    docs,
    parse_fault,
)
from thermotilt.physics.sensor import Trend, drift_sets
from thermotilt.physics.terms import REGISTRY
from thermotilt.surfaces import PAPER_DEFAULTS

DEFAULT_TOML = Path(__file__).resolve().parents[1] / "thermotilt" / "models" / "default.toml"
LSB_PER_G = 1 / 0.061e-3  # LSM9DS0 at +-2 g
CONTROL_PERIOD_S = 0.25  # firmware/thermal_chamber: CONTROL_PERIOD_MS

SENSOR_EFFECTS_OFF = {
    "die_lag": False,
    "drift": False,
    "rate_sensitivity": False,
    "temperature_offset": False,
    "sensitivity_loss": False,
    "noise": False,
    "measuring_offset": False,
    "drift_repeatability": False,
    "bias_instability": False,
}
# The discovery workflow's candidate terms, off by default (test_candidate_terms.py).
CANDIDATES = ("sensor_lag", "hysteresis", "scale_tempco", "cross_axis")
# The sources of the paper's scatter the surfaces do not explain (test_scatter.py).
SCATTER_OFF = {"drift_repeatability": False, "bias_instability": False}


@pytest.fixture(scope="module")
def model():
    return Model.load()


def run_p_control(model, ambient_c, setpoints, hold_s, dt_s=0.01):
    """The chamber's model in a loop with the firmware's own drive law
    (lib/ChamberControl through thermotilt.native): every 250 ms on the inner
    thermistor, the drive held until the next tick. Returns (time_s,
    setpoint, inner thermistor, signed pwm: + heats) per step."""
    chamber = Chamber(model, ambient_c)
    steps_per_tick = round(CONTROL_PERIOD_S / dt_s)
    steps_per_hold = round(hold_s / dt_s)
    trace = []
    duty, direction, signed_pwm = 0.0, 0, 0
    step = 0
    for setpoint in setpoints:
        for _ in range(steps_per_hold):
            if step % steps_per_tick == 0:
                pwm, drive = native.chamber_drive([setpoint], [chamber.inner_thermistor_c], CONTROL_PERIOD_S)
                direction = {native.DRIVE_OFF: 0, native.DRIVE_HEAT: 1, native.DRIVE_COOL: -1}[int(drive[0])]
                duty, signed_pwm = int(pwm[0]) / 255.0, int(pwm[0]) * direction
            chamber.step(dt_s, duty, direction, ambient_c)
            step += 1
            trace.append((step * dt_s, setpoint, chamber.inner_thermistor_c, signed_pwm))
    return trace


def hold_mean(trace, start_s, end_s, column=2):
    values = [row[column] for row in trace if start_s < row[0] <= end_s]
    return sum(values) / len(values)


# --- model file -------------------------------------------------------------


def test_default_model_has_every_term(model):
    assert model.source == "default"
    assert set(model.terms) == set(TERMS)
    # Every effect on; the discovery workflow's candidates off.
    assert {term: model.enabled(term) for term in TERMS} == {term: REGISTRY[term].enabled_by_default for term in TERMS}
    assert not any(model.enabled(term) for term in CANDIDATES)
    assert model.faults == ()


def test_the_docs_tables_are_the_declarations():
    # docs/physics-model.md's tables come from the terms' declarations;
    # `python -m thermotilt.physics.docs` rewrites them.
    text = docs.DOC.read_text(encoding="utf-8")
    assert docs.rendered(text) == text


def test_with_terms_switches_only_the_named_term(model):
    changed = model.with_terms({"noise": False})
    assert not changed.enabled("noise")
    assert model.enabled("noise")
    assert changed.terms["noise"]["sigma_lsb"] == model.terms["noise"]["sigma_lsb"]
    with pytest.raises(ModelError, match="unknown term 'wind'"):
        model.with_terms({"wind": True})


def test_with_faults_appends(model):
    first = Fault("inner_open", 120.0, 180.0)
    second = Fault("imu_uart_corrupt", rate=0.001)
    assert model.with_faults([first]).with_faults([second]).faults == (first, second)


def write_model(tmp_path, text):
    path = tmp_path / "model.toml"
    path.write_text(text, encoding="utf-8")
    return path


def default_text():
    return DEFAULT_TOML.read_text(encoding="utf-8")


def test_faults_are_read_from_the_file(tmp_path):
    path = write_model(
        tmp_path,
        default_text()
        + '\n[[faults]]\nname = "outer_short"\nstart_s = 10\nend_s = 20\n'
        + '\n[[faults]]\nname = "chamber_uart_corrupt"\nrate = 0.01\n',
    )
    loaded = Model.load(path)
    assert loaded.source == str(path)
    assert loaded.faults == (
        Fault("outer_short", 10.0, 20.0),
        Fault("chamber_uart_corrupt", rate=0.01),
    )


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t + "\n[wind]\nenabled = true\n", r"unknown section \[wind\]"),
        (
            lambda t: t.replace("offset_c = -1.0", "offset_c = -1.0\nslope = 2.0"),
            r"\[temperature_offset\] unknown parameter 'slope'",
        ),
        (
            lambda t: t.replace("schmitt_band_c = 0.5", ""),
            r"\[drift\] missing parameter 'schmitt_band_c'",
        ),
        (
            lambda t: t.replace("time_constant_s = 2.5", 'time_constant_s = "fast"'),
            r"\[thermistor_lag\] time_constant_s: expected a number, got 'fast'",
        ),
        (
            lambda t: t.replace("time_constant_s = 2.5", "time_constant_s = 0.0"),
            r"\[thermistor_lag\] time_constant_s: must be > 0",
        ),
        (
            lambda t: t.replace("[noise]\nenabled = true", "[noise]\nenabled = 1"),
            r"\[noise\] enabled: expected true or false",
        ),
        (
            lambda t: t.replace('coefficients = "paper"', 'coefficients = "table 9"'),
            r"\[drift\] coefficients: expected \"paper\"",
        ),
        (
            lambda t: t.replace("z = 1200.0 }", "w = 1200.0 }"),
            r"\[rate_sensitivity\] lsb_per_c_per_s: expected a table",
        ),
        (
            lambda t: t + '\n[[faults]]\nname = "meteor"\n',
            r"\[\[faults\]\] #1: unknown fault 'meteor'",
        ),
        (lambda t: t + '\n[[faults]]\nname = "imu_uart_corrupt"\n', r"needs a rate"),
        (lambda t: t + "\n[tilt\n", r"not valid TOML"),
    ],
)
def test_bad_model_files_name_file_term_and_problem(tmp_path, edit, message):
    path = write_model(tmp_path, edit(default_text()))
    with pytest.raises(ModelError, match=message) as raised:
        Model.load(path)
    text = str(raised.value)
    assert text.startswith(str(path))
    assert "\n" not in text


def test_an_omitted_table_takes_its_registered_defaults(tmp_path, model):
    text = default_text().replace("[tilt]\nenabled = true\n", "")
    assert Model.load(write_model(tmp_path, text)).terms["tilt"] == {"enabled": True}
    empty = Model.load(write_model(tmp_path, ""))
    assert empty.terms == model.terms and empty.constants == model.constants
    with pytest.raises(ModelError, match="cannot read"):
        Model.load(tmp_path / "absent.toml")


def test_the_default_file_states_every_registered_default(model):
    # default.toml spells out every parameter with its source; the registry
    # holds the same numbers for files that omit a table.
    document = tomllib.loads(default_text())
    assert set(document) == set(DECLARATIONS)
    for section, parameters in DECLARATIONS.items():
        assert list(document[section]) == [p.name for p in parameters], section
        for parameter in parameters:
            assert document[section][parameter.name] == parameter.default, (section, parameter)


def test_explicit_coefficients_replace_the_paper_tables(tmp_path):
    surfaces = "{ X = [100.0, 0, 0, 0, 0, 0], Y = [0, 0, 0, 0, 0, 0], Z = [0, 0, 0, 0, 0, 0] }"
    text = default_text().replace('coefficients = "paper"', f"coefficients = {{ W = {surfaces}, C = {surfaces} }}")
    loaded = Model.load(write_model(tmp_path, text))
    loaded = loaded.with_terms(SENSOR_EFFECTS_OFF | {"drift": True})
    sample = Sensor(loaded, seed=1, environment_c=30.0).step(0.01, 30.0, 0.0, 0.0)
    assert sample.drift_x == 100.0
    assert sample.ax == 100


# --- faults -----------------------------------------------------------------


def test_parse_fault_syntax():
    assert parse_fault("inner_open@120-180") == Fault("inner_open", 120.0, 180.0)
    assert parse_fault("imu_uart_corrupt=0.001") == Fault("imu_uart_corrupt", 0.0, None, 0.001)
    assert parse_fault("sensor_stuck@30") == Fault("sensor_stuck", 30.0)
    assert parse_fault("chamber_uart_corrupt=0.5@2.5-7") == Fault("chamber_uart_corrupt", 2.5, 7.0, 0.5)
    assert parse_fault("peltier_disconnected") == Fault("peltier_disconnected")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("meteor@10", "unknown fault 'meteor'"),
        ("inner_open=0.1", "takes no rate"),
        ("imu_uart_corrupt", "needs a rate"),
        ("imu_uart_corrupt=1.5", "needs a rate"),
        ("imu_uart_corrupt=lots", "must be numbers"),
        ("inner_open@180-120", "must be after start"),
        ("inner_open@", "expected NAME"),
        ("Inner_Open", "expected NAME"),
    ],
)
def test_parse_fault_rejects(text, message):
    with pytest.raises(ModelError, match=message):
        parse_fault(text)


def test_every_fault_name_parses():
    for name in FAULT_NAMES:
        text = f"{name}=0.01@1-2" if name.endswith("_uart_corrupt") else f"{name}@1-2"
        assert parse_fault(text).name == name


# --- chamber ----------------------------------------------------------------


def test_undriven_chamber_at_ambient_stays_at_ambient(model):
    chamber = Chamber(model, 21.3)
    for _ in range(60_000):
        chamber.step(0.01, 0.0, 0, 21.3)
    assert (chamber.inner_c, chamber.outer_c) == (21.3, 21.3)
    assert (chamber.inner_thermistor_c, chamber.outer_thermistor_c) == (21.3, 21.3)


def test_steady_state_matches_the_heat_balance(model):
    # Inner and outer nodes at constant drive, solved as a linear system from
    # the file's parameters:
    #   inner: -P d + f J d^2 + K (To - Ti) + Ga (Ta - Ti) = 0
    #   outer:  P d + (1 - f) J d^2 + K (Ti - To) + Gs (Ta - To) = 0
    terms = model.terms
    pumped = terms["peltier_pumping"]["full_duty_w"]
    joule = terms["joule_heating"]["full_duty_w"]
    share = terms["joule_heating"]["inner_fraction"]
    cell = terms["heatsink"]["inner_conductance_w_per_k"]
    sink = terms["heatsink"]["ambient_conductance_w_per_k"]
    leak = terms["ambient_leak"]["conductance_w_per_k"]
    ambient, duty = 20.0, 0.6
    heat = joule * duty**2
    matrix = np.array([[cell + leak, -cell], [-cell, cell + sink]])
    rhs = np.array(
        [
            -pumped * duty + share * heat + leak * ambient,
            pumped * duty + (1 - share) * heat + sink * ambient,
        ]
    )
    inner_expected, outer_expected = np.linalg.solve(matrix, rhs)

    # 4 h: many times the slowest time constant (inner face ~620 s).
    chamber = Chamber(model, ambient)
    for _ in range(288_000):
        chamber.step(0.05, duty, -1, ambient)
    assert chamber.inner_c == pytest.approx(inner_expected, abs=1e-3)
    assert chamber.outer_c == pytest.approx(outer_expected, abs=1e-3)


def drive(model, duty, direction, seconds=60.0, ambient=20.0):
    chamber = Chamber(model, ambient)
    for _ in range(round(seconds / 0.01)):
        chamber.step(0.01, duty, direction, ambient)
    return chamber


def test_without_pumping_and_joule_the_drive_does_nothing(model):
    chamber = drive(model.with_terms({"peltier_pumping": False, "joule_heating": False}), 1.0, -1)
    assert (chamber.inner_c, chamber.outer_c) == (20.0, 20.0)
    pumping_only = drive(model.with_terms({"joule_heating": False}), 1.0, -1)
    assert pumping_only.inner_c < 19.0 and pumping_only.outer_c > 20.5


def test_joule_heating_breaks_the_heat_cool_symmetry(model):
    no_joule = model.with_terms({"joule_heating": False})
    heated, cooled = drive(no_joule, 0.8, 1), drive(no_joule, 0.8, -1)
    assert heated.inner_c - 20.0 == pytest.approx(20.0 - cooled.inner_c, abs=1e-9)
    heated, cooled = drive(model, 0.8, 1), drive(model, 0.8, -1)
    assert heated.inner_c - 20.0 > (20.0 - cooled.inner_c) + 0.1


def test_ideal_heatsink_keeps_the_outer_face_at_ambient(model):
    chamber = drive(model.with_terms({"heatsink": False}), 1.0, -1)
    assert chamber.outer_c == 20.0 and chamber.outer_thermistor_c == 20.0
    assert drive(model, 1.0, -1).outer_c > 21.0


def test_ambient_leak_pulls_the_inner_face_to_ambient(model):
    # Without the leak and with an ideal heatsink, a face started elsewhere only
    # relaxes through the cell; the leak adds its own conductance.
    def relax(m):
        chamber = Chamber(m, 20.0)
        chamber.inner_c = 30.0
        for _ in range(1000):
            chamber.step(0.01, 0.0, 0, 20.0)
        return chamber.inner_c

    capacity = model.constants["chamber"]["inner_heat_capacity_j_per_k"]
    cell = model.terms["heatsink"]["inner_conductance_w_per_k"]
    leak = model.terms["ambient_leak"]["conductance_w_per_k"]
    sealed = model.with_terms({"heatsink": False, "ambient_leak": False})
    leaky = model.with_terms({"heatsink": False})
    sealed_expected = 20.0 + 10.0 * math.exp(-10.0 * cell / capacity)
    leaky_expected = 20.0 + 10.0 * math.exp(-10.0 * (cell + leak) / capacity)
    assert relax(sealed) == pytest.approx(sealed_expected, abs=1e-3)
    assert relax(leaky) == pytest.approx(leaky_expected, abs=1e-3)


def test_one_adc_code_spans_what_the_divider_slope_says(model):
    # V = S R / (R + Rref), R = R25 exp(beta (1/T - 1/T25)): at 25 degC with
    # R25 = Rref the slope is S beta / (4 T^2), so one code of S/1024 spans
    # 4 T^2 / (1024 beta) degC.
    constants = model.constants["chamber"]
    assert constants["thermistor_r25_ohm"] == constants["divider_reference_ohm"]
    kelvin = 25.0 + 273.15
    expected = 4.0 * kelvin**2 / (1024.0 * constants["thermistor_beta_k"])
    assert Chamber(model, 25.0).celsius_per_adc_code(25.0) == pytest.approx(expected, rel=1e-6)


def test_thermistor_lag_is_first_order(model):
    tau = model.terms["thermistor_lag"]["time_constant_s"]
    assert tau < 5.0  # paper section 3.1: thermal response below 5 s
    chamber = Chamber(model.with_terms({"heatsink": False}), 20.0)
    chamber.inner_c = 30.0
    chamber.step(tau, 0.0, 0, 20.0)
    # The face itself relaxes a little meanwhile; the reading follows it.
    moved = chamber.inner_thermistor_c - 20.0
    assert moved == pytest.approx((1 - math.exp(-1)) * (chamber.inner_c - 20.0), rel=0.02)
    instant = Chamber(model.with_terms({"thermistor_lag": False}), 20.0)
    instant.step(0.01, 1.0, 1, 20.0)
    assert instant.inner_thermistor_c == instant.inner_c


def test_divider_millivolts():
    chamber = Chamber(Model.load(), 25.0)
    assert chamber.thermistor_millivolts() == pytest.approx((2500.0, 2500.0), abs=1e-9)
    # beta equation by hand: R(0 degC) = 100k exp(3950 (1/273.15 - 1/298.15)) = 336.2 kOhm
    # -> 5000 * 336.2 / 436.2 = 3853.75 mV; R(45 degC) = 43.50 kOhm -> 1515.23 mV.
    chamber.inner_thermistor_c, chamber.outer_thermistor_c = 0.0, 45.0
    inner_mv, outer_mv = chamber.thermistor_millivolts()
    assert inner_mv == pytest.approx(3853.75, abs=0.05)
    assert outer_mv == pytest.approx(1515.23, abs=0.05)


@pytest.mark.parametrize(
    "terms, faults",
    [
        ({}, ()),
        ({"drive_dead_zone": True}, ()),
        ({"heatsink": False}, ()),
        ({"thermistor_lag": False, "thermistor_offset": True}, ()),
        ({}, ("inner_thermistor_detached", "heatsink_failed")),
    ],
)
def test_held_series_is_step_after_step(model, terms, faults):
    rng = np.random.default_rng(8)
    count = 600
    # Status frames about a second apart, some gaps long enough for step()
    # to split them into substeps; duties on a grid, so pairs repeat.
    dt_s = np.where(rng.random(count) < 0.05, rng.uniform(2.0, 100.0, count), rng.uniform(0.9, 1.1, count))
    duty = np.round(rng.random(count), 2)
    direction = rng.integers(-1, 2, count)
    ambient_c = 20.0 + np.cumsum(rng.normal(0.0, 0.01, count))
    changed = model.with_terms(terms)
    stepped, held = Chamber(changed, 20.0), Chamber(changed, 20.0)
    for chamber in (stepped, held):
        chamber.start_at_readings(31.0, 24.0)
        for fault in faults:
            setattr(chamber, fault, True)
    assert max(stepped.substeps(dt) for dt in dt_s.tolist()) > 1
    expected = []
    for dt, d, s, a in zip(dt_s.tolist(), duty.tolist(), direction.tolist(), ambient_c.tolist()):
        stepped.step(dt, d, s, a)
        expected.append((*stepped.readings_c(), stepped.inner_c))
    # A prefix scan sums in another order: the same values to rounding,
    # far below the 0.1 degC a reading is written to.
    np.testing.assert_allclose(np.array(held.held(dt_s, duty, direction, ambient_c)).T, expected, rtol=0, atol=1e-9)
    assert (held.inner_c, held.outer_c) == pytest.approx((stepped.inner_c, stepped.outer_c), abs=1e-9)
    assert held.readings_c() == pytest.approx(stepped.readings_c(), abs=1e-9)


def test_chamber_rejects_impossible_drive(model):
    chamber = Chamber(model, 20.0)
    with pytest.raises(ValueError, match="duty"):
        chamber.step(0.01, 1.5, 1, 20.0)
    with pytest.raises(ValueError, match="direction"):
        chamber.step(0.01, 0.5, 2, 20.0)
    with pytest.raises(ValueError, match="duty"):
        chamber.held(np.array([1.0]), np.array([1.5]), np.array([1]), np.array([20.0]))
    with pytest.raises(ValueError, match="direction"):
        chamber.held(np.array([1.0]), np.array([0.5]), np.array([2]), np.array([20.0]))
    with pytest.raises(ValueError, match="dt_s"):
        chamber.held(np.array([0.0]), np.array([0.5]), np.array([1]), np.array([20.0]))


# --- Figure 8 and the campaign range ----------------------------------------


@pytest.fixture(scope="module")
def figure8(model):
    setpoints = (16.0, 18.0, 20.0, 22.0)
    trace = run_p_control(model, 19.0, setpoints, 60.0)
    settled = [hold_mean(trace, 60.0 * k + 40.0, 60.0 * (k + 1)) for k in range(4)]
    return setpoints, trace, settled


@pytest.mark.twin
def test_figure8_two_degree_steps_take_about_13_s(figure8):
    # Paper section 3.1: "completed in approximately 13 s". Time from the
    # setpoint change to 90 % of the way between the two settled means.
    _, trace, settled = figure8
    for k in (1, 2, 3):
        start = 60.0 * k
        target = settled[k - 1] + 0.9 * (settled[k] - settled[k - 1])
        reached = next(t for t, _, reading, _ in trace if t > start and reading >= target)
        assert 10.0 <= reached - start <= 16.0


@pytest.mark.twin
def test_figure8_settled_offset_lies_on_the_ambient_side(figure8):
    # Paper section 3.1: measured above programmed below the external
    # temperature (19 degC here), below it above.
    setpoints, _, settled = figure8
    for setpoint, mean in zip(setpoints, settled):
        offset = mean - setpoint
        assert offset * (19.0 - setpoint) > 0
        # A P law settles at e = 255/350 * d_hold, and a chamber that holds
        # -10 degC at 22 degC ambient needs d_hold <= 0.1 within 3 K of
        # ambient (docs/physics-model.md, test_figure8's float bound before
        # its allowance for the thermistor's noise).
        assert abs(offset) < 255 / 350 * 0.1


@pytest.mark.twin
@pytest.mark.parametrize(("ambient", "setpoint"), [(22.0, -10.0), (20.0, -10.0), (20.0, 45.0), (22.0, 45.0)])
def test_chamber_reaches_and_holds_the_campaign_range(model, ambient, setpoint):
    trace = run_p_control(model, ambient, (setpoint,), 2400.0, dt_s=0.05)
    settled = hold_mean(trace, 2340.0, 2400.0)
    assert abs(settled - setpoint) < 1.5
    assert (settled - setpoint) * (ambient - setpoint) > 0


# --- sensor -----------------------------------------------------------------


def test_tilt_of_30_degrees_on_x(model):
    quiet = model.with_terms(SENSOR_EFFECTS_OFF)
    sample = Sensor(quiet, seed=1, environment_c=25.0).step(0.01, 25.0, 30.0, 0.0)
    # 1 g = 1 / 0.061 mg = 16393.44 LSB; sin 30 = 0.5, cos 30 = 0.8660
    assert sample.ideal_ax == pytest.approx(8196.72, abs=0.01)
    assert sample.ideal_ay == pytest.approx(0.0, abs=1e-9)
    assert sample.ideal_az == pytest.approx(14197.14, abs=0.01)
    assert (sample.ax, sample.ay, sample.az) == (8197, 0, 14197)


def test_tilt_off_leaves_the_sensor_flat(model):
    flat = model.with_terms(SENSOR_EFFECTS_OFF | {"tilt": False})
    sample = Sensor(flat, seed=1, environment_c=25.0).step(0.01, 25.0, 30.0, -20.0)
    assert (sample.ax, sample.ay, sample.az) == (0, 0, round(LSB_PER_G))


def test_sensitivity_loss_shrinks_large_accelerations(model):
    lossy = model.with_terms(SENSOR_EFFECTS_OFF | {"sensitivity_loss": True})
    k = model.terms["sensitivity_loss"]["gain_loss_at_1g"]
    sample = Sensor(lossy, seed=1, environment_c=25.0).step(0.01, 25.0, 30.0, 0.0)
    assert sample.ideal_ax == pytest.approx(LSB_PER_G * 0.5 * (1 - k * 0.25), abs=1e-6)
    assert sample.ideal_ax < 8196.72 - 10


def sweep(model, temperatures, incl_x=0.0, incl_y=0.0):
    sensor = Sensor(model, seed=3, environment_c=temperatures[0])
    return [sensor.step(0.01, t, incl_x, incl_y) for t in temperatures]


def test_paper_drift_over_the_calibration_range(model):
    # Paper section 4.1: X drifts "around 1300 LSB", Y "about 850 LSB" over
    # -10..45 degC. Tables 2 and 3 at 0 deg, by hand:
    #   warming X: f(45) - f(-10) = -550.26 - 763.36 = -1313.62
    #   warming Y:                  -280.14 - 493.31 =  -773.44
    #   cooling X: f(45) - f(-10) = -535.08 - 787.90 = -1322.99
    #   cooling Y:                  -305.60 - 463.00 =  -768.61
    # (so Y's tables give ~770 LSB, not 850).
    drift_only = model.with_terms(SENSOR_EFFECTS_OFF | {"drift": True})
    rising = sweep(drift_only, [-10.0 + 0.05 * i for i in range(1101)])
    assert {s.drift_set for s in rising} == {"W"}
    assert rising[-1].ax - rising[0].ax == pytest.approx(-1313.62, abs=1.0)
    assert rising[-1].ay - rising[0].ay == pytest.approx(-773.44, abs=1.0)
    # From 47: by 45 the die has cooled past set_transition_c (1.5 degC), so
    # the sensor is wholly in its cooling set.
    falling = sweep(drift_only, [47.0 - 0.05 * i for i in range(1141)])
    at_45 = next(s for s in falling if s.die_c <= 45.0 + 1e-9)
    assert at_45.drift_set == "C" and falling[-1].die_c == pytest.approx(-10.0)
    assert falling[-1].ax - at_45.ax == pytest.approx(1322.99, abs=1.0)
    assert falling[-1].ay - at_45.ay == pytest.approx(768.61, abs=1.0)


def test_drift_set_follows_the_trend_with_a_schmitt_band(model):
    drift_only = model.with_terms(SENSOR_EFFECTS_OFF | {"drift": True})
    path = [20.0, 21.0, 22.0, 21.6, 21.4, 21.6, 21.0, 20.0, 20.4, 20.6]
    sets = [s.drift_set for s in sweep(drift_only, path)]
    # 22 -> 21.6 is 0.4 below the peak (inside the 0.5 band), 21.4 is 0.6 below;
    # from the 20.0 trough, 20.6 is the first more than 0.5 above.
    assert sets == ["W", "W", "W", "W", "C", "C", "C", "C", "C", "W"]


def offsets_along(model, path):
    """The measuring offset on X (LSB) at each die temperature of path, the
    measuring offset alone switched on (set_transition_c 1.5 degC)."""
    assert model.terms["drift"]["set_transition_c"] == 1.5
    alone = model.with_terms(SENSOR_EFFECTS_OFF | {"measuring_offset": True})
    sensor = Sensor(alone, seed=1, environment_c=path[0])
    return np.array([sensor.step(0.01, t, 0.0, 0.0).unrounded_ax for t in path])


def test_the_offset_crosses_between_sets_over_the_transition_temperature(model):
    warming, cooling = (model.terms["measuring_offset"][key]["x"] for key in ("warming_lsb", "cooling_lsb"))
    # Up to 30, back down 0.75 degC (half of 1.5), up again, then down 3.
    path = [20.0, 30.0, 29.25, 30.0, 31.0, 30.25, 29.5, 28.0]
    offsets = offsets_along(model, path)
    expected_shares = [1.0, 1.0, 0.5, 1.0, 1.0, 0.5, 0.0, 0.0]
    assert offsets.tolist() == pytest.approx([cooling + s * (warming - cooling) for s in expected_shares])


def test_the_set_state_depends_on_the_path_not_the_rate(model):
    # The same turn at 0.1 and at 0.001 degC a step: the same offsets at the
    # same temperatures (a stop operator is rate-independent).
    fast = np.concatenate([np.linspace(25.0, 30.0, 51), np.linspace(30.0, 28.0, 21)[1:]])
    slow = np.concatenate([np.linspace(25.0, 30.0, 5001), np.linspace(30.0, 28.0, 2001)[1:]])
    assert offsets_along(model, fast)[-1] == pytest.approx(offsets_along(model, slow)[-1], abs=1e-6)
    assert offsets_along(model, fast)[55] == pytest.approx(offsets_along(model, slow)[5500], abs=1e-6)


def test_small_wiggles_move_the_offset_in_proportion_not_in_steps(model):
    # A plateau wandering +-0.1 degC moves the share by at most 0.2 / 1.5 of
    # the way between the sets: no jump from one set's offset to the other's.
    warming, cooling = (model.terms["measuring_offset"][key]["x"] for key in ("warming_lsb", "cooling_lsb"))
    wiggle = 25.0 + 0.1 * np.sin(np.linspace(0.0, 20.0 * np.pi, 2001))
    offsets = offsets_along(model, np.concatenate([[20.0], wiggle]))
    assert np.ptp(offsets[1:]) <= abs(warming - cooling) * 0.2 / 1.5 + 1e-9


def test_firmware_compensation_recovers_the_tilt(model):
    # The firmware computes raw - f(T, raw) with T = raw_temperature / 8 + 21.
    # The measuring offset, which the surfaces leave alone, is off here.
    quiet = model.with_terms(
        {"noise": False, "rate_sensitivity": False, "die_lag": False, "measuring_offset": False} | SCATTER_OFF
    )
    rising = [-10.0 + 0.05 * i for i in range(1101)]
    for sample in sweep(quiet, rising, incl_x=20.0, incl_y=-15.0)[::50]:
        reported = sample.temperature_raw / 8 + 21
        for raw, ideal, axis in (
            (sample.ax, sample.ideal_ax, "X"),
            (sample.ay, sample.ideal_ay, "Y"),
        ):
            compensated = raw - PAPER_DEFAULTS.surface("W", axis).evaluate(reported, raw)
            assert compensated == pytest.approx(ideal, abs=5.0)


def test_drift_is_indexed_by_the_reported_temperature(model):
    offset_only = model.with_terms(SENSOR_EFFECTS_OFF | {"drift": True, "temperature_offset": True})
    sample = Sensor(offset_only, seed=1, environment_c=30.0).step(0.01, 30.0, 0.0, 0.0)
    offset = model.terms["temperature_offset"]["offset_c"]
    assert sample.reported_c == pytest.approx(30.0 + offset)
    expected = PAPER_DEFAULTS.surface("W", "X").evaluate(30.0 + offset, 0.0)
    assert sample.drift_x == pytest.approx(expected)
    no_offset = Sensor(model.with_terms(SENSOR_EFFECTS_OFF), seed=1, environment_c=30.0)
    assert no_offset.step(0.01, 30.0, 0.0, 0.0).reported_c == 30.0


def test_temperature_register_has_eighth_degree_steps(model):
    plain = model.with_terms(SENSOR_EFFECTS_OFF)
    # raw = round((T - 21) * 8): 25.06 -> 32.48 -> 32; 25.07 -> 32.56 -> 33; 20.0 -> -8
    cases = ((25.0, 32), (25.06, 32), (25.07, 33), (20.0, -8), (-10.0, -248), (45.0, 192))
    for temperature, raw in cases:
        sample = Sensor(plain, seed=1, environment_c=temperature).step(0.01, temperature, 0, 0)
        assert sample.temperature_raw == raw
        assert abs(raw / 8 + 21 - temperature) <= 1 / 16


def test_without_quantisation_the_mean_code_carries_no_staircase(model):
    def mean_decoded(m):
        sensor = Sensor(m, seed=5, environment_c=21.05)
        codes = [sensor.step(0.01, 21.05, 0, 0).temperature_raw for _ in range(20_000)]
        return statistics.fmean(code / 8 + 21 for code in codes)

    plain = model.with_terms(SENSOR_EFFECTS_OFF)
    assert mean_decoded(plain) == 21.0  # 0.4 LSB always rounds down
    dithered = plain.with_terms({"temperature_quantisation": False})
    assert mean_decoded(dithered) == pytest.approx(21.05, abs=0.005)


def test_die_lag_is_first_order(model):
    tau = model.terms["die_lag"]["time_constant_s"]
    lagging = model.with_terms({"noise": False})
    sensor = Sensor(lagging, seed=1, environment_c=20.0)
    for _ in range(round(tau / 0.01)):
        sample = sensor.step(0.01, 30.0, 0, 0)
    assert sample.die_c == pytest.approx(20.0 + 10.0 * (1 - math.exp(-1)), abs=1e-6)
    instant = Sensor(lagging.with_terms({"die_lag": False}), seed=1, environment_c=20.0)
    assert instant.step(0.01, 30.0, 0, 0).die_c == 30.0


def test_rate_sensitivity_adds_gain_times_rate_on_z(model):
    gain = model.terms["rate_sensitivity"]["lsb_per_c_per_s"]["z"]
    assert gain > 0
    assert model.terms["rate_sensitivity"]["lsb_per_c_per_s"]["x"] == 0.0
    rate_only = model.with_terms(SENSOR_EFFECTS_OFF | {"rate_sensitivity": True})
    ramp = sweep(rate_only, [20.0 + 0.001 * i for i in range(100)])  # 0.1 degC/s
    assert ramp[-1].rate_c_per_s == pytest.approx(0.1)
    assert ramp[-1].az - round(LSB_PER_G) == pytest.approx(gain * 0.1, abs=0.6)
    assert ramp[-1].ax == 0
    flat = sweep(model.with_terms(SENSOR_EFFECTS_OFF), [20.0 + 0.001 * i for i in range(100)])
    assert flat[-1].az == round(LSB_PER_G)


def test_measuring_offset_shifts_each_axis_by_the_papers_set(model):
    # Paper section 4.1: X -1823 LSB warming, -1857 cooling; Y -143, -110.
    offset_only = model.with_terms(SENSOR_EFFECTS_OFF | {"measuring_offset": True})
    # The last two are more than set_transition_c (1.5 degC) below the peak.
    path = [25.0, 26.0, 24.0, 23.0]
    samples = sweep(offset_only, path)
    assert [s.drift_set for s in samples] == ["W", "W", "C", "C"]
    assert [(s.ax, s.ay, s.az) for s in samples] == [
        (-1823, -143, round(LSB_PER_G)),
        (-1823, -143, round(LSB_PER_G)),
        (-1857, -110, round(LSB_PER_G)),
        (-1857, -110, round(LSB_PER_G)),
    ]
    assert all((s.ideal_ax, s.drift_x) == (0.0, 0.0) for s in samples)


def test_the_paper_surfaces_leave_the_measuring_offset_in_the_compensated_reading(model):
    # Section 3.3: the surfaces compensate the thermal drift only; the
    # firmware's raw - f(T, raw) keeps the offset, within a few LSB (f is
    # evaluated at the offset reading).
    quiet = model.with_terms({"noise": False, "rate_sensitivity": False, "die_lag": False} | SCATTER_OFF)
    offset = model.terms["measuring_offset"]["warming_lsb"]
    for sample in sweep(quiet, [-10.0 + 0.05 * i for i in range(1101)], incl_x=20.0)[::100]:
        reported = sample.temperature_raw / 8 + 21
        for raw, ideal, axis in ((sample.ax, sample.ideal_ax, "X"), (sample.ay, sample.ideal_ay, "Y")):
            compensated = raw - PAPER_DEFAULTS.surface("W", axis).evaluate(reported, raw)
            assert compensated - ideal == pytest.approx(offset[axis.lower()], abs=6.0), axis


def test_noise_is_seeded_and_has_the_datasheet_sigma(model):
    noisy = model.with_terms(SENSOR_EFFECTS_OFF | {"noise": True})

    def draw(seed, n=20_000):
        sensor = Sensor(noisy, seed=seed, environment_c=25.0)
        return [sensor.step(0.01, 25.0, 0.0, 0.0) for _ in range(n)]

    first, again, other = draw(7), draw(7), draw(8)
    assert [s.ax for s in first] == [s.ax for s in again]
    assert [s.ax for s in first] != [s.ax for s in other]
    # 150 ug/sqrt(Hz) * sqrt(50 Hz) / 0.061 mg = 17.39 LSB (+ 1/sqrt(12) rounding)
    expected = math.hypot(150e-6 * math.sqrt(50) * LSB_PER_G, 1 / math.sqrt(12))
    one_g = round(LSB_PER_G)
    for values in ([s.ax for s in first], [s.ay for s in first], [s.az - one_g for s in first]):
        assert statistics.pstdev(values) == pytest.approx(expected, abs=0.4)
        assert abs(statistics.fmean(values)) < 0.5


def test_registers_saturate(model):
    drift_only = model.with_terms(SENSOR_EFFECTS_OFF | {"drift": True})
    # Warming X at -2000 degC: 571.5 + 20.23 * 2000 - 0.1044 * 2000^2 = -376568.5 LSB
    cold = Sensor(drift_only, seed=1, environment_c=-2000.0).step(0.01, -2000.0, 0.0, 0.0)
    assert cold.ax == -32768 and cold.temperature_raw == -2048
    hot = Sensor(drift_only, seed=1, environment_c=1000.0).step(0.01, 1000.0, 0.0, 0.0)
    assert hot.temperature_raw == 2047


@given(
    band_c=st.sampled_from([0.0, 0.25, 0.5, 1.0]),
    start_c=st.floats(-40.0, 85.0),
    moves=st.lists(st.sampled_from([-0.5, -0.25, -0.125, 0.0, 0.125, 0.25, 0.5, math.nan]), max_size=120),
)
def test_drift_sets_are_the_trend_updated_step_by_step(band_c, start_c, moves):
    """Walks in register steps (so excursions land on the band exactly),
    with unknown (NaN) temperatures the trend must step over."""
    die_c = start_c + np.nancumsum(moves)
    die_c[np.isnan(moves)] = math.nan
    trend = Trend(band_c, start_c)
    assert drift_sets(band_c, start_c, die_c).tolist() == [trend.update(value) for value in die_c.tolist()]
