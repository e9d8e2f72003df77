"""``thermotilt campaign --twin``: one run folder per position, campaign.json,
parallel workers, Ctrl-C keeping every finished position, --resume redoing
only the others, and bad input as one line (docs/calibration.md)."""

import json
import signal
import subprocess
import sys

import pytest

from thermotilt import cli
from thermotilt.calibration.campaign import select_positions
from thermotilt.runlog import read_run_log
from thermotilt.scenarios import campaign_positions

from test_log import wait_for

THERMOTILT = [sys.executable, "-m", "thermotilt"]
# 1 s timed holds: a 58 s cycle, about 2 wall seconds per position.
SHORT = ["--hold-seconds", "1", "--rest-seconds", "0", "--hold-start", "T"]


def campaign_file(out):
    return json.loads((out / "campaign.json").read_text())


def statuses(out):
    return {entry["label"]: entry["status"] for entry in campaign_file(out)["positions"]}


def test_positions_run_in_workers_each_into_its_own_folder(tmp_path, capsys):
    out = tmp_path / "campaign"
    status = cli.main(["campaign", "--twin", "--out", str(out), "--positions", "0,X+30,Y-15",
                       "--jobs", "2", "--seed", "5", *SHORT])
    stdout = capsys.readouterr().out
    assert status == 0, stdout
    assert "all 3 positions done" in stdout
    document = campaign_file(out)
    assert document["rig"] == "twin" and document["seed"] == 5 and document["model"] == "default"
    assert document["program"]["hold_s"] == 1 and document["program"]["hold_start"] == "T"
    index = {label: number for number, (label, _, _) in enumerate(campaign_positions())}
    for entry in document["positions"]:
        label = entry["label"]
        assert entry["status"] == "done"
        assert entry["seed"] == 5 + index[label]
        assert entry["firmware"]["imu_reader"].startswith("imu_reader ")
        assert entry["firmware"]["thermal_chamber"].startswith("thermal_chamber ")
        rows = read_run_log(str(out / label / "run.csv"))
        summary = json.loads((out / label / "summary.json").read_text())
        assert summary["seed"] == entry["seed"] and summary["interrupted"] is False
        angles = {(row["incl_x_deg"], row["incl_y_deg"]) for row in rows}
        assert angles == {(f"{entry['incl_x_deg']:.2f}", f"{entry['incl_y_deg']:.2f}")}
        assert {row["phase"] for row in rows} >= {"W", "C"}
    assert not (out / ".partial").exists()


def test_a_position_is_the_same_run_in_a_subset_and_in_another_campaign(tmp_path):
    runs = []
    for name, positions, jobs in (("pair", "X+30,0", "2"), ("one", "0", "1")):
        out = tmp_path / name
        assert cli.main(["campaign", "--twin", "--out", str(out), "--positions", positions,
                         "--jobs", jobs, *SHORT]) == 0
        runs.append((out / "0" / "run.csv").read_bytes())
    assert runs[0] == runs[1]


def test_ctrl_c_keeps_finished_positions_and_resume_runs_only_the_others(tmp_path):
    out = tmp_path / "campaign"
    # 3 s holds, so that the last position is surely still running at the signal.
    longer = ["--hold-seconds", "3", *SHORT[2:]]
    command = [*THERMOTILT, "campaign", "--twin", "--out", str(out), "--positions", "0,X+30,X-30",
               "--jobs", "2", *longer]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def first_done():
        assert process.poll() is None, process.communicate()
        return (out / "campaign.json").exists() and "done" in statuses(out).values()

    # Two workers, three positions: once one is done the last one is running.
    wait_for(first_done, "a finished position", timeout_s=120)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert stderr.rstrip().endswith("thermotilt: interrupted")
    assert "add --resume" in stdout
    before = statuses(out)
    finished = {label for label, status in before.items() if status == "done"}
    assert finished and set(before.values()) <= {"done", "interrupted", "pending"}
    assert "interrupted" in before.values()
    kept = {label: (out / label / "run.csv").read_bytes() for label in finished}

    assert cli.main(["campaign", "--twin", "--out", str(out), "--positions", "0,X+30,X-30",
                     "--jobs", "2", *longer]) == 1
    assert cli.main(["campaign", "--twin", "--out", str(out), "--positions", "0,X+30,X-30",
                     "--jobs", "2", "--resume", *longer]) == 0
    assert set(statuses(out).values()) == {"done"}
    for label, data in kept.items():
        assert (out / label / "run.csv").read_bytes() == data
    assert not (out / ".partial").exists()


def test_resume_refuses_other_settings(tmp_path, capsys):
    out = tmp_path / "campaign"
    assert cli.main(["campaign", "--twin", "--out", str(out), "--positions", "0", *SHORT]) == 0
    capsys.readouterr()
    changed = [argument if argument != "1" else "2" for argument in SHORT]
    assert cli.main(["campaign", "--twin", "--out", str(out), "--positions", "0", "--resume",
                     *changed]) == 1
    assert "its program differ" in capsys.readouterr().err


@pytest.mark.parametrize("arguments, message", [
    (["--positions", "0,X+7"], "unknown position(s) X+7"),
    (["--positions", "0,0"], "listed twice"),
    (["--positions", ","], "names no position"),
    (["--resume"], "nothing to resume"),
    ([], "needs --twin"),
    (["--twin", "--model", "/nonexistent.toml"], "nonexistent.toml"),
])
def test_bad_campaign_input_is_one_line(tmp_path, capsys, arguments, message):
    twin = [] if "--twin" in arguments or arguments == [] else ["--twin"]
    status = cli.main(["campaign", "--out", str(tmp_path / "c"), *twin, *arguments])
    err = capsys.readouterr().err
    assert status == 1
    assert err.count("\n") == 1 and message in err, err


def test_all_is_the_papers_37_positions():
    positions = select_positions("all")
    assert len(positions) == 37 and positions[0].label == "0"
    assert [p.index for p in positions] == list(range(37))
