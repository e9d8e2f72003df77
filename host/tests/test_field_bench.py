"""The field benchmark's machinery (the benchmark itself is `make
bench-field`; docs/benchmarks/field-accuracy.md): the host replay is the
twin's run (a field run to the printed digit, a chamber run within the
tolerance its interpolated face leaves), a tiny design runs on a Dask
cluster and resumes from its record, and the page regenerates from a record
with Wilson intervals that recompute."""

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from distributed import LocalCluster

from thermotilt.calibration import field_accuracy
from thermotilt.calibration.campaign.folder import CAMPAIGN_FILE, DONE
from thermotilt.calibration.campaign.plan import select_positions
from thermotilt.calibration.field_bench import (
    COLUMNS,
    NO,
    YES,
    Design,
    Task,
    read_record,
    run_bench,
    run_field,
    slope_reference_u95,
)
from thermotilt.calibration.field_calibration import (
    BASE_SENSOR,
    BaseDesign,
    SensorCalibration,
    load_base,
    sensor_model,
)
from thermotilt.calibration.field_replay import (
    DEFAULTS_CLOCK,
    EEPROM_CLOCK,
    FIELD_PROFILES,
    TWIN_TOLERANCE,
    SensorInputs,
    field_inputs,
    field_scenario,
    position_inputs,
    printed,
    replay_frames,
    twin_gap,
    within_tolerance,
)
from thermotilt.lsm9ds0 import LSB_PER_G
from thermotilt.physics.terms.sensor import coefficient_table_of
from thermotilt.run.folder import RunFolder
from thermotilt.run.log import RunLogWriter, format_numbers, read_run_columns
from thermotilt.twin import simulate
from thermotilt.twin.scenarios import ScenarioOptions, build
from thermotilt.wire.coefficients import encode_block

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
import generated_page  # noqa: E402

# ---- the replay is the twin's ----------------------------------------------


@pytest.mark.twin
@pytest.mark.parametrize("profile", ["field-warming", "field-cooling"])
def test_a_field_replay_is_the_twins_run_to_the_printed_digit(tmp_path, profile):
    """A sensor of the batch in the twin's field run (compressed to 90 s;
    field-cooling's sensor starts in its cooling state) at 20 deg, its
    fitted-like coefficients in the IMU's EEPROM: the host replay gives
    every frame the firmware sent, each value as it printed it, the same
    set, at the same time."""
    sensor = "TT-03"
    model = sensor_model(10, 1, sensor)
    task = Task(sensor, profile, 20.0, 0)
    scenario = field_scenario(task.profile, task.tilt_deg, task.seed, duration_s=90.0)
    table = coefficient_table_of(model.terms["drift"]["coefficients"])
    imu = simulate.ImuRun(model, tmp_path / "run", task.seed, eeprom=encode_block(table, sensor), sensor_id=sensor)
    simulate.run_sensors(scenario, model, [imu])
    columns = read_run_columns(str(RunFolder.at(tmp_path / "run").log))
    assert set(columns.texts["coef_source"]) == {"E"}

    inputs = field_inputs(scenario)
    assert inputs.warming_share == (0.0 if profile == "field-cooling" else 1.0)
    frames = replay_frames(model, task.seed, inputs, table)
    # The firmware loads the block at start, which puts its frames a step later.
    assert inputs.frame_steps[0] == EEPROM_CLOCK.first_step
    assert len(inputs.frame_steps) == columns.rows > 850
    assert np.array_equal(inputs.time_s, columns.numbers["time_s"])
    for name in ("ax_raw", "ay_raw", "az_raw"):
        assert np.array_equal(frames[name], columns.numbers[name]), name
    gaps = twin_gap(columns, frames)
    assert max(gaps.values()) < 1e-9, gaps


@pytest.mark.slow
@pytest.mark.twin
def test_a_chamber_runs_replay_is_the_twins_within_its_tolerance(tmp_path):
    """Another sensor than the base's in a twin chamber run (Figure 8, 15 s
    holds), replayed from its run.csv as a base position is: the face known
    one step in ten to 1e-4 degC puts a few register values 1 LSB off, which
    the filters pass on at a hundredth; every frame within TWIN_TOLERANCE of
    the twin's beyond the printed rounding, every set the same."""
    model = sensor_model(10, 1, "TT-02")
    simulate.run_sensors(build("fig8", ScenarioOptions(hold_s=15)), model, [simulate.ImuRun(model, tmp_path, 7)])
    columns = read_run_columns(str(RunFolder.at(tmp_path).log))
    frames = replay_frames(model, 7, position_inputs(columns))
    gaps = twin_gap(columns, frames)
    assert within_tolerance(gaps), gaps
    assert gaps["comp_set"] == 0.0
    # The tolerance is the replay's: a sensor it was not made for is far off.
    other = twin_gap(columns, replay_frames(sensor_model(10, 1, "TT-04"), 7, position_inputs(columns)))
    assert other["ax_filt"] > 100 * TWIN_TOLERANCE["lsb"]


