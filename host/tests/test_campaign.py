"""``thermotilt campaign --twin``: one run folder per position, campaign.json,
parallel workers, Ctrl-C keeping every finished position, --resume redoing
only the others, and bad input as one line (docs/calibration.md)."""

import json
import signal
import subprocess
import zlib
from pathlib import Path

import pytest
from child_process import THERMOTILT, popen, run
from test_log import wait_for
from twin_helpers import pty_twin

from thermotilt import cli
from thermotilt.calibration.campaign.plan import select_positions
from thermotilt.physics import Model
from thermotilt.run.log import read_run_log
from thermotilt.twin.scenarios import campaign_positions

# 1 s timed holds: a 58 s cycle, about 2 wall seconds per position.
SHORT = ["--hold-seconds", "1", "--rest-seconds", "0", "--hold-start", "T"]


def campaign_file(out):
    return json.loads((out / "campaign.json").read_text())


def statuses(out):
    return {entry["label"]: entry["status"] for entry in campaign_file(out)["positions"]}


def interrupt_once_a_position_is_done(command, out):
    """Runs the campaign command and sends Ctrl-C once a position is done;
    it must exit 130 keeping that position. Returns the statuses then and
    each finished position's run.csv."""
    process = popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def first_done():
        assert process.poll() is None, process.communicate()
        return (out / "campaign.json").exists() and "done" in statuses(out).values()

    wait_for(first_done, "a finished position", timeout_s=120)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert stderr.rstrip().endswith("thermotilt: interrupted")
    assert "add --resume" in stdout
    before = statuses(out)
    finished = {label for label, status in before.items() if status == "done"}
    assert finished
    return before, {label: (out / label / "run.csv").read_bytes() for label in finished}


@pytest.mark.slow
@pytest.mark.twin
def test_positions_run_in_workers_each_into_its_own_folder(tmp_path, capsys):
    out = tmp_path / "campaign"
    status = cli.main(
        ["campaign", "--twin", "--out", str(out), "--positions", "0,X+30,Y-15", "--jobs", "2", "--seed", "5", *SHORT]
    )
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


@pytest.mark.slow
@pytest.mark.twin
def test_a_position_is_the_same_run_in_a_subset_and_in_another_campaign(tmp_path):
    runs = []
    for name, positions, jobs in (("pair", "X+30,0", "2"), ("one", "0", "1")):
        out = tmp_path / name
        assert (
            cli.main(["campaign", "--twin", "--out", str(out), "--positions", positions, "--jobs", jobs, *SHORT]) == 0
        )
        runs.append((out / "0" / "run.csv").read_bytes())
    assert runs[0] == runs[1]


@pytest.mark.slow
@pytest.mark.twin
def test_ctrl_c_keeps_finished_positions_and_resume_runs_only_the_others(tmp_path):
    out = tmp_path / "campaign"
    # 3 s holds, so that the last position is surely still running at the signal.
    longer = ["--hold-seconds", "3", *SHORT[2:]]
    command = [
        *THERMOTILT,
        "campaign",
        "--twin",
        "--out",
        str(out),
        "--positions",
        "0,X+30,X-30",
        "--jobs",
        "2",
        *longer,
    ]
    # Two workers, three positions: once one is done the last one is running.
    before, kept = interrupt_once_a_position_is_done(command, out)
    assert set(before.values()) <= {"done", "interrupted", "pending"}
    assert "interrupted" in before.values()

    assert (
        cli.main(["campaign", "--twin", "--out", str(out), "--positions", "0,X+30,X-30", "--jobs", "2", *longer]) == 1
    )
    assert (
        cli.main(
            ["campaign", "--twin", "--out", str(out), "--positions", "0,X+30,X-30", "--jobs", "2", "--resume", *longer]
        )
        == 0
    )
    assert set(statuses(out).values()) == {"done"}
    for label, data in kept.items():
        assert (out / label / "run.csv").read_bytes() == data
    assert not (out / ".partial").exists()


