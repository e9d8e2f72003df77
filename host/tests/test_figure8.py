"""Figure 8 in the twin under both controllers (`thermotilt simulate fig8
--controller float|rounded-error`), feature by feature beside the paper
(section 3.1): (a) a 2 degC step completes in about 13 s, (b) an offset of
about 0.5 degC between programmed and measured, negative below the outside
temperature and positive above, (c) an overshoot when the inside crosses the
outside, (d) a consistently negative offset of the LSM9DS0's own temperature.
Also the default hold start: every hold is hold_s at its setpoint.
"""

import subprocess

import pytest
from child_process import THERMOTILT, popen, run

from thermotilt.program import PAPER_HOLD_S
from thermotilt.run.log import read_run_columns
from thermotilt.twin import figures
from thermotilt.twin.scenarios import FIG8_AMBIENT_C
from thermotilt.wire.protocol import FrameReader

CONTROLLERS = ("float", "rounded-error")

# (a) docs/twin.md's tolerance for the paper's "approximately 13 s"; the
# chamber temperature arrives once a second (CHS), so a step time is read to 1 s.
STEP_TIME_TOLERANCE_S = 3.0
# (b) float: with a P law the settled error is 255/350 * d_hold degC, and a
# chamber that holds -10 degC at 22 degC ambient needs d_hold <= 0.1 within
# 3 K of ambient (docs/physics-model.md): at most 0.073 degC, doubled for the
# thermistor lag and noise. The paper's 0.5 degC cannot come from it.
FLOAT_MAX_OFFSET_C = 0.15
# (b) rounded-error: the +-0.5 degC dead band lets the face drift towards the
# outside until the band's edge; 3 K from the outside (16 and 22 degC) it gets
# there within a hold, so the paper's "about 0.5" is read as 0.5 +- 0.15.
# Nearer the outside (18, 20 degC) the drift is slower than a hold, and the
# offset is wherever the step's approach left the face inside the band; the
# band's edge plus one CHS reading of lag bounds its size.
ROUNDED_OFFSET_FAR_C = (0.35, 0.65)
ROUNDED_MAX_OFFSET_C = 0.6
FAR_FROM_OUTSIDE_C = 2.5
# (d) The model's LSM9DS0 temperature offset is -1.0 degC (assumed: the paper
# gives the sign, not a value); the die's lag and the 1/8 degC register add
# less than 0.5 degC once a hold has settled.
IMU_OFFSET_RANGE_C = (-1.5, -0.5)
# The default hold start: a hold starts once the face is within 1 degC of its
# setpoint (lib/Program kReachedBandC) and lasts hold_s; CHS frames come once a
# second and the program ticks every 250 ms.
REACHED_BAND_C = 1.0
HOLD_TIMING_TOLERANCE_S = 1.5


@pytest.fixture(scope="module")
def fig8_runs(tmp_path_factory):
    """Both controllers side by side (two cores), seed 7 as docs/twin.md states."""
    runs, processes = {}, {}
    for controller in CONTROLLERS:
        out = tmp_path_factory.mktemp(controller)
        processes[controller] = (
            out,
            popen(
                [*THERMOTILT, "simulate", "fig8", "--seed", "7", "--controller", controller, "--out", str(out)],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            ),
        )
    for controller, (out, process) in processes.items():
        stdout, stderr = process.communicate(timeout=900)
        assert process.returncode == 0, stderr
        log = read_run_columns(str(out / "run.csv"))
        runs[controller] = {"out": out, "stdout": stdout, "log": log, "figures": figures.fig8_figures(log)}
    return runs


@pytest.mark.twin
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_the_command_prints_the_four_features_beside_the_paper(fig8_runs, controller):
    stdout = fig8_runs[controller]["stdout"]
    assert f"Figure 8 (outside {FIG8_AMBIENT_C:g} degC; offsets programmed - measured)" in stdout
    for feature in (
        "(a) 2 degC step time",
        "(b) offset below outside",
        "offset above outside",
        "(c) overshoot, crossing",
        "(d) IMU temperature offset",
    ):
        assert feature in stdout
    assert "thermal_chamber reported" not in stdout and "refused" not in stdout


@pytest.mark.twin
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_a_step_completes_in_about_13_seconds(fig8_runs, controller):
    steps = fig8_runs[controller]["figures"]["steps"]
    assert [(step["from_c"], step["to_c"]) for step in steps] == [(16, 18), (18, 20), (20, 22)]
    for step in steps:
        assert step["completion_s"] == pytest.approx(figures.PAPER_STEP_TIME_S, abs=STEP_TIME_TOLERANCE_S), step


def side_of_outside(hold):
    """The paper's sign of programmed - measured: -1 below the outside, +1 above."""
    return -1 if hold["setpoint_c"] < FIG8_AMBIENT_C else 1