# ---- a tiny design on a cluster ---------------------------------------------

# Five positions, each a ramp from the room down to -10, up to 45 and back
# down at 0.2 degC/s (no chamber program: no phase column), enough for the
# fit and the certificate; written as a twin campaign of the base's sensor,
# its frames the replay's own.
TINY_POSITIONS = "0,X+30,X-30,Y+30,Y-30"
RAMP_C = (22.0, -10.0, 45.0, -10.0)
RAMP_C_PER_S = 0.2


def _ramp_inputs(incl_x: float, incl_y: float) -> SensorInputs:
    knots_s = np.cumsum([0.0] + [abs(b - a) / RAMP_C_PER_S for a, b in zip(RAMP_C, RAMP_C[1:])])
    steps = int(knots_s[-1] / 0.01)
    frame_steps = np.arange(DEFAULTS_CLOCK.first_step, steps - 1, 10)
    # The face at the rows' steps (one after each frame's sample), to 1e-4
    # degC as run.csv holds it, and linear between them: what
    # position_inputs reads back.
    face = np.round(np.interp((frame_steps + 1) * 0.01, knots_s, RAMP_C), 4)
    environment = np.interp(np.arange(steps), frame_steps + 1, face)
    return SensorInputs(RAMP_C[0], environment, incl_x, incl_y, frame_steps)


def _write_base(folder: Path, design: BaseDesign) -> None:
    setup = design.setup(1)
    model = sensor_model(1, design.seed, BASE_SENSOR)
    records = []
    for position in select_positions(design.positions):
        inputs = _ramp_inputs(position.incl_x_deg, position.incl_y_deg)
        seed = setup.position_seed(position, BASE_SENSOR)
        frames = printed(replay_frames(model, seed, inputs))
        raw = replay_frames(model, seed, inputs)
        count = len(inputs.frame_steps)
        time_s = inputs.time_s
        cells = {
            "time_s": format_numbers(time_s.tolist(), 3),
            "ambient_c": ["22.000"] * count,
            "chamber_c": format_numbers(inputs.environment_c[inputs.frame_steps].tolist(), 2),
            "incl_x_deg": format_numbers([position.incl_x_deg] * count, 3),
            "incl_y_deg": format_numbers([position.incl_y_deg] * count, 3),
            "since_move_s": format_numbers(time_s.tolist(), 3),
            "true_inner_c": format_numbers(inputs.environment_c[inputs.frame_steps + 1].tolist(), 4),
            "imu_temp_c": format_numbers(frames["temp_c"].tolist(), 3),
            "comp_set": ["C" if value else "W" for value in raw["set"].tolist()],
            "coef_source": ["D"] * count,
        }
        for name in ("ax_filt", "ay_filt", "az_filt", "ax_comp", "ay_comp", "az_comp"):
            cells[name] = format_numbers(frames[name].tolist(), 1)
        for name in ("ax_raw", "ay_raw", "az_raw"):
            cells[name] = [str(value) for value in raw[name].tolist()]
        log = RunFolder.at(folder / BASE_SENSOR / position.label).log
        log.parent.mkdir(parents=True)
        with open(log, "w", newline="", encoding="utf-8") as stream:
            RunLogWriter(stream, with_truth=True, flush_each_row=False).write_columns(cells)
        records.append({"label": position.label, "status": DONE, "seed": seed, "sensor_id": BASE_SENSOR})
    document = {"seed": design.seed, "program": {"hold_s": design.hold_s, "rest_s": design.rest_s}}
    (folder / BASE_SENSOR / CAMPAIGN_FILE).write_text(json.dumps({**document, "positions": records}))


TINY = Design(
    sensors=2,
    profiles=("field-warming",),
    tilts_deg=(20.0,),
    base=BaseDesign(positions=TINY_POSITIONS, hold_s=1, rest_s=0, seed=3),
    duration_s=300.0,
)


def _without_seconds(row):
    return {key: value for key, value in row.items() if key != "seconds"}


