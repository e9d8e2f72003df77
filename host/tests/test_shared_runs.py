"""conftest.made_once_per_test_run: a twin run that pytest-xdist's workers
share is made by the first worker that asks, and its failure is every
worker's."""

import pytest
from conftest import made_once_per_test_run


class WorkerTempPaths:
    """tmp_path_factory as a worker sees it: its own folder in the run's."""

    def __init__(self, run_folder, worker):
        self._base = run_folder / f"popen-{worker}"
        self._base.mkdir(parents=True, exist_ok=True)

    def getbasetemp(self):
        return self._base


def test_the_first_worker_makes_it_and_the_others_read_it(tmp_path, monkeypatch):
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw0")
    made = []

    def make(folder):
        made.append(folder)
        (folder / "run.csv").write_text("rows\n")

    folders = [made_once_per_test_run(WorkerTempPaths(tmp_path, worker), "runs", make) for worker in ("gw0", "gw1")]
    assert made == [tmp_path / "runs"]
    assert folders == [tmp_path / "runs"] * 2
    assert (tmp_path / "runs" / "run.csv").read_text() == "rows\n"


def test_a_failure_is_every_workers_and_not_tried_again(tmp_path, monkeypatch):
    monkeypatch.setenv("PYTEST_XDIST_WORKER", "gw0")
    tries = []

    def make(folder):
        tries.append(folder)
        raise AssertionError("the twin exited with 1")

    with pytest.raises(AssertionError, match="the twin exited with 1"):
        made_once_per_test_run(WorkerTempPaths(tmp_path, "gw0"), "runs", make)
    with pytest.raises(pytest.fail.Exception, match="another worker failed to make runs: the twin exited with 1"):
        made_once_per_test_run(WorkerTempPaths(tmp_path, "gw1"), "runs", make)
    assert len(tries) == 1
