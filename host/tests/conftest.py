"""What more than one test module takes: twin runs, made once per
session, and the CLI run in this process."""

import subprocess

import pytest

from child_process import THERMOTILT, popen
from thermotilt import cli

# The scatter terms change each mounting's drift by design
# (host/tests/test_scatter.py bounds them by the paper's RMS errors).
SCATTER_OFF = ("--disable", "drift_repeatability", "--disable", "bias_instability")


@pytest.fixture(scope="session")
def cycle_runs(tmp_path_factory):
    """`simulate cycle` at 0 deg and at 30 deg on X, run side by side (two
    cores), with the scatter terms off: the drift bounds of test_simulate
    do not cover them, and discovery's tests take only the chamber's side
    and the angles of these runs."""
    runs = {}
    processes = []
    for angle in (0, 30):
        out = tmp_path_factory.mktemp(f"cycle{angle}")
        runs[angle] = out
        processes.append(popen(
            [*THERMOTILT, "simulate", "cycle", "--out", str(out), "--incl-x", str(angle),
             "--rest-seconds", "60", *SCATTER_OFF],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
    for process in processes:
        _, stderr = process.communicate(timeout=1800)
        assert process.returncode == 0, stderr
    return runs


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