@pytest.mark.slow
@pytest.mark.twin
def test_a_tiny_design_runs_on_a_cluster_and_resumes_from_its_record(tmp_path):
    folder, record = tmp_path / "bench", tmp_path / "runs.csv"
    _write_base(folder / "base", TINY.base)
    base, gaps = load_base(folder / "base", TINY.base)
    assert all(within_tolerance(gap) for gap in gaps.values()), gaps
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address="127.0.0.1:0") as cluster:
        with cluster.get_client() as client:
            said = []
            first = run_bench(TINY, record, folder, client, say=said.append)
            assert (first.done, first.todo, first.failed) == (2, 0, [])
            assert sum("calibrated" in line for line in said) == 2
            rows = read_record(record)
            assert [row["key"] for row in rows] == [task.key for task in TINY.tasks()]
            assert {row["base"] for row in rows} == {base.digest}
            # A second start runs nothing and calibrates nothing.
            said.clear()
            second = run_bench(TINY, record, folder, client, say=said.append)
            assert (second.done, second.todo) == (2, 0) and not said
            assert read_record(record) == rows
            # A row of other sources is stale: it runs again, its sensor's
            # calibration from the cache, and comes out the same.
            stale = [{**rows[0], "method": "other"}, rows[1]]
            with open(record, "w", newline="") as stream:
                stream.write(",".join(COLUMNS) + "\n")
                for row in stale:
                    stream.write(",".join(str(row[column]) for column in COLUMNS) + "\n")
            said.clear()
            third = run_bench(TINY, record, folder, client, say=said.append)
            assert third.done == 2 and "1 rows" in said[0] and not any("calibrated" in line for line in said)
            assert [_without_seconds(r) for r in read_record(record)] == [_without_seconds(r) for r in rows]
    for row in rows:
        assert row["within"] in (YES, NO)
        assert float(row["p95_change_deg"]) > 0 and float(row["u95_deg"]) > 0
        assert (row["within"] == YES) == (float(row["p95_change_deg"]) <= float(row["u95_deg"]))
        assert 0.0 <= float(row["rows_within_share"]) <= 1.0 and int(row["rows"]) > 0
        # The default model draws a drift slope per mounting, so every run has the yardstick.
        assert float(row["slope_u95_deg"]) > 0 and 0.0 <= float(row["rows_within_slope_share"]) <= 1.0
    # A row made again alone, from its key's seed and its sensor's calibration, is the same row.
    cached = next((folder / "calibrations").glob(f"*/{rows[1]['sensor']}.json"))
    calibration = SensorCalibration.from_json(cached.read_text())
    again = run_field(TINY.tasks()[1], calibration, TINY)
    assert _without_seconds({k: str(v) for k, v in again.items() if k != "base"}) == _without_seconds(
        {k: v for k, v in rows[1].items() if k != "base"}
    )


def test_the_slope_yardstick_is_the_normal_bound_of_a_drawn_slope_times_the_excursion():
    sigma = {"x": 0.55, "y": 0.8}
    temperature = np.array([10.0, 25.0, 40.0])
    level, tilted = np.zeros(3), np.full(3, LSB_PER_G * math.sin(math.radians(40.0)))
    u95 = slope_reference_u95(sigma, temperature, {"X": tilted, "Y": level})(25.0)
    # d asin(a / g) / da at a = g sin(40 deg) is 1 / (g cos(40 deg)); 1.959964 the normal's 97.5 % point.
    per_lsb_level = math.degrees(1.0 / LSB_PER_G)
    assert u95["Y"] == pytest.approx(1.959964 * 0.8 * np.array([15.0, 0.0, 15.0]) * per_lsb_level, rel=1e-6)
    assert u95["X"] == pytest.approx(
        1.959964 * 0.55 * np.array([15.0, 0.0, 15.0]) * per_lsb_level / math.cos(math.radians(40.0)), rel=1e-5
    )
    # Drawn slopes at the model's sigma: about 95 % of changes fall within it.
    drawn = np.random.default_rng(7).normal(0.0, 0.8, 20000) * 15.0 * per_lsb_level
    assert np.mean(np.abs(drawn) <= u95["Y"][0]) == pytest.approx(0.95, abs=0.01)


def test_every_run_has_its_own_seed_and_the_design_has_over_100_runs():
    tasks = Design().tasks()
    assert len(tasks) >= 100
    assert len({task.key for task in tasks}) == len({task.seed for task in tasks}) == len(tasks)
    assert {task.profile for task in tasks} == set(FIELD_PROFILES)
    assert {task.tilt_deg for task in tasks} == {0.0, 20.0, 40.0}
    assert 8 <= len({task.sensor for task in tasks}) <= 12


# ---- the page -----------------------------------------------------------------


