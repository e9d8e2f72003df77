"""How the tests start a process: `thermotilt` or any other program, with
SIGINT at its default action whatever this test run inherited.

A shell without job control starts a background job (`nohup make test &`,
some CI runners) with SIGINT ignored; an ignored signal stays ignored
across fork and exec, and Python then raises no KeyboardInterrupt for it,
so the Ctrl-C tests would stop nothing."""

import signal
import subprocess
import sys

THERMOTILT = (sys.executable, "-m", "thermotilt")


def _ctrl_c_at_its_default() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def popen(command, **options) -> subprocess.Popen:
    return subprocess.Popen(command, preexec_fn=_ctrl_c_at_its_default, **options)


def run(command, **options) -> subprocess.CompletedProcess:
    return subprocess.run(command, preexec_fn=_ctrl_c_at_its_default, **options)


def thermotilt(*args, **options) -> subprocess.CompletedProcess:
    """`python -m thermotilt ARGS` to its end; stdout and stderr as text."""
    options.setdefault("stdout", subprocess.PIPE)
    return run([*THERMOTILT, *map(str, args)], stderr=subprocess.PIPE, text=True, timeout=60, check=False, **options)
