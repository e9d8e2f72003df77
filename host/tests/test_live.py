"""The live view (thermotilt.live, docs/live.md) without a browser: the
folder read as a campaign, a batch or a run writes it (a log that grows by
complete lines, a position moved from .partial into place, faults from the
rows and from campaign.json, the ETA), each sensor's registry line, the
server's GET-only API and event stream, and bad input as one line."""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import time
from datetime import UTC, datetime
from pathlib import Path

import pytest
from child_process import THERMOTILT, popen
from starlette.testclient import TestClient

from thermotilt.calibration.campaign.folder import DONE, FAILED, PENDING
from thermotilt.live.folder_state import (
    BATCH,
    CAMPAIGN,
    RUN,
    RUNNING,
    FolderState,
    WatchError,
    campaign_eta_seconds,
    folder_kind,
)
from thermotilt.live.registry_lines import RegistryLines
from thermotilt.live.server import create_app
from thermotilt.live.tail import RunLogTail
from thermotilt.registry.database import Registry
from thermotilt.registry.schema import Calibration, Sensor
from thermotilt.run.log import COLUMNS
from thermotilt.run.summary import BoardReport, RunSummary
from thermotilt.wire.protocol import build_frame

PROGRAM = {"start_c": -10.0, "max_c": 45.0, "step_c": 2.0, "hold_s": 10, "rest_s": 0, "hold_start": "T"}
HEADER = ",".join(COLUMNS) + "\n"


def row(time_s: float, chamber_c: float = 20.0, fault: str = "OK", ax: float = -1700.0, ay: float = -400.0) -> str:
    cells = dict.fromkeys(COLUMNS, "")
    cells.update(
        time_s=f"{time_s:.3f}",
        setpoint_c="25.00",
        chamber_c=f"{chamber_c:.2f}",
        outer_c="22.00",
        phase="W" if fault == "OK" else "F",
        chamber_fault=fault,
        ax_filt=f"{ax:.1f}",
        ay_filt=f"{ay:.1f}",
    )
    return ",".join(cells[column] for column in COLUMNS) + "\n"


