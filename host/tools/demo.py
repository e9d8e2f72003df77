"""`make demo`: the calibration job end to end in the digital twin, with the
same commands a user runs on a real rig.

    campaign (a subset of the paper's positions) -> fit -> compare with the
    paper and with the model -> upload into the twin's IMU through its
    pseudo-terminal -> field-warming and field-cooling runs that start with
    the EEPROM the IMU saved -> validate, next to the paper's RMS figures.

Every step is a `thermotilt` command, printed before it runs; what each
prints is what a user sees. Outputs go to runs/demo/ (DEMO_DIR).
"""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from thermotilt.cli import announced_ports

THERMOTILT = [sys.executable, "-m", "thermotilt"]
# A subset of section 3.2's 37 positions that still gives each fitted axis
# its ends and middle: 0, +-15, +-30, +-45 on X, +-30 on Y.
POSITIONS = "0,X+15,X-15,X+30,X-30,X+45,X-45,Y+30,Y-30"
# 20 s of each step held once reached (the paper holds 60 s): the filtered
# reading settles within ~10 s of the face reaching the step, and the fit
# then has ~200 rows per step and position.
HOLD_SECONDS = 20
# The field tests' 3 h and 9 h, compressed so that the demo stays short; the
# warming ramp is then 3x faster than the paper's, the cooling one 9x.
FIELD_SECONDS = 3600
DEFAULT_MODEL = Path(__file__).resolve().parents[1] / "thermotilt" / "models" / "default.toml"
# Generous bounds: the twin announces its ports once both boards are up and
# stops on SIGINT, its files written, each within seconds.
PORTS_TIMEOUT_S = 60
STOP_TIMEOUT_S = 120


def step(title: str) -> None:
    print(f"\n=== {title}", flush=True)


def thermotilt(*arguments: str, **options) -> subprocess.CompletedProcess:
    print("$ thermotilt " + " ".join(shlex.quote(a) for a in arguments), flush=True)
    result = subprocess.run([*THERMOTILT, *arguments], text=True, **options)
    if result.returncode != 0:
        sys.exit(f"demo: thermotilt {arguments[0]} failed (exit {result.returncode})")
    return result


def default_sigint() -> None:
    """In the twin's process before it starts: SIGINT as the shell gives it
    to a foreground command, so that the twin stops on the one this script
    sends even when the script itself was started with SIGINT ignored (a
    background job: `nohup make demo &`)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def ports_of(twin: subprocess.Popen) -> dict[str, str]:
    """The ports the twin announces; a twin that has announced none within
    PORTS_TIMEOUT_S is killed."""
    timed_out = threading.Event()

    def give_up() -> None:
        timed_out.set()
        twin.kill()

    deadline = threading.Timer(PORTS_TIMEOUT_S, give_up)
    deadline.start()
    try:
        return announced_ports(twin.stdout)
    except EOFError as error:
        if timed_out.is_set():
            sys.exit(f"demo: the twin announced no ports within {PORTS_TIMEOUT_S} s; stopped it")
        sys.exit(f"demo: {error} (exit {twin.wait()})")
    finally:
        deadline.cancel()


def stop(twin: subprocess.Popen) -> None:
    """Ctrl-C for the twin: it keeps what it simulated, the IMU's EEPROM included."""
    twin.send_signal(signal.SIGINT)
    try:
        twin.wait(timeout=STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        twin.kill()
        twin.wait()
        sys.exit(f"demo: the twin did not stop within {STOP_TIMEOUT_S} s of SIGINT; killed it")


def upload_through_pty(fit: Path, board_dir: Path) -> Path:
    """The twin's boards idle behind pseudo-terminals; `thermotilt upload`
    talks to the IMU like to a Nano on USB. Returns the EEPROM the IMU saved."""
    print("$ thermotilt simulate idle --pty ...  (in the background)", flush=True)
    # preexec_fn runs between fork and exec; no other thread is running yet.
    twin = subprocess.Popen([*THERMOTILT, "simulate", "idle", "--pty", "--out", str(board_dir), "--force"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            preexec_fn=default_sigint)
    try:
        ports = ports_of(twin)
        thermotilt("upload", str(fit), "--port", ports["imu_reader"])
    finally:
        stop(twin)
    eeprom = board_dir / "imu_reader_eeprom.bin"
    if not eeprom.is_file():
        sys.exit(f"demo: the twin stopped (exit {twin.returncode}) without writing {eeprom}")
    return eeprom


def main() -> None:
    out = Path(os.environ.get("DEMO_DIR", "runs/demo"))
    begin = time.monotonic()

    step(f"1. calibration campaign in the twin: {POSITIONS}, each -10 -> 45 -> -10 degC")
    thermotilt("campaign", "--twin", "--positions", POSITIONS, "--hold-seconds", str(HOLD_SECONDS),
               "--rest-seconds", "0", "--out", str(out / "campaign"), "--force")

    step("2. fit the paper's surfaces (Tables 2-3), with statistics and the model-family comparison")
    thermotilt("fit", str(out / "campaign"), "--out", str(out / "fit"), "--compare-families")

    step("3. compare with the paper's fits and with the model the twin ran")
    thermotilt("compare", str(out / "fit"))
    thermotilt("compare", str(out / "fit"), "--reference", str(DEFAULT_MODEL))

    step("4. upload the coefficients into the twin's IMU through its serial port")
    eeprom = upload_through_pty(out / "fit", out / "board")

    step("5. field tests with the uploaded coefficients, then the paper's RMS check")
    runs = {name: out / name for name in ("field-warming", "field-cooling")}
    with ThreadPoolExecutor(len(runs)) as pool:
        results = list(pool.map(lambda item: subprocess.run(
            [*THERMOTILT, "simulate", item[0], "--duration", str(FIELD_SECONDS), "--eeprom", str(eeprom),
             "--out", str(item[1]), "--force"], capture_output=True, text=True), runs.items()))
    for (name, run), result in zip(runs.items(), results):
        print(f"$ thermotilt simulate {name} --duration {FIELD_SECONDS} --eeprom {eeprom} --out {run}")
        print(result.stdout, end="")
        if result.returncode != 0:
            sys.exit(f"demo: simulate {name} failed: {result.stderr.strip()}")
    for name, run in runs.items():
        thermotilt("validate", str(run), "--coefficients", str(out / "fit"))

    minutes = (time.monotonic() - begin) / 60.0
    step(f"done in {minutes:.1f} min; reports: {out}/fit/report.md, "
         f"{out}/field-warming/validation/report.md, {out}/field-cooling/validation/report.md")


if __name__ == "__main__":
    main()