def _row(key, profile, tilt, p95, u95, share="0.98", rows="1000", sensor="TT-01"):
    row = dict.fromkeys(COLUMNS, "")
    row.update(
        key=key,
        sensor=sensor,
        profile=profile,
        tilt_deg=tilt,
        index="0",
        p95_change_deg=f"{p95}",
        u95_deg=f"{u95}",
        within=YES if p95 <= u95 else NO,
        max_change_deg=f"{2 * p95}",
        rows_within_share=share,
        p95_x_deg=f"{p95}",
        p95_y_deg=f"{p95 / 2}",
        u95_x_deg=f"{u95}",
        u95_y_deg=f"{u95}",
        rows=rows,
        outside_rows="10",
        imu_min_c="10.00",
        imu_max_c="30.00",
        set_changes="2",
        certificate_u95_deg="0.3",
        seconds="2.0",
    )
    return row


def _wilson(count: int, runs: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson's score interval, from its formula."""
    p = count / runs
    centre = (p + z * z / (2 * runs)) / (1 + z * z / runs)
    half = z / (1 + z * z / runs) * math.sqrt(p * (1 - p) / runs + z * z / (4 * runs * runs))
    return centre - half, centre + half


def _record():
    rows = [_row(f"w{i}", "field-warming", "0", 0.1, 0.2) for i in range(18)]
    rows += [_row("w18", "field-warming", "0", 0.5, 0.2, share="0.6"), _row("w19", "field-warming", "0", 0.3, 0.2)]
    rows += [_row(f"d{i}", "field-days", "40", 0.1, 0.3, share="1", rows="3000") for i in range(20)]
    return rows


def test_the_page_regenerates_from_a_small_record_with_wilson_intervals(tmp_path):
    rows = _record()
    share = field_accuracy.runs_within(rows)
    assert (share.count, share.runs) == (38, 40)
    assert share.interval == pytest.approx(_wilson(38, 40), abs=1e-12)
    cell = field_accuracy.runs_within(rows[:20])
    assert cell.interval == pytest.approx(_wilson(18, 20), abs=1e-12)
    # Pooled by rows: (18 x 0.98 + 0.6 + 0.98) x 1000 + 20 x 3000, over 80,000 rows.
    assert field_accuracy.rows_within(rows) == pytest.approx((18 * 980 + 600 + 980 + 60000) / 80000)
    text = field_accuracy.report(rows)
    low, high = _wilson(38, 40)
    assert f"38/40 = 95.0% ({low:.1%}–{high:.1%})" in text
    assert "| field-warming | 18/20 = 90.0% (" in text
    assert "**missed: above**" in text  # field-days: 20 of 20, a U that holds every run
    # The largest misses by p95 / U, first the largest.
    misses = text[text.index("The largest misses") :]
    assert misses.index("w18") < misses.index("w19")

    document = tmp_path / "page.md"
    document.write_text(f"# Field accuracy\n\nWritten by hand.\n\n{field_accuracy.BEGIN}\nold\n{field_accuracy.END}\n")
    for _ in range(2):
        generated_page.write_block(document, field_accuracy.BEGIN, field_accuracy.END, text)
    written = document.read_text()
    assert written.startswith("# Field accuracy\n\nWritten by hand.") and "\nold\n" not in written
    assert written.count(field_accuracy.BEGIN) == 1 and text in written
    assert "Against the drift-slope yardstick" not in text  # the record has no yardstick columns
    with_yardstick = [dict(row, slope_u95_deg="0.15", rows_within_slope_share="0.9") for row in rows]
    yardstick = field_accuracy.report(with_yardstick)
    # field-warming: 18 runs of p95 0.1 within 0.15, w18 (0.5) and w19 (0.3) not; U / yardstick 0.2 / 0.15.
    assert "| field-warming | 18/20 = 90.0% (" in yardstick[yardstick.index("Against the drift-slope") :]
    assert "| all | 38/40 = 95.0% (" in yardstick and "| 90.00% | 1.67 |" in yardstick
    field_accuracy.figure(rows, tmp_path / "figure.png")
    assert (tmp_path / "figure.png").stat().st_size > 10_000


def test_a_run_without_a_verdict_is_counted_apart():
    rows = _record()
    silent = dict(rows[0], key="none", within="", p95_change_deg="", u95_deg="", rows_within_share="", rows="0")
    text = field_accuracy.report([*rows, silent])
    assert "1 without a verdict" in text
    assert field_accuracy.runs_within([*rows, silent]).runs == 40


def test_rows_of_another_method_are_said_to_be_stale():
    rows = [dict(row, method="new") for row in _record()]
    rows[3]["method"] = "old"
    assert field_accuracy.report(rows, "new").startswith("**Stale**: 1 of the 40 runs below were made by method old")
    assert "Stale" not in field_accuracy.report(rows[4:], "new")
