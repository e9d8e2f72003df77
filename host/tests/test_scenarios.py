"""Scenario timelines: the paper's experiments as commands, positions and
ambient profiles (no simulation runs here)."""

import pytest

from thermotilt.physics import Model
from thermotilt.twin.scenarios import (
    FIELD_SENSOR_OFFSET_C,
    ScenarioError,
    ScenarioOptions,
    build,
    campaign_positions,
    program_steps,
    reach_allowance_s,
)
from thermotilt.wire.protocol import build_frame, parse_line


def test_program_steps_match_the_firmware_staircase():
    # lib/Program's header: -10..45 degC in 2 degC steps is 29 warming + 28 cooling.
    assert program_steps(-10.0, 45.0, 2.0) == 57
    # 16..22: 16, 18, 20, 22 up, 20, 18, 16 down.
    assert program_steps(16.0, 22.0, 2.0) == 7


def test_fig8_programs_four_one_minute_steps_from_16_degC():
    scenario = build("fig8", ScenarioOptions())
    setprg, start = scenario.commands
    assert setprg.frame_type == "SETPRG" and start.frame_type == "START"
    # Every hold waits for its setpoint (the twin's default), so the run lasts
    # four holds and the approaches.
    assert setprg.values[:4] == (16.0, 22.0, 2.0, 60) and setprg.values[-1] == "A"
    assert start.at_s > setprg.at_s
    allowance = reach_allowance_s(16.0, 4, 19.0, ScenarioOptions())
    assert allowance > 0
    assert scenario.duration_s == pytest.approx(start.at_s + 4 * 60 + allowance)
    # The commands are valid frames for the chamber.
    frame = parse_line(build_frame("SETPRG", 0, setprg.values))
    assert frame["start_c"] == 16.0 and frame["hold_s"] == 60
    # 19 degC lies between the 18 and 20 degC steps: the run crosses ambient.
    assert 18.0 < scenario.ambient_c(100.0) < 20.0


def test_fig8_sends_the_rounded_error_controller_before_start():
    commands = build("fig8", ScenarioOptions(controller="rounded-error")).commands
    assert [c.frame_type for c in commands] == ["SETPRG", "SETCTL", "START"]
    assert commands[1].values == ("PR", 350.0, 0.0)
    assert commands[0].at_s < commands[1].at_s < commands[2].at_s
    parse_line(build_frame("SETCTL", 0, commands[1].values))


def test_cycle_lasts_57_holds_and_the_rest():
    timed = build("cycle", ScenarioOptions(hold_s=30, rest_s=100, hold_start="T"))
    assert timed.duration_s == pytest.approx(1.5 + 57 * 30 + 100)
    assert [c.frame_type for c in timed.commands] == ["SETPRG", "START"]
    scenario = build("cycle", ScenarioOptions(hold_s=30, rest_s=100, incl_x_deg=30.0))
    assert scenario.duration_s == pytest.approx(
        1.5 + 57 * 30 + 100 + reach_allowance_s(-10.0, 57, 22.0, ScenarioOptions())
    )
    assert [c.frame_type for c in scenario.commands] == ["SETPRG", "START"]
    assert scenario.positions[0].incl_x_deg == 30.0
    assert scenario.positions[0].label == "X+30"


def test_campaign_has_the_papers_37_positions():
    labels = [label for label, _, _ in campaign_positions()]
    assert len(labels) == 37 and len(set(labels)) == 37
    assert labels[0] == "0"
    assert {"X+5", "X-45", "Y+45", "Y-5"} <= set(labels)
    angles = {label: (x, y) for label, x, y in campaign_positions()}
    assert angles["Y-15"] == (0.0, -15.0) and angles["X+40"] == (40.0, 0.0)


def test_campaign_subset_runs_each_position_through_a_cycle():
    options = ScenarioOptions(hold_s=10, rest_s=20, positions=("0", "X+30"))
    scenario = build("campaign", options)
    cycle_s = build("cycle", options).duration_s
    assert [p.label for p in scenario.positions] == ["0", "X+30"]
    assert scenario.positions[1].at_s == pytest.approx(cycle_s)
    assert [(c.board, c.frame_type) for c in scenario.commands] == [
        ("imu_reader", "RESEED"),
        ("thermal_chamber", "SETPRG"),
        ("thermal_chamber", "START"),
        ("imu_reader", "RESEED"),
        ("thermal_chamber", "START"),
    ]
    assert [c.at_s for c in scenario.commands] == sorted(c.at_s for c in scenario.commands)
    assert scenario.duration_s == pytest.approx(2 * cycle_s)


def test_field_scenarios_follow_the_papers_profiles():
    # Section 4.3 states the temperatures the LSM9DS0 read: the air is warmer
    # by the default model's sensor offset.
    assert FIELD_SENSOR_OFFSET_C == Model.load().terms["temperature_offset"]["offset_c"]

    def read(scenario, t):
        return scenario.ambient_c(t) + FIELD_SENSOR_OFFSET_C

    warming = build("field-warming", ScenarioOptions())
    assert not warming.uses_chamber and warming.duration_s == 3 * 3600
    assert read(warming, 0) == pytest.approx(9.0)
    assert read(warming, warming.duration_s) == pytest.approx(48.0)
    # A straight ramp (docs/physics-model.md, "Field tests").
    assert read(warming, 3600) == pytest.approx(22.0)
    cooling = build("field-cooling", ScenarioOptions(duration_s=900))
    assert cooling.duration_s == 900
    assert read(cooling, 0) == pytest.approx(26.0) and read(cooling, 900) == pytest.approx(16.0)
    assert read(cooling, 450) == pytest.approx(21.0)
    alternating = build("field-alternating", ScenarioOptions())
    samples = [alternating.ambient_c(t) for t in range(0, 12 * 3600, 600)]
    rises = sum(1 for a, b in zip(samples, samples[1:]) if b > a)
    assert 0.3 < rises / (len(samples) - 1) < 0.7


@pytest.mark.parametrize(
    "name, options, message",
    [
        ("fig9", ScenarioOptions(), "unknown scenario"),
        ("campaign", ScenarioOptions(positions=("X+7",)), "unknown position"),
        ("cycle", ScenarioOptions(hold_s=0), "--hold-seconds"),
        ("cycle", ScenarioOptions(incl_x_deg=120.0), "outside -90..90"),
        ("cycle", ScenarioOptions(hold_start="X"), "hold start"),
        ("fig8", ScenarioOptions(controller="pid"), "unknown controller"),
    ],
)
def test_bad_options_are_refused_with_a_reason(name, options, message):
    with pytest.raises(ScenarioError, match=message):
        build(name, options)
