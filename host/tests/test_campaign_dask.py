"""``thermotilt campaign --twin --scheduler ADDRESS``: positions on a Dask
cluster (here a LocalCluster of two worker processes) give the same folders
and campaign.json as local worker processes; Ctrl-C and --resume work the
same way; an unreachable scheduler or a worker without the build is one
line (docs/calibration.md)."""

import json

import pytest
from child_process import THERMOTILT, run
from distributed import Client, Event, LocalCluster
from test_campaign import SHORT, campaign_file, interrupt_once_a_position_is_done, statuses

from thermotilt import cli
from thermotilt.calibration.campaign.dask import run_twin_position_shipped
from thermotilt.calibration.campaign.folder import CAMPAIGN_FILE
from thermotilt.calibration.campaign.plan import Unit, select_positions
from thermotilt.calibration.campaign.twin import TwinSetup
from thermotilt.twin.scenarios import ScenarioOptions

TIMES = ("started_utc", "wall_seconds")


@pytest.fixture(scope="module")
def cluster():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0") as local:
        yield local


def records_without_times(out):
    return [
        {key: value for key, value in entry.items() if key not in TIMES} for entry in campaign_file(out)["positions"]
    ]


def files_of(folder):
    return sorted(path.relative_to(folder).as_posix() for path in folder.rglob("*") if path.is_file())


@pytest.mark.twin
@pytest.mark.parametrize("batch", [[], ["--sensors", "2"]], ids=["one sensor", "a batch of two"])
def test_a_dask_cluster_writes_what_local_workers_write(cluster, tmp_path, capsys, batch):
    positions = ["--positions", "X+30,Y-15", "--seed", "5", *batch, *SHORT]
    local, dask = tmp_path / "local", tmp_path / "dask"
    assert cli.main(["campaign", "--twin", "--out", str(local), "--jobs", "2", *positions]) == 0
    capsys.readouterr()
    assert (
        cli.main(["campaign", "--twin", "--out", str(dask), "--scheduler", cluster.scheduler_address, *positions]) == 0
    )
    stdout = capsys.readouterr().out
    assert f"on the Dask cluster at {cluster.scheduler_address} (2 worker threads)" in stdout
    assert files_of(dask) == files_of(local)
    campaigns = [path.parent.relative_to(local) for path in local.rglob(CAMPAIGN_FILE)]
    assert len(campaigns) == max(1, len(batch) and int(batch[1]))
    for campaign in campaigns:
        for label in ("X+30", "Y-15"):
            for name in ("run.csv", "serial/imu_reader.txt", "serial/thermal_chamber.txt", "imu_reader_eeprom.bin"):
                assert (dask / campaign / label / name).read_bytes() == (local / campaign / label / name).read_bytes()
        assert records_without_times(dask / campaign) == records_without_times(local / campaign)
        header = {
            key: value
            for key, value in campaign_file(local / campaign).items()
            if key not in ("created_utc", "positions")
        }
        assert header == {
            key: value
            for key, value in campaign_file(dask / campaign).items()
            if key not in ("created_utc", "positions")
        }
        assert not (dask / campaign / ".partial").exists()


@pytest.mark.twin
def test_ctrl_c_on_a_cluster_keeps_finished_positions_and_resume_runs_the_others(cluster, tmp_path):
    out = tmp_path / "campaign"
    command = [
        *THERMOTILT,
        "campaign",
        "--twin",
        "--out",
        str(out),
        "--positions",
        "0,X+30,X-30",
        "--scheduler",
        cluster.scheduler_address,
        *SHORT,
    ]
    # Two workers, three positions: the last one starts only when one is done.
    before, kept = interrupt_once_a_position_is_done(command, out)
    assert set(before.values()) == {"done", "pending"}

    result = run([*command, "--resume"], capture_output=True, text=True, timeout=180, check=False)
    assert result.returncode == 0, result.stderr
    assert set(statuses(out).values()) == {"done"}
    for label, data in kept.items():
        assert (out / label / "run.csv").read_bytes() == data
    assert not (out / ".partial").exists()