@pytest.mark.slow
@pytest.mark.twin
def test_resume_refuses_other_settings(tmp_path, capsys):
    out = tmp_path / "campaign"
    assert cli.main(["campaign", "--twin", "--out", str(out), "--positions", "0", *SHORT]) == 0
    capsys.readouterr()
    changed = [argument if argument != "1" else "2" for argument in SHORT]
    assert cli.main(["campaign", "--twin", "--out", str(out), "--positions", "0", "--resume", *changed]) == 1
    assert "its program differ" in capsys.readouterr().err


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--positions", "0,X+7"], "unknown position(s) X+7"),
        (["--positions", "0,0"], "listed twice"),
        (["--positions", ","], "names no position"),
        (["--resume"], "nothing to resume"),
        ([], "needs --twin"),
        (["--twin", "--model", "/nonexistent.toml"], "nonexistent.toml"),
    ],
)
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


# ---- real boards: the twin's pseudo-terminals stand in for the serial ports ----


@pytest.fixture
def idle_twin(tmp_path):
    """Both firmware images idle behind pseudo-terminals, the table at X+30."""
    with pty_twin(tmp_path / "twin", "idle", "--incl-x", "30", "--duration", "3000") as ports:
        yield ports


def boards_campaign(ports, out, answers, *extra):
    # The twin races ahead of the wall clock, so a wall-clock heartbeat would trip: off.
    return run(
        [
            *THERMOTILT,
            "campaign",
            "--imu-port",
            ports["imu_reader"],
            "--chamber-port",
            ports["thermal_chamber"],
            "--out",
            str(out),
            "--heartbeat-seconds",
            "0",
            *SHORT,
            *extra,
        ],
        input=answers,
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
    )


@pytest.mark.slow
@pytest.mark.twin
def test_boards_campaign_asks_for_each_position_and_logs_its_program(idle_twin, tmp_path):
    out = tmp_path / "campaign"
    result = boards_campaign(idle_twin, out, "q\n", "--positions", "X+30,0")
    assert result.returncode == 1
    assert "Set the tilt table to X+30 (X +30 deg, Y +0 deg)" in result.stdout
    assert "stopped with 2 position(s) to run (X+30, 0)" in result.stderr
    result = boards_campaign(idle_twin, out, "\n", "--positions", "X+30,0", "--resume")
    # The twin's table stays at X+30: the user confirms it and then stops.
    assert result.returncode == 1, result.stderr
    assert "X+30: done" in result.stdout and "stopped with 1 position(s) to run (0)" in result.stderr
    document = campaign_file(out)
    assert document["rig"] == "boards" and document["ports"]["imu_reader"] == idle_twin["imu_reader"]
    entry = document["positions"][0]
    assert entry["status"] == "done" and entry["firmware"]["imu_reader"].startswith("imu_reader ")
    # The twin's IMU has no sensor ID: recorded as none.
    assert entry["sensor_id"] == ""
    rows = read_run_log(str(out / "X+30" / "run.csv"))
    assert {row["incl_x_deg"] for row in rows} == {"30.00"}
    assert {"W", "C"} <= {row["phase"] for row in rows}
    # The log starts right after RESEED and runs until the program is done.
    assert rows[0]["since_move_s"] == "0.00" and float(rows[-1]["since_move_s"]) > 50
    assert abs(float(rows[0]["ax_filt"]) - float(rows[0]["ax_raw"])) < 100
    summary = json.loads((out / "X+30" / "summary.json").read_text())
    assert summary["end_reason"] == "program done" and summary["rows"] == len(rows)
    assert (out / "X+30" / "serial" / "thermal_chamber.txt").stat().st_size > 0
    # Another sensor on the IMU port (here: the same board given an ID) is
    # refused before its position runs; the done position stays.
    assigned = run([*THERMOTILT, "assign-id", "NODE-07", "--port", idle_twin["imu_reader"]], capture_output=True)
    assert assigned.returncode == 0, assigned.stderr
    result = boards_campaign(idle_twin, out, "\n", "--positions", "X+30,0", "--resume")
    assert result.returncode == 1 and result.stderr.count("\n") == 1
    assert (
        f"0: the IMU reader on {idle_twin['imu_reader']} is sensor NODE-07, this campaign's positions so far "
        "were logged with (no ID)" in result.stderr
    )
    document = campaign_file(out)
    assert [(entry["label"], entry["status"]) for entry in document["positions"]] == [("X+30", "done"), ("0", "failed")]


