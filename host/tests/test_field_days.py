"""`simulate field-days`: days of weather inside a closed box outdoors
(twin/weather.py), seeded, with the statistics its SiteWeather states, within
the calibration range, and a run of it through the CLI.

The statistical bounds are about five standard errors of each estimate over
50 seeds x 40 days (2000 days): a daily series with lag-1 correlation phi
carries (1 - phi) / (1 + phi) of the information of independent days, so
2000 days at phi = 0.7 count as about 350 (Wilks, "Statistical Methods in
the Atmospheric Sciences", the variance inflation of a mean under AR(1)).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict

import numpy as np
import pytest
from child_process import thermotilt

from thermotilt.cli import build_parser
from thermotilt.discovery.twin_gap import scenario_of
from thermotilt.run.log import read_run_columns
from thermotilt.run.summary import TWIN, RunSummary, read_summary
from thermotilt.twin.cli import _model_and_scenario
from thermotilt.twin.scenarios import SCENARIOS, ScenarioError, ScenarioOptions, build
from thermotilt.twin.weather import GRID_S, MAX_DAYS, SECONDS_PER_DAY, SITE, SiteWeather, draw_weather

SEEDS, DAYS = 50, 40
ROWS_PER_DAY = int(SECONDS_PER_DAY / GRID_S)


def hour_index(day, hour: float):
    """The grid row of that hour of that day (days counted from 0), or of each day of an array."""
    return np.asarray((day * SECONDS_PER_DAY + hour * 3600.0) // GRID_S, dtype=int)


@pytest.fixture(scope="module")
def many_days():
    """The air at each day's coldest and warmest hour, and the box's inside,
    for SEEDS draws of DAYS days."""
    day = np.arange(DAYS)
    cold, warm, inside = [], [], []
    for seed in range(SEEDS):
        drawn = draw_weather(DAYS, seed)
        cold.append(drawn.air_c[hour_index(day, SITE.coldest_hour)])
        warm.append(drawn.air_c[hour_index(day, SITE.warmest_hour)])
        inside.append(drawn.inside_c)
    return np.array(cold), np.array(warm), np.array(inside)


def effective_days(correlation: float = SITE.day_to_day_correlation) -> float:
    return SEEDS * DAYS * (1.0 - correlation) / (1.0 + correlation)


def test_the_same_seed_gives_the_same_weather_bit_for_bit():
    first, again = draw_weather(2, 5), draw_weather(2, 5)
    assert np.array_equal(first.inside_c, again.inside_c) and np.array_equal(first.air_c, again.air_c)
    times = np.linspace(0.0, 2 * SECONDS_PER_DAY, 997)
    one, two = (build("field-days", ScenarioOptions(days=2, seed=5)).ambient_c for _ in range(2))
    assert [one(t) for t in times] == [two(t) for t in times]
    assert all(type(one(t)) is float for t in times[:5])


def test_different_seeds_give_different_weather():
    five, six = draw_weather(2, 5), draw_weather(2, 6)
    assert np.max(np.abs(five.inside_c - six.inside_c)) > 1.0
    assert not np.array_equal(five.daily_mean_c, six.daily_mean_c)
    # The twin's seed range reaches 2**64 - 1.
    assert draw_weather(0.1, 2**64 - 1).inside_c.shape == (ROWS_PER_DAY // 10 + 1,)


def test_more_days_continue_the_same_weather():
    short, longer = draw_weather(1.5, 11), draw_weather(3, 11)
    assert np.array_equal(longer.inside_c[: len(short.inside_c)], short.inside_c)


def test_the_days_means_spread_and_persistence_are_the_sites(many_days):
    cold, warm, _ = many_days
    anomaly = (cold + warm) / 2.0 - SITE.daily_mean_c
    sd = SITE.daily_mean_sd_c
    # The mean of the days' means: standard error sd / sqrt(effective days).
    assert abs(anomaly.mean()) < 5 * sd / math.sqrt(effective_days())
    # Their standard deviation: relative standard error sqrt((1 + phi^2) / (1 - phi^2) / 2N), 2.6 %.
    phi = SITE.day_to_day_correlation
    relative = math.sqrt((1 + phi**2) / (1 - phi**2) / (2 * SEEDS * DAYS))
    assert math.sqrt(np.mean(anomaly**2)) == pytest.approx(sd, rel=5 * relative)
    # From one day to the next the mean moves by sd * sqrt(2 (1 - phi)), 1.9 degC.
    step = np.diff(anomaly, axis=1)
    assert math.sqrt(np.mean(step**2)) == pytest.approx(sd * math.sqrt(2 * (1 - phi)), rel=5 * relative)
    # Lag-1 correlation: standard error sqrt((1 - phi^2) / N), 0.016.
    lag1 = np.sum(anomaly[:, 1:] * anomaly[:, :-1]) / np.sum(anomaly[:, :-1] ** 2)
    assert lag1 == pytest.approx(phi, abs=5 * math.sqrt((1 - phi**2) / (SEEDS * DAYS)))


def test_the_days_diurnal_range_is_the_sites(many_days):
    cold, warm, _ = many_days
    diurnal = warm - cold
    # The gusts add their own spread at both hours: sqrt(2) * gust_sd to the range's.
    spread = math.hypot(SITE.diurnal_range_sd_c, math.sqrt(2) * SITE.gust_sd_c)
    assert abs(diurnal.mean() - SITE.diurnal_range_c) < 5 * spread / math.sqrt(effective_days())
    phi = SITE.day_to_day_correlation
    relative = math.sqrt((1 + phi**2) / (1 - phi**2) / (2 * SEEDS * DAYS))
    assert diurnal.std() == pytest.approx(spread, rel=5 * relative)


def test_the_box_stays_within_the_calibration_range(many_days):
    _, _, inside = many_days
    assert SITE.lowest_c == -10.0 and SITE.highest_c == 45.0
    assert inside.min() >= SITE.lowest_c and inside.max() <= SITE.highest_c
    # The defaults keep the inside off the clip nearly always (0.006 % of
    # these 2000 days); the clip is a bound, not the weather.
    assert np.mean((inside == SITE.highest_c) | (inside == SITE.lowest_c)) < 1e-3
    # A hotter site is held at the calibration's top.
    assert draw_weather(3, 1, SiteWeather(daily_mean_c=35.0)).inside_c.max() == 45.0


def test_the_sun_heats_the_box_and_clouds_cut_it():
    def noon_excess(site: SiteWeather) -> np.ndarray:
        """Each of 10 days' largest excess of the inside over the air, 11:00-13:00."""
        drawn = draw_weather(10, 3, site)
        excess = drawn.inside_c - drawn.air_c
        return np.array([excess[int(hour_index(day, 11.0)) : int(hour_index(day, 13.0))].max() for day in range(10)])

    # Gusts reach the air at once and the inside through the box's lag: 5 gust_sd apart at most.
    clear = noon_excess(SiteWeather(cloud_cover=0.0, cloud_cover_per_range_c=0.0))
    assert clear == pytest.approx(SITE.clear_sky_gain_c, abs=5 * SITE.gust_sd_c)
    overcast = noon_excess(SiteWeather(cloud_cover=1.0, cloud_cover_per_range_c=0.0))
    assert overcast == pytest.approx(SITE.cloud_transmission * SITE.clear_sky_gain_c, abs=5 * SITE.gust_sd_c)
    # At night the box is the air, lagged.
    drawn = draw_weather(2, 3)
    night = slice(int(hour_index(1, 2.0)), int(hour_index(1, 4.0)))
    assert np.abs(drawn.inside_c[night] - drawn.air_c[night]).max() < 5 * SITE.gust_sd_c


