"""What more than one test module takes: twin runs, made once per test
run, the CLI run in this process, and a registry of each test's own."""

import fcntl
import os
import shutil
import subprocess

import pytest
from child_process import THERMOTILT, popen

from thermotilt import cli

# The scatter terms change each mounting's drift by design
# (host/tests/test_scatter.py bounds them by the paper's RMS errors).
SCATTER_OFF = ("--disable", "drift_repeatability", "--disable", "bias_instability")
CYCLE_ANGLES = (0, 30)
# A hidden file: the registry's walk of a folder skips it.
TEST_REGISTRY_FILE = ".thermotilt-registry.sqlite3"


@pytest.fixture(scope="session", autouse=True)
def registry_of_the_test_run(tmp_path_factory):
    """The commands record what they make in a registry (docs/registry.md),
    by default runs/registry.sqlite3 wherever they run: the session's
    fixtures record in one of the test run's own, and each test in its own
    (below). Processes the tests start inherit it."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("THERMOTILT_REGISTRY", f"sqlite:///{tmp_path_factory.getbasetemp() / TEST_REGISTRY_FILE}")
        yield


@pytest.fixture(autouse=True)
def registry_of_the_test(tmp_path, monkeypatch):
    monkeypatch.setenv("THERMOTILT_REGISTRY", f"sqlite:///{tmp_path / TEST_REGISTRY_FILE}")
    return tmp_path / TEST_REGISTRY_FILE


def made_once_per_test_run(tmp_path_factory, name, make):
    """The folder `make(folder)` fills, made once per test run: without
    pytest-xdist in this process; with it by the first worker that asks,
    while the others wait for it on a lock and then read the same folder
    (the pattern pytest-xdist documents for session fixtures: the workers'
    temporary folders share a parent). A failure is reported by every worker
    that asks, not tried again."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        folder = tmp_path_factory.mktemp(name)
        make(folder)
        return folder
    shared = tmp_path_factory.getbasetemp().parent
    folder, made, failed = shared / name, shared / f"{name}.made", shared / f"{name}.failed"
    with open(shared / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if failed.exists():
            pytest.fail(f"another worker failed to make {name}: {failed.read_text()}")
        if not made.exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            try:
                make(folder)
            except (Exception, pytest.fail.Exception) as error:
                failed.write_text(str(error))
                raise
            made.touch()
    return folder


def run_cycles(folder):
    processes = [
        popen(
            [
                *THERMOTILT,
                "simulate",
                "cycle",
                "--out",
                str(folder / str(angle)),
                "--incl-x",
                str(angle),
                "--rest-seconds",
                "60",
                *SCATTER_OFF,
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for angle in CYCLE_ANGLES
    ]
    for process in processes:
        _, stderr = process.communicate(timeout=1800)
        assert process.returncode == 0, stderr


@pytest.fixture(scope="session")
def cycle_runs(tmp_path_factory):
    """`simulate cycle` at 0 deg and at 30 deg on X, run side by side (two
    cores), with the scatter terms off: the drift bounds of test_simulate
    do not cover them, and discovery's tests take only the chamber's side
    and the angles of these runs. {angle: run folder}, read only."""
    folder = made_once_per_test_run(tmp_path_factory, "cycle_runs", run_cycles)
    return {angle: folder / str(angle) for angle in CYCLE_ANGLES}


@pytest.fixture
def cli_in_process(capsys):
    """`thermotilt ARGS` as cli.main in this process, its status and output
    as subprocess.run gives them (--help, --version and usage errors end in
    argparse's SystemExit). child_process.thermotilt runs the real command."""

    def run(*args):
        try:
            status = cli.main([str(arg) for arg in args])
        except SystemExit as exit:
            status = exit.code
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(args, status, out, err)

    return run


# Fixtures that take 2 s or more (twin runs, emulated campaigns): every
# test that takes one is slow, even after another test has paid for it, so
# that -m "not slow" never starts them.
SLOW_FIXTURES = {"cycle_runs", "fig8_runs", "fig8_run", "campaign_rmse", "field_runs", "cluster"}


def pytest_collection_modifyitems(items):
    for item in items:
        if SLOW_FIXTURES & set(item.fixturenames):
            item.add_marker(pytest.mark.slow)