@pytest.mark.slow
@pytest.mark.twin
def test_boards_campaign_logs_each_imu_on_the_table_into_its_sensors_campaign(tmp_path):
    # Two twins' IMU readers on one table, the first twin's chamber driving the program.
    with (
        pty_twin(tmp_path / "a", "idle", "--incl-x", "30", "--duration", "3000") as first,
        pty_twin(tmp_path / "b", "idle", "--incl-x", "30", "--duration", "3000") as second,
    ):
        imus = [first["imu_reader"], second["imu_reader"]]
        out = tmp_path / "campaign"
        command = [
            *THERMOTILT,
            "campaign",
            *("--imu-port", imus[0], "--imu-port", imus[1]),
            *("--chamber-port", first["thermal_chamber"], "--out", str(out)),
            *("--heartbeat-seconds", "0", "--positions", "X+30", *SHORT),
        ]
        blank = run(command, input="\n", capture_output=True, text=True, timeout=180, check=False)
        assert blank.returncode == 1 and blank.stderr.count("\n") == 1, blank.stderr
        assert f"{imus[0]} has no sensor ID" in blank.stderr and f"assign-id ID --port {imus[0]}" in blank.stderr
        sensors = {"NODE-02": imus[0], "NODE-01": imus[1]}
        for sensor, port in sensors.items():
            assert run([*THERMOTILT, "assign-id", sensor, "--port", port], capture_output=True).returncode == 0
        result = run(command, input="\n", capture_output=True, text=True, timeout=180, check=False)
    assert result.returncode == 0, result.stderr
    assert "NODE-01 X+30: done" in result.stdout and "NODE-02 X+30: done" in result.stdout
    assert "all 2 sensor positions done" in result.stdout
    batch = json.loads((out / "batch.json").read_text())
    assert batch["sensors"] == ["NODE-01", "NODE-02"] and batch["rig"] == "boards"
    chamber = set()
    for sensor, port in sensors.items():
        document = campaign_file(out / sensor)
        assert document["sensor"] == sensor and document["ports"]["imu_reader"] == port
        (entry,) = document["positions"]
        assert entry["status"] == "done" and entry["sensor_id"] == sensor
        rows = read_run_log(str(out / sensor / "X+30" / "run.csv"))
        assert {"W", "C"} <= {row["phase"] for row in rows}
        summary = json.loads((out / sensor / "X+30" / "summary.json").read_text())
        assert summary["end_reason"] == "program done" and summary["boards"]["imu_reader"]["port"] == port
        chamber.add((out / sensor / "X+30" / "serial" / "thermal_chamber.txt").read_bytes())
    # One chamber ran the program; each folder holds its whole capture.
    assert len(chamber) == 1 and len(next(iter(chamber))) > 0


