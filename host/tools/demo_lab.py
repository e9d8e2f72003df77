"""`make demo`'s lab: every batch sensor's fit onto its own board, then a
second calibration of one sensor months later as a lab would make it —
its campaign watched live (`campaign --serve`, a screenshot of the page
for docs/figures), fitted with the registry naming its previous
calibration (the certificate's long-term stability component), uploaded
onto its board — and the fleet (`thermotilt sensors`) and that sensor's
history (`thermotilt history`).

The demo records into a registry of its own (DEMO_REGISTRY in its folder,
made afresh each run), so that a second run's fits take their previous
calibrations from this run alone; at the end its folders are ingested
into the registry the user's commands read (THERMOTILT_REGISTRY, else
runs/registry.sqlite3).
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import socket
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import generated_page
import live_screenshot

REGISTRY_VARIABLE = "THERMOTILT_REGISTRY"
DEMO_REGISTRY = ".registry.sqlite3"
# The recalibration's noise seed: another mounting of the same sensor at every position.
RECALIBRATION_SEED = 2
# Rows of the current position drawn before the screenshot: about a third of its staircase.
SCREENSHOT_POINTS = 10000
SCREENSHOT_TIMEOUT_S = 600
LIVE_FIGURE = generated_page.DOCS / "figures" / "live-campaign.png"
HISTORY_FIGURE = generated_page.DOCS / "figures" / "history.png"
STABILITY = "long-term stability"


def use_own_registry(out: Path) -> str | None:
    """Points this process's commands at a new registry in out; returns what the user's commands read."""
    users = os.environ.get(REGISTRY_VARIABLE)
    registry = (out / DEMO_REGISTRY).resolve()
    registry.parent.mkdir(parents=True, exist_ok=True)
    for leftover in registry.parent.glob(DEMO_REGISTRY + "*"):
        leftover.unlink()
    os.environ[REGISTRY_VARIABLE] = f"sqlite:///{registry}"
    return users


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def watched_recalibration(command: list[str], arguments: list[str], out: Path) -> None:
    """The campaign with --serve, and a screenshot of its page once it has
    drawn SCREENSHOT_POINTS rows of a running position (of the finished
    campaign, with a warning, when it ends first)."""
    port = free_port()
    arguments = [*arguments, "--serve", f"127.0.0.1:{port}"]
    print("$ thermotilt " + " ".join(shlex.quote(a) for a in arguments), flush=True)
    campaign = subprocess.Popen([*command, *arguments], text=True)
    try:
        caught = live_screenshot.take(
            f"http://127.0.0.1:{port}/",
            LIVE_FIGURE,
            SCREENSHOT_POINTS,
            SCREENSHOT_TIMEOUT_S,
            stop_waiting=lambda: campaign.poll() is not None,
        )
    except Exception as error:  # noqa: BLE001 - any browser failure ends the demo in one line
        campaign.kill()
        campaign.wait()
        sys.exit(f"demo: no screenshot of the live page: {str(error).splitlines()[0] if str(error) else error!r}")
    if caught:
        print(f"(screenshot of the live page: {LIVE_FIGURE})", flush=True)
    else:
        print(
            f"demo: warning: the campaign ended before its page drew {SCREENSHOT_POINTS} rows of a running "
            f"position; {LIVE_FIGURE} shows it finished",
            flush=True,
        )
    if campaign.wait() != 0:
        sys.exit(f"demo: thermotilt campaign exited {campaign.returncode}")


def recalibrate(
    thermotilt: Callable[..., subprocess.CompletedProcess],
    command: list[str],
    out: Path,
    sensor: str,
    program: tuple[str, ...],
) -> Path:
    """The sensor's second campaign and fit; returns the fit folder."""
    arguments = [
        "campaign",
        "--twin",
        "--model",
        str(out / "batch" / "model.toml"),
        "--sensor",
        sensor,
        "--seed",
        str(RECALIBRATION_SEED),
        *program,
        "--out",
        str(out / "recalibration"),
        "--force",
    ]
    watched_recalibration(command, arguments, out)
    fit = out / "recalibration-fit"
    thermotilt("fit", str(out / "recalibration"), "--out", str(fit))
    previous = json.loads((fit / "certificate.json").read_text())["previous_calibration"]
    if previous is None:
        sys.exit(f"demo: the registry gave {sensor}'s recalibration no previous calibration")
    return fit


def fleet_and_history(
    thermotilt: Callable[..., subprocess.CompletedProcess], out: Path, sensor: str
) -> tuple[str, str]:
    """`thermotilt sensors` and `thermotilt history SENSOR` as printed."""
    listing = thermotilt("sensors", capture_output=True).stdout
    print(listing, end="", flush=True)
    history = thermotilt("history", sensor, "--out", str(out / "history"), capture_output=True).stdout
    print(history, end="", flush=True)
    shutil.copyfile(out / "history" / "history.png", HISTORY_FIGURE)
    return listing, history


def into_users_registry(thermotilt: Callable[..., subprocess.CompletedProcess], out: Path, users: str | None) -> None:
    environment = {name: value for name, value in os.environ.items() if name != REGISTRY_VARIABLE}
    if users is not None:
        environment[REGISTRY_VARIABLE] = users
    thermotilt("registry", "ingest", str(out), env=environment)


def lab_section(out: Path, sensor: str, listing: str, history: str) -> list[str]:
    first = json.loads((out / "batch-fit" / sensor / "certificate.json").read_text())
    second = json.loads((out / "recalibration-fit" / "certificate.json").read_text())
    rows = []
    for axis, budget in second["budget"].items():
        component = next(c for c in budget["components"] if c["name"] == STABILITY)
        rows.append(
            (
                axis,
                f"{component['value']:.3f}",
                f"{component['contribution_deg']:.3f}",
                f"{first['u95_max_deg'][axis]:#.2g}",
                f"{second['u95_max_deg'][axis]:#.2g}",
            )
        )
    return [
        "## The lab: the fleet, a recalibration and its history",
        "",
        f"The demo's commands record into a registry (docs/registry.md). Each batch sensor's fit went onto its "
        f"own twin board (`assign-id`, `upload`); then {sensor} was calibrated again, as a lab does when a "
        "sensor comes back from the field (here minutes later: the twin's sensor does not age): the same "
        f"positions and program, another mounting at each (seed "
        f"{RECALIBRATION_SEED}), the campaign watched live (`campaign --serve`, docs/live.md), the fit's "
        "previous calibration named by the registry, and the new fit uploaded onto its board. `thermotilt "
        "sensors` then lists:",
        "",
        "```",
        listing.rstrip(),
        "```",
        "",
        f"`thermotilt history {sensor}` shows both calibrations and the change of the drift surfaces between "
        "them. The change is the two campaigns' own mounting scatter alone, which is why the stability "
        "component errs on the safe side.",
        "",
        "```",
        history.rstrip(),
        "```",
        "",
        f"![the change of {sensor}'s drift surfaces between its calibrations](figures/{HISTORY_FIGURE.name})",
        "",
        "The recalibration's certificate carries that change as its long-term stability component "
        "(rectangular; its value is the widest spread of the change over temperature and sets at one tilt):",
        "",
        *generated_page.table(
            (
                "axis",
                "long-term stability, half-width, °",
                "its standard uncertainty, °",
                "largest U, first calibration, °",
                "largest U, recalibration, °",
            ),
            rows,
        ),
        "",
        "The live page during the recalibration's campaign (`thermotilt campaign ... --serve`):",
        "",
        f"![the live page of a twin campaign](figures/{LIVE_FIGURE.name})",
    ]