def write_log(path: Path, *rows: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(HEADER + "".join(rows))
    return path


def record(label: str, status: str = PENDING, wall_seconds: float | None = None, **more) -> dict:
    entry = {"label": label, "incl_x_deg": 0.0, "incl_y_deg": 0.0, "status": status, "wall_seconds": wall_seconds}
    if status != PENDING:
        entry["started_utc"] = more.pop("started_utc", "2026-12-06T10:00:00Z")
    return entry | more


def write_campaign(folder: Path, *records: dict, **header) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    document = {"format": 1, "rig": "twin", "program": PROGRAM, **header, "positions": list(records)}
    (folder / "campaign.json").write_text(json.dumps(document))
    return folder


def view(state: FolderState, cursors=None):
    state.refresh(max_age_s=0)
    return state.snapshot(cursors)


def test_a_growing_log_is_read_by_complete_lines_only(tmp_path):
    log = write_log(tmp_path / "run.csv", row(0.1), row(0.2))
    partial = row(0.3)
    with open(log, "a") as stream:
        stream.write(partial[:20])
    tail = RunLogTail()
    assert tail.poll(log) == 2
    with open(log, "a") as stream:
        stream.write(partial[20:] + row(0.4))
    assert tail.poll(log) == 2
    assert tail.series["t_s"] == [0.0, 0.1, 0.2, 0.3]
    assert tail.poll(log) == 0


def test_a_log_written_again_is_read_from_its_start(tmp_path):
    log = write_log(tmp_path / "run.csv", row(0.1), row(0.2), row(0.3))
    tail = RunLogTail()
    tail.poll(log)
    generation = tail.generation
    log.unlink()
    write_log(log, row(5.0))
    assert tail.poll(log) == 1
    assert tail.rows == 1 and tail.generation != generation


def test_a_file_that_is_not_a_run_log_gives_no_rows(tmp_path):
    log = tmp_path / "run.csv"
    log.write_text("a,b,c\n1,2,3\n")
    assert RunLogTail().poll(log) == 0


def test_a_running_position_is_followed_into_its_folder_and_its_rows_come_as_increments(tmp_path):
    out = write_campaign(tmp_path / "campaign", record("0"), record("X+15"))
    log = write_log(out / ".partial" / "0" / "run.csv", row(0.1), row(0.2), row(0.3))
    state = FolderState(out)
    first, cursors = view(state)
    assert first["kind"] == CAMPAIGN
    assert first["current"]["label"] == "0" and first["current"]["k"] == 1 and first["current"]["n"] == 2
    assert [(p["label"], p["status"]) for p in first["positions"]] == [("0", RUNNING), ("X+15", PENDING)]
    (block,) = first["series"]
    assert block["start"] == 0 and block["columns"]["t_s"] == [0.0, 0.1, 0.2]

    with open(log, "a") as stream:
        stream.write(row(0.4))
    second, cursors = view(state, cursors)
    assert second["series"][0]["start"] == 3 and second["series"][0]["columns"]["chamber_c"] == [20.0]

    os.replace(out / ".partial" / "0", out / "0")
    write_campaign(out, record("0", DONE, 60.0), record("X+15"))
    third, _ = view(state, cursors)
    assert third["current"]["label"] == "0" and third["current"]["status"] == DONE
    assert third["series"][0]["start"] == 4 and third["series"][0]["columns"]["t_s"] == []
    # A reader that has nothing gets the whole position again.
    assert view(state)[0]["series"][0]["rows"] == 4


def test_a_chamber_fault_is_noted_once_at_its_first_row_and_a_failed_position_with_its_errors(tmp_path):
    out = write_campaign(tmp_path / "campaign", record("0"))
    write_log(
        out / ".partial" / "0" / "run.csv",
        row(10.0),
        row(10.5),
        row(11.0, fault="INNER_OPEN"),
        row(11.5, fault="INNER_OPEN"),
    )
    faults = view(FolderState(out))[0]["faults"]
    assert [(f["kind"], f["position"], f["t_s"], f["text"]) for f in faults] == [("chamber", "0", 1.0, "INNER_OPEN")]

    error = "the program ended early: chamber fault INNER_OPEN"
    reported = ["thermal_chamber: THERMISTOR INNER_OPEN at 11.01 s"]
    write_campaign(out, record("0", FAILED, 2.0, error=error, reported_errors=reported))
    state = FolderState(out)
    document, _ = view(state)
    assert {(f["kind"], f["board"], f["text"], f["t_s"]) for f in document["faults"]} == {
        ("chamber", "", "INNER_OPEN", 1.0),
        ("board", "thermal_chamber", "THERMISTOR INNER_OPEN", 11.01),
        ("failed", "", error, None),
    }
    assert document["positions"][0]["status"] == FAILED
    assert len(view(state)[0]["faults"]) == 3


def test_a_fault_that_ends_the_run_before_a_row_carries_it_is_read_from_the_chamber_capture(tmp_path):
    # A latched fault ends a campaign position's log at the CHS frame that
    # reports it, so its rows rarely show it: the capture does, as it arrives.
    out = write_campaign(tmp_path / "campaign", record("0"))
    position = out / ".partial" / "0"
    write_log(position / "run.csv", row(0.0), row(449.9))
    capture = position / "serial" / "thermal_chamber.txt"
    capture.parent.mkdir()
    capture.write_text(
        build_frame("ERR", 452, [-1, "THERMISTOR", "INNER_OPEN"])
        + build_frame("CHS", 453, [450000, "F", 0, math.nan, math.nan, 35.26, 0, "O", "INNER_OPEN"])
    )
    state = FolderState(out)
    faults = view(state)[0]["faults"]
    assert [(f["kind"], f["board"], f["text"], f["t_s"]) for f in faults] == [
        ("board", "thermal_chamber", "THERMISTOR INNER_OPEN", 449.9),
        ("chamber", "", "INNER_OPEN", 449.9),
    ]
    # campaign.json's record of the same error gives its exact time, not a second entry.
    reported = ["thermal_chamber: THERMISTOR INNER_OPEN at 450.01 s"]
    write_campaign(out, record("0", FAILED, 2.0, error="ended early", reported_errors=reported))
    faults = view(state)[0]["faults"]
    assert [(f["kind"], f["t_s"]) for f in faults] == [("board", 450.01), ("chamber", 449.9), ("failed", None)]


def test_a_finished_campaign_shows_its_last_position_and_no_time_left(tmp_path):
    out = write_campaign(
        tmp_path / "campaign",
        record("0", DONE, 60.0, started_utc="2026-12-06T10:00:00Z"),
        record("X+15", DONE, 62.0, started_utc="2026-12-06T10:01:00Z"),
    )
    for label in ("0", "X+15"):
        write_log(out / label / "run.csv", row(0.1), row(0.2))
    document, _ = view(FolderState(out))
    assert document["current"]["label"] == "X+15" and document["current"]["k"] == 2
    assert document["eta_s"] == 0.0 and document["faults"] == []
    assert document["series"][0]["rows"] == 2


def test_a_stopped_campaign_has_no_eta_and_a_stale_partial_is_not_running(tmp_path):
    out = write_campaign(tmp_path / "campaign", record("0", DONE, 60.0), record("X+15", "interrupted"))
    log = write_log(out / ".partial" / "X+15" / "run.csv", row(0.1))
    an_hour_ago = time.time() - 3600
    os.utime(log, (an_hour_ago, an_hour_ago))
    document, _ = view(FolderState(out))
    assert [p["status"] for p in document["positions"]] == [DONE, "interrupted"]
    assert document["eta_s"] is None


def test_the_eta_rule():
    # Two finished at 60 s each, one running a quarter done, one pending: 1.75 x 60 s.
    assert campaign_eta_seconds([60.0, 60.0], 2, [0.25], None) == pytest.approx(105.0)
    # Two running at once halve it; before any finished, the pace's estimate.
    assert campaign_eta_seconds([], 3, [0.5, 0.5], 100.0) == pytest.approx(100.0)
    assert campaign_eta_seconds([], 3, [0.0], None) is None
    assert campaign_eta_seconds([60.0], 0, [], None) == 0.0
    assert campaign_eta_seconds([60.0], 2, [], None) is None


def test_a_batch_shows_each_sensors_rows_and_registry_line(tmp_path):
    out = tmp_path / "batch"
    out.mkdir()
    (out / "batch.json").write_text(json.dumps({"format": 1, "sensors": ["TT-01", "TT-02"]}))
    for number, sensor in enumerate(("TT-01", "TT-02")):
        write_campaign(out / sensor, record("0", sensor_id=sensor), sensor=sensor)
        write_log(out / sensor / ".partial" / "0" / "run.csv", row(0.1, ax=100.0 * number), row(0.2, ax=100.0 * number))
    line = {"calibrated": "2026-01-10"}
    document, cursors = view(FolderState(out, lambda ids: {"TT-01": line} if "TT-01" in ids else {}))
    assert document["kind"] == BATCH
    assert [(s["id"], s["registry"]) for s in document["sensors"]] == [("TT-01", line), ("TT-02", None)]
    assert {b["sensor"]: b["columns"]["ax_filt"] for b in document["series"]} == {
        "TT-01": [0.0, 0.0],
        "TT-02": [100.0, 100.0],
    }
    assert set(cursors) == {"TT-01", "TT-02"}


def test_a_run_folder_shows_the_run_without_positions(tmp_path):
    run = tmp_path / "fig8"
    write_log(run / "run.csv", row(0.1), row(0.2))
    state = FolderState(run)
    document, _ = view(state)
    assert document["kind"] == RUN and document["positions"] == []
    assert document["current"] == {"k": None, "n": None, "label": "fig8", "status": RUNNING}
    report = BoardReport(reported_errors=["RUNAWAY WRONG_WAY at 23.50 s"])
    RunSummary("twin", 2, "chamber fault WRONG_WAY", 1.0, {"thermal_chamber": report}).write(run)
    document, _ = view(state)
    assert document["current"]["status"] == FAILED
    assert {(f["kind"], f["board"], f["t_s"]) for f in document["faults"]} == {
        ("board", "thermal_chamber", 23.5),
        ("failed", "", None),
    }


def test_a_folder_that_is_no_campaign_and_no_run_is_refused_in_one_line(tmp_path):
    with pytest.raises(WatchError, match="neither a campaign folder"):
        folder_kind(tmp_path)
    with pytest.raises(WatchError, match="no such folder"):
        folder_kind(tmp_path / "missing")
    # A campaign about to start: the server waits for the folder.
    document, _ = view(FolderState(tmp_path / "missing"))
    assert "no such folder" in document["problem"] and document["kind"] is None


def test_a_sensors_registry_line_is_its_line_of_thermotilt_sensors_and_a_dash_otherwise(
    tmp_path, monkeypatch, registry_of_the_test
):
    assert RegistryLines()(["TT-01"]) == {"TT-01": None}
    assert not registry_of_the_test.exists(), "a registry that does not exist is not made"
    with Registry.open(f"sqlite:///{registry_of_the_test}") as registry, registry.writing() as session:
        session.add(Sensor(sensor_id="TT-01"))
        session.flush()
        session.add(
            Calibration(
                folder=str(tmp_path / "fit"),
                source_sha256="0" * 64,
                sensor_id="TT-01",
                positions=37,
                ended_utc=datetime(2026, 1, 10, 12, tzinfo=UTC).replace(tzinfo=None),
                tilt_u95_deg=0.4,
                domain={},
            )
        )
    lines = RegistryLines()(["TT-01", "TT-09"])
    assert lines["TT-09"] is None
    assert lines["TT-01"]["calibrated"] == "2026-01-10" and lines["TT-01"]["U (deg)"] == "0.40"
    assert lines["TT-01"]["recalibration due"].startswith("2027-01-10")
    monkeypatch.setenv("THERMOTILT_REGISTRY", "off")
    assert RegistryLines()(["TT-01"]) == {"TT-01": None}
    # watch --registry URL, or the campaign's, before the environment.
    assert RegistryLines(f"sqlite:///{registry_of_the_test}")(["TT-01"]) == {"TT-01": lines["TT-01"]}


@pytest.fixture
def campaign_folder(tmp_path):
    out = write_campaign(tmp_path / "campaign", record("0"), record("X+15"))
    write_log(out / ".partial" / "0" / "run.csv", row(0.1), row(0.2, fault="WRONG_WAY"))
    return out


def test_the_server_answers_the_state_the_page_and_its_files(campaign_folder):
    with TestClient(create_app(FolderState(campaign_folder))) as client:
        state = client.get("/api/state")
        assert state.status_code == 200 and state.headers["content-type"] == "application/json"
        assert state.json()["current"]["label"] == "0" and state.json()["faults"][0]["text"] == "WRONG_WAY"
        page = client.get("/")
        assert page.status_code == 200 and 'id="temperature-chart"' in page.text
        for name in ("app.js", "app.css", "uPlot.iife.min.js", "uPlot.min.css"):
            assert client.get(f"/static/{name}").status_code == 200, name
        assert client.get("/static/missing.js").status_code == 404


def test_the_event_stream_starts_with_the_whole_view(campaign_folder):
    import threading

    stopping = threading.Event()
    with TestClient(create_app(FolderState(campaign_folder), stopping=stopping)) as client:
        with client.stream("GET", "/api/events") as events:
            assert events.headers["content-type"].startswith("text/event-stream")
            first = next(line for line in events.iter_lines() if line.startswith("data: "))
            stopping.set()
    document = json.loads(first.removeprefix("data: "))
    assert document["series"][0]["start"] == 0 and document["series"][0]["rows"] == 2


@pytest.mark.parametrize("method", ["POST", "PUT", "DELETE"])
@pytest.mark.parametrize("path", ["/", "/api/state", "/api/events", "/static/app.js"])
def test_the_server_only_reads(campaign_folder, method, path):
    with TestClient(create_app(FolderState(campaign_folder))) as client:
        assert client.request(method, path).status_code == 405


def assert_one_line(result, *parts: str) -> None:
    assert result.returncode != 0
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("thermotilt: error: ")
    for part in parts:
        assert part in lines[0]


@pytest.fixture
def port_in_use():
    with socket.create_server(("127.0.0.1", 0)) as taken:
        yield taken.getsockname()[1]


def test_a_port_in_use_is_one_line_and_the_campaign_does_not_start(
    campaign_folder, tmp_path, port_in_use, cli_in_process
):
    result = cli_in_process("watch", campaign_folder, "--serve", f"127.0.0.1:{port_in_use}")
    assert_one_line(result, "in use")
    out = tmp_path / "new-campaign"
    result = cli_in_process(
        "campaign", "--twin", "--out", out, "--positions", "0", "--serve", f"127.0.0.1:{port_in_use}"
    )
    assert_one_line(result, "in use")
    assert not out.exists()


@pytest.mark.parametrize(
    ("folder", "message"),
    [("missing", "no such folder"), ("empty", "neither a campaign folder"), ("file.txt", "not a folder")],
)
def test_watching_what_is_no_campaign_or_run_is_one_line(tmp_path, cli_in_process, folder, message):
    (tmp_path / "empty").mkdir()
    (tmp_path / "file.txt").write_text("x")
    assert_one_line(cli_in_process("watch", tmp_path / folder, "--serve", "0"), message)


@pytest.mark.parametrize("address", ["http", "127.0.0.1:99999", "127.0.0.1:", ":8765", "-1"])
def test_a_malformed_address_is_one_line(campaign_folder, cli_in_process, address):
    assert_one_line(cli_in_process("watch", campaign_folder, "--serve", address), "expected [HOST:]PORT")


def test_watch_serves_the_folder_until_ctrl_c(campaign_folder):
    process = popen(
        [*THERMOTILT, "watch", str(campaign_folder), "--serve", "127.0.0.1:0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = process.stdout.readline()
        assert "read-only" in line, process.stderr.read() if process.poll() is not None else line
        url = next(word for word in line.split() if word.startswith("http://"))
        import urllib.request

        with urllib.request.urlopen(f"{url}api/state", timeout=10) as answer:
            assert json.load(answer)["kind"] == CAMPAIGN
    finally:
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=20)
    assert process.returncode == 130, stderr


def _page_answers(url: str) -> bool:
    import urllib.error
    import urllib.request

    try:
        with urllib.request.urlopen(f"{url}api/state", timeout=5) as answer:
            return answer.status == 200
    except (urllib.error.URLError, ConnectionError):
        return False


def _served_campaign(out: Path) -> tuple[subprocess.Popen, str]:
    process = popen(
        [
            *THERMOTILT,
            "campaign",
            "--twin",
            "--out",
            str(out),
            "--positions",
            "0",
            "--registry",
            "off",
            "--serve",
            "127.0.0.1:0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    line = process.stdout.readline()
    assert "read-only" in line, process.stderr.read() if process.poll() is not None else line
    url = next(word for word in line.split() if word.startswith("http://"))
    assert _page_answers(url)
    # Once the campaign has started: a Ctrl-C while Python still imports
    # numpy can end the process by SIGINT itself instead of exit 130 (CPython's
    # exit path, seen with strace), which a shell reports as 130 too.
    assert "campaign of" in process.stdout.readline()
    return process, url


@pytest.mark.parametrize(("stop", "returncode"), [(signal.SIGINT, 130), (signal.SIGKILL, -signal.SIGKILL)])
def test_a_served_campaign_leaves_no_server_behind(tmp_path, stop, returncode):
    """The page is served by a child process: Ctrl-C on the campaign stops
    it with the campaign, and a campaign killed outright leaves it within
    the reader's next look at its parent (PUSH_EVERY_S; 30 s is for a busy machine)."""
    process, url = _served_campaign(tmp_path / "campaign")
    process.send_signal(stop)
    process.communicate(timeout=60)
    assert process.returncode == returncode
    if stop == signal.SIGINT:
        assert not _page_answers(url)
    deadline = time.monotonic() + 30
    while _page_answers(url) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not _page_answers(url)