def test_boards_campaign_without_a_board_is_one_line(tmp_path):
    result = run(
        [
            *THERMOTILT,
            "campaign",
            "--imu-port",
            str(tmp_path / "ttyNONE"),
            "--chamber-port",
            str(tmp_path / "ttyNONE2"),
            "--out",
            str(tmp_path / "c"),
            "--positions",
            "0",
            *SHORT,
        ],
        input="\n",
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and "1 position(s) failed: 0: serial port:" in result.stderr
    assert campaign_file(tmp_path / "c")["positions"][0]["status"] == "failed"


@pytest.mark.slow
@pytest.mark.twin
def test_one_job_reports_progress_while_a_position_runs(tmp_path):
    from thermotilt.calibration.campaign.folder import PARTIAL_DIR
    from thermotilt.calibration.campaign.twin import TwinCampaign, TwinSetup
    from thermotilt.twin.scenarios import ScenarioOptions

    out = tmp_path / "campaign"
    program = ScenarioOptions(hold_s=1, rest_s=0, hold_start="T")
    campaign = TwinCampaign(out, select_positions("0"), TwinSetup(program, seed=1))
    running = []
    campaign.run(1, progress=lambda seconds: running.append((out / PARTIAL_DIR / "0").exists()))
    # The bar moves while the position still runs in its partial folder,
    # not all at once after it ends.
    assert running.count(True) > 1


@pytest.mark.twin
def test_a_batch_is_one_chamber_run_per_position_and_a_campaign_per_sensor(tmp_path, capsys):
    out = tmp_path / "batch"
    arguments = ["campaign", "--twin", "--out", str(out), "--positions", "0,X+30", "--sensors", "2", "--seed", "5"]
    assert cli.main([*arguments, "--jobs", "2", *SHORT]) == 0
    stdout = capsys.readouterr().out
    assert "a batch of 2 sensors (TT-01, TT-02) on one tilt table" in stdout
    assert "all 4 sensor positions done" in stdout and f"thermotilt fit {out}" in stdout
    batch = json.loads((out / "batch.json").read_text())
    assert batch["sensors"] == ["TT-01", "TT-02"] and batch["drawn"] == 2
    # The drawn batch is kept as a model file: each sensor's truth.
    kept, drawn = Model.load(str(out / batch["model_file"])), Model.load().with_population(2, seed=5)
    assert kept.sensor_ids == drawn.sensor_ids
    assert all(kept.for_sensor(sensor).terms == drawn.for_sensor(sensor).terms for sensor in drawn.sensor_ids)
    index = {label: number for number, (label, _, _) in enumerate(campaign_positions())}
    for sensor in batch["sensors"]:
        document = campaign_file(out / sensor)
        assert document["sensor"] == sensor and document["model"] == f"default (sensor {sensor})"
        for entry in document["positions"]:
            assert entry["status"] == "done" and entry["sensor_id"] == sensor
            assert entry["seed"] == 5 + index[entry["label"]] + zlib.crc32(sensor.encode())
        assert f"{sensor} X+30: done" in stdout
    for label in ("0", "X+30"):
        chamber = {
            (out / sensor / label / "serial" / "thermal_chamber.txt").read_bytes() for sensor in batch["sensors"]
        }
        imu = {(out / sensor / label / "run.csv").read_bytes() for sensor in batch["sensors"]}
        # One chamber run carried both sensors; each sensor drifted its own way.
        assert len(chamber) == 1 and len(imu) == 2
    # A resumed batch must be the same sensors; another seed, without
    # --resume or --force, changes nothing of the batch there.
    assert cli.main([*arguments[:-4], "--sensors", "3", "--resume", *SHORT]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "its batch is TT-01, TT-02" in err, err
    kept_files = {name: (out / name).read_bytes() for name in ("batch.json", batch["model_file"])}
    assert cli.main([*arguments[:-1], "6", *SHORT]) == 1
    assert "exists; add --resume" in capsys.readouterr().err
    assert {name: (out / name).read_bytes() for name in kept_files} == kept_files


def children_of(pid):
    children = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            children.append(int(stat.parent.name))
    return children


@pytest.mark.slow
@pytest.mark.twin
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")
def test_workers_stop_when_their_campaign_is_killed(tmp_path):
    out = tmp_path / "campaign"
    longer = ["--hold-seconds", "3", *SHORT[2:]]
    process = popen(
        [*THERMOTILT, "campaign", "--twin", "--out", str(out), "--positions", "0,X+30", "--jobs", "2", *longer],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    wait_for(lambda: len(list((out / ".partial").glob("*"))) == 2, "both positions running", timeout_s=120)
    workers = children_of(process.pid)
    assert workers
    process.kill()
    process.wait(timeout=10)

    def running(pid):
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return False

    def gone():
        return not any(running(pid) for pid in workers)

    # A worker looks for its parent once a second (campaign.ORPHAN_POLL_S).
    wait_for(gone, "the workers to stop", timeout_s=30)