def test_the_scenario_plays_the_days_from_midnight_or_compressed():
    drawn = draw_weather(1, 3)
    natural = build("field-days", ScenarioOptions(days=1, seed=3, incl_x_deg=20.0))
    assert natural.duration_s == SECONDS_PER_DAY and not natural.uses_chamber
    assert natural.positions[0].incl_x_deg == 20.0
    assert natural.ambient_c(12 * 3600.0) == drawn.inside_c[ROWS_PER_DAY // 2]
    compressed = build("field-days", ScenarioOptions(days=1, seed=3, duration_s=864.0))
    assert compressed.duration_s == 864.0 and "compressed into 864 s" in compressed.description
    assert compressed.ambient_c(432.0) == pytest.approx(drawn.inside_c[ROWS_PER_DAY // 2], abs=1e-12)
    assert build("field-days", ScenarioOptions()).duration_s == 2 * SECONDS_PER_DAY


@pytest.mark.parametrize(
    "name, options, message",
    [
        ("field-days", ScenarioOptions(days=0), "--days must be more than 0"),
        ("field-days", ScenarioOptions(days=-1), "--days must be more than 0"),
        ("field-days", ScenarioOptions(days=math.nan), "got nan"),
        ("field-days", ScenarioOptions(days=MAX_DAYS + 1), f"at most {MAX_DAYS:g}"),
        ("field-warming", ScenarioOptions(days=1), "--days is for field-days, not field-warming"),
        ("cycle", ScenarioOptions(days=2), "--days is for field-days, not cycle"),
    ],
)
def test_bad_days_are_refused_with_a_reason(name, options, message):
    with pytest.raises(ScenarioError, match=message):
        build(name, options)


@pytest.mark.parametrize("name", [name for name in SCENARIOS if name != "field-days"])
def test_the_seed_changes_no_other_scenario(name):
    plain, seeded = build(name, ScenarioOptions()), build(name, ScenarioOptions(seed=12345))
    assert (plain.duration_s, plain.commands, plain.positions, plain.marks) == (
        seeded.duration_s,
        seeded.commands,
        seeded.positions,
        seeded.marks,
    )
    times = np.linspace(0.0, plain.duration_s, 101)
    assert [plain.ambient_c(t) for t in times] == [seeded.ambient_c(t) for t in times]


@pytest.mark.parametrize(("name", "kept_seed"), [("field-days", 7), ("fig8", 0), ("field-warming", 0)])
def test_the_command_line_gives_its_seed_to_the_weather_alone(name, kept_seed):
    # A scenario that draws nothing keeps the default seed, so that its
    # summary's options read as they did before field-days.
    args = build_parser().parse_args(["simulate", name, "--seed", "7", "--incl-y", "-15"])
    _, scenario = _model_and_scenario(args)
    assert scenario.options.seed == kept_seed and scenario.positions[0].incl_y_deg == -15.0


def write_summary(folder, scenario: str, options: dict) -> None:
    (folder / "run.csv").write_text("")
    summary = RunSummary(TWIN, 0, "60 s simulated", 1.0, {}, scenario=scenario, options=options, seed=1)
    summary.write(folder)


def test_a_summary_from_before_days_and_seed_builds_its_scenario_again(tmp_path):
    old = {
        key: value for key, value in asdict(ScenarioOptions(duration_s=900.0)).items() if key not in ("days", "seed")
    }
    write_summary(tmp_path, "field-cooling", old)
    scenario, seed, faults = scenario_of(tmp_path)
    assert scenario.name == "field-cooling" and scenario.options == ScenarioOptions(duration_s=900.0)
    assert (seed, faults) == (1, [])


def test_a_field_days_summary_builds_the_same_weather_again(tmp_path):
    options = ScenarioOptions(days=0.5, seed=9, duration_s=600.0)
    write_summary(tmp_path, "field-days", json.loads(json.dumps(asdict(options))))
    scenario, _, _ = scenario_of(tmp_path)
    original = build("field-days", options)
    times = np.linspace(0.0, 600.0, 61)
    assert [scenario.ambient_c(t) for t in times] == [original.ambient_c(t) for t in times]


@pytest.mark.slow
@pytest.mark.twin
def test_a_short_field_days_run_of_a_batch_sensor_makes_a_run_folder(tmp_path):
    model = tmp_path / "batch.toml"
    model.write_text('[[sensors]]\nid = "TT-07"\n', encoding="utf-8")
    out = tmp_path / "run"
    result = thermotilt(
        "simulate", "field-days", "--days", "0.25", "--duration", "20", "--incl-x", "20", "--seed", "5",
        "--model", model, "--sensor", "TT-07", "--out", out,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "field days: 0.25 days of weather from midnight (seed 5)" in result.stdout
    assert "day 1: inside " in result.stdout
    summary = read_summary(out)
    assert summary.options["days"] == 0.25 and summary.options["seed"] == 5 and summary.seed == 5
    assert summary.positions[0]["incl_x_deg"] == 20.0 and "TT-07" in summary.model
    columns = read_run_columns(str(out / "run.csv"))
    ambient = build("field-days", ScenarioOptions(days=0.25, seed=5, duration_s=20.0)).ambient_c
    # Each row holds the ambient of the 10 ms step its frame came in: the profile within 0.1 s of its time.
    for t, recorded in zip(columns.numbers["time_s"], columns.numbers["ambient_c"]):
        near = [ambient(t + offset) for offset in np.linspace(-0.1, 0.1, 21)]
        assert min(near) - 0.001 <= recorded <= max(near) + 0.001, (t, recorded)


@pytest.mark.parametrize(
    "args, status, message",
    [
        (["field-days", "--days", "0"], 1, "--days must be more than 0 and at most 49, got 0"),
        (["field-days", "--days", "nan"], 1, "--days must be more than 0 and at most 49, got nan"),
        (["field-warming", "--days", "1"], 1, "--days is for field-days, not field-warming"),
        (["field-days", "--days", "two"], 2, "argument --days: invalid float value: 'two'"),
    ],
)
def test_bad_days_on_the_command_line_are_one_line(cli_in_process, tmp_path, args, status, message):
    out = tmp_path / "run"
    result = cli_in_process("simulate", *args, "--out", out)
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("thermotilt: error: ") and message in lines[0], result.stderr
    assert result.returncode == status and not out.exists()
