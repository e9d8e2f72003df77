"""The twin as a desk of boards for tests: `thermotilt simulate SCENARIO
--pty` in a subprocess, its two pseudo-terminals, and Ctrl-C at the end."""

import signal
import subprocess
from contextlib import contextmanager
from pathlib import Path

import pytest
from child_process import THERMOTILT, popen

from thermotilt.twin.cli import announced_ports


@contextmanager
def pty_twin(out: Path, scenario: str = "idle", *options):
    """Yields {"imu_reader": path, "thermal_chamber": path}. The twin races
    (`--realtime off`): the clients under test take simulated time as it
    comes, and test_realtime.py covers the pacing a user gets by default."""
    process = popen(
        [*THERMOTILT, "simulate", scenario, "--pty", "--realtime", "off", "--out", str(out), *map(str, options)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        try:
            ports = announced_ports(process.stdout)
        except EOFError:
            pytest.fail(f"the twin ended before announcing its ports: {process.stderr.read()}")
        yield ports
    finally:
        process.send_signal(signal.SIGINT)
        process.communicate(timeout=60)