@pytest.mark.twin
def test_a_position_on_a_worker_stops_at_the_campaigns_stop_event_and_ships_what_it_ran(cluster):
    setup = TwinSetup(ScenarioOptions(hold_s=1, rest_s=0, hold_start="T"))
    position = select_positions("X+30")[0]
    with Client(cluster.scheduler_address, set_as_default=False) as client:
        stop = Event("test-stop-event", client=client)
        stop.set()
        shipped = client.submit(run_twin_position_shipped, setup, position, (Unit(None, ""),), stop.name).result(
            timeout=60
        )
    ((record,), (files,)) = shipped.records, shipped.files
    assert record.status == "interrupted"
    assert set(files) >= {"run.csv", "summary.json", "serial/imu_reader.txt", "serial/thermal_chamber.txt"}
    summary = json.loads(files["summary.json"])
    assert summary["interrupted"] is True and summary["sim_seconds"] < 5
    assert shipped.sim_seconds == pytest.approx(summary["sim_seconds"], abs=1.0)


@pytest.mark.slow
def test_an_unreachable_scheduler_is_one_line(tmp_path):
    out = tmp_path / "campaign"
    result = run(
        [
            *THERMOTILT,
            "campaign",
            "--twin",
            "--out",
            str(out),
            "--positions",
            "0",
            "--scheduler",
            "tcp://127.0.0.1:1",
            *SHORT,
        ],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1, result.stderr
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:1" in result.stderr
    assert not (out / CAMPAIGN_FILE).exists()


@pytest.mark.parametrize(
    "address, message",
    [
        ("127.0.0.1", "missing port number"),
        ("udp://127.0.0.1:8786", "unknown address scheme"),
    ],
)
def test_a_malformed_scheduler_address_is_one_line(tmp_path, capsys, address, message):
    status = cli.main(["campaign", "--twin", "--out", str(tmp_path / "c"), "--scheduler", address, *SHORT])
    err = capsys.readouterr().err
    assert status == 1
    assert err.count("\n") == 1 and message in err and "tcp://HOST:8786" in err, err


def test_a_worker_without_the_build_is_one_line_before_anything_is_written(tmp_path):
    out = tmp_path / "campaign"
    missing = tmp_path / "no-build"
    with LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=True,
        dashboard_address="127.0.0.1:0",
        env={"THERMOTILT_BUILD_DIR": str(missing)},
    ) as unbuilt:
        result = run(
            [
                *THERMOTILT,
                "campaign",
                "--twin",
                "--out",
                str(out),
                "--positions",
                "0",
                "--scheduler",
                unbuilt.scheduler_address,
                *SHORT,
            ],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1, result.stderr
    assert "cannot run the twin" in result.stderr and str(missing) in result.stderr
    assert "run `make build` first" in result.stderr
    assert not (out / CAMPAIGN_FILE).exists()


@pytest.mark.slow
def test_a_scheduler_without_workers_is_one_line(tmp_path):
    out = tmp_path / "campaign"
    with LocalCluster(n_workers=0, processes=True, dashboard_address="127.0.0.1:0") as empty:
        result = run(
            [
                *THERMOTILT,
                "campaign",
                "--twin",
                "--out",
                str(out),
                "--positions",
                "0",
                "--scheduler",
                empty.scheduler_address,
                *SHORT,
            ],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1, result.stderr
    assert "has no workers" in result.stderr and f"dask worker {empty.scheduler_address}" in result.stderr
    assert not (out / CAMPAIGN_FILE).exists()


def test_scheduler_needs_the_twin(tmp_path, capsys):
    status = cli.main(
        [
            "campaign",
            "--imu-port",
            "/dev/null",
            "--chamber-port",
            "/dev/null",
            "--out",
            str(tmp_path / "c"),
            "--scheduler",
            "tcp://127.0.0.1:1",
        ]
    )
    assert status == 1
    assert "it needs --twin" in capsys.readouterr().err