@pytest.mark.twin
def test_float_offset_has_the_papers_sign_but_not_its_size(fig8_runs):
    holds = fig8_runs["float"]["figures"]["holds"]
    assert [hold["setpoint_c"] for hold in holds] == [16, 18, 20, 22]
    for hold in holds:
        assert 0 < side_of_outside(hold) * hold["offset_c"] < FLOAT_MAX_OFFSET_C, hold


def rounded_holds(fig8_runs, far_from_outside):
    holds = fig8_runs["rounded-error"]["figures"]["holds"]
    assert [hold["setpoint_c"] for hold in holds] == [16, 18, 20, 22]
    return [
        hold for hold in holds if (abs(hold["setpoint_c"] - FIG8_AMBIENT_C) > FAR_FROM_OUTSIDE_C) == far_from_outside
    ]


@pytest.mark.twin
def test_rounded_error_offset_is_about_half_a_degree_far_from_the_outside(fig8_runs):
    low, high = ROUNDED_OFFSET_FAR_C
    for hold in rounded_holds(fig8_runs, far_from_outside=True):
        assert low < side_of_outside(hold) * hold["offset_c"] < high, hold
    for hold in rounded_holds(fig8_runs, far_from_outside=False):
        assert abs(hold["offset_c"]) < ROUNDED_MAX_OFFSET_C, hold


@pytest.mark.twin
@pytest.mark.xfail(
    strict=True,
    reason="1 K from the outside the face drifts too slowly to reach the dead "
    "band's edge within a minute; at 18 degC it settles at the setpoint "
    "(docs/physics-model.md)",
)
def test_rounded_error_offset_has_the_papers_sign_near_the_outside(fig8_runs):
    for hold in rounded_holds(fig8_runs, far_from_outside=False):
        assert side_of_outside(hold) * hold["offset_c"] > 0, hold


@pytest.mark.parametrize("controller", CONTROLLERS)
@pytest.mark.twin
@pytest.mark.xfail(
    strict=True,
    reason="neither controller overshoots more at the crossing than at the "
    "other steps: nothing in the twin's chamber is crossing-specific (docs/physics-model.md)",
)
def test_the_crossing_step_overshoots_most(fig8_runs, controller):
    result = fig8_runs[controller]["figures"]
    assert result["crossing_overshoot_c"] > result["other_overshoot_c"]


@pytest.mark.twin
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_the_crossing_step_is_the_one_across_the_outside_temperature(fig8_runs, controller):
    result = fig8_runs[controller]["figures"]
    assert result["ambient_c"] == pytest.approx(FIG8_AMBIENT_C)
    crossing = figures.crossing_step(
        figures.step_responses(figures.warming_rows(fig8_runs[controller]["log"])), result["ambient_c"]
    )
    assert (crossing.from_c, crossing.to_c) == (18, 20)
    assert result["crossing_overshoot_c"] == pytest.approx(crossing.overshoot_c, abs=1e-3)


@pytest.mark.twin
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_the_imu_reads_below_the_chamber(fig8_runs, controller):
    low, high = IMU_OFFSET_RANGE_C
    assert low < fig8_runs[controller]["figures"]["imu_temperature_offset_c"] < high


@pytest.mark.twin
@pytest.mark.parametrize("controller", CONTROLLERS)
def test_each_hold_lasts_a_minute_from_reaching_its_setpoint(fig8_runs, controller):
    capture = (fig8_runs[controller]["out"] / "serial" / "thermal_chamber.txt").read_bytes()
    status = [f for f in FrameReader().feed(capture) if f.type == "CHS" and f["phase"] in ("W", "C")]
    starts = [i for i, f in enumerate(status) if i == 0 or f["step"] != status[i - 1]["step"]]
    for first, after in zip(starts, starts[1:]):
        frames = status[first:after]
        reached = next(f for f in frames if abs(f["inner_c"] - f["setpoint_c"]) <= REACHED_BAND_C)
        held_s = (status[after]["t_ms"] - reached["t_ms"]) / 1000
        assert held_s == pytest.approx(PAPER_HOLD_S, abs=HOLD_TIMING_TOLERANCE_S), frames[0]
    # The first hold waited for the run from 19 degC down to 17 degC.
    first_step_s = (status[starts[1]]["t_ms"] - status[0]["t_ms"]) / 1000
    assert first_step_s > PAPER_HOLD_S + 5


@pytest.mark.slow
@pytest.mark.twin
def test_holds_too_short_to_settle_are_said_so_not_printed_as_nan(tmp_path):
    result = run(
        [*THERMOTILT, "simulate", "fig8", "--hold-seconds", "10", "--out", str(tmp_path / "short")],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert "nan" not in result.stdout and "Warning" not in result.stderr
    assert f"no hold lasted {2 * figures.SETTLED_WINDOW_S:g} s" in result.stdout
