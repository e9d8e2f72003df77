"""`make demo`: the calibration job end to end in the digital twin, with the
same commands a user runs on a real rig.

    campaign (a subset of the paper's positions) -> fit -> compare with the
    paper and with the model -> upload into the twin's IMU through its
    pseudo-terminal -> field-warming and field-cooling runs that start with
    the EEPROM the IMU saved -> validate, next to the paper's RMS figures;
    then a batch of three sensors on one tilt table -> a fit and a
    certificate each -> each fit compared with its own sensor's drift ->
    IDs: a fit for another sensor refused by a board, each its own
    uploaded -> the lab (demo_lab.py): one sensor recalibrated, its campaign
    watched live, the fleet and its history from the registry.

Every step is a `thermotilt` command, printed before it runs; what each
prints is what a user sees. Outputs go to runs/demo/ (DEMO_DIR); at the end
the comparison with the paper is written to docs/paper-comparison.md
(overwritten), from what `fit` wrote and what `compare` and `validate` compute
on the demo's folders.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import shlex
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import numpy as np

# generated_page sits beside this file, which tests load by its path (for the
# campaign settings) without this folder on sys.path.
sys.path.insert(0, str(Path(__file__).resolve().parent))
import demo_lab  # noqa: E402
import generated_page  # noqa: E402

from thermotilt.calibration.compare import CALIBRATED_C, compare, expected_mounting_miss_lsb, read_fit
from thermotilt.calibration.paper import FIELD_RMS_LSB, FIELD_TEST_SET, TABLES
from thermotilt.calibration.validate import SET_NAMES, load_coefficients, validate
from thermotilt.lsm9ds0 import LSB_PER_G
from thermotilt.physics import Model
from thermotilt.run.summary import read_summary
from thermotilt.twin.cli import announced_ports

THERMOTILT = [sys.executable, "-m", "thermotilt"]
# A subset of section 3.2's 37 positions that still gives each fitted axis
# its ends and middle: 0, +-15, +-30, +-45 on X, +-30 on Y.
POSITIONS = "0,X+15,X-15,X+30,X-30,X+45,X-45,Y+30,Y-30"
# 20 s of each step held once reached (the paper holds 60 s): the filtered
# reading settles within ~10 s of the face reaching the step, and the fit
# then has ~200 rows per step and position.
HOLD_SECONDS = 20
# Sensors drawn about the model for the batch (physics/batch.py's spreads).
BATCH_SENSORS = 3
# The field tests' 3 h and 9 h, compressed so that the demo stays short; the
# warming ramp is then 3x faster than the paper's, the cooling one 9x.
FIELD_SECONDS = 3600
# Figure 17's 12 h alternation compressed into 3 h: its fastest change is
# then 0.6 degC/min, within the certificate's field rates (1 degC/min).
ALTERNATING_SECONDS = 3 * 3600
# The tilt the field-alternating check uses, on X.
ALTERNATING_INCL_X_DEG = 20
FIGURES = generated_page.DOCS / "figures"
DEFAULT_MODEL = Path(__file__).resolve().parents[1] / "thermotilt" / "models" / "default.toml"
PAGE = generated_page.DOCS / "paper-comparison.md"
# Generous bounds: the twin announces its ports once both boards are up and
# stops on SIGINT, its files written, each within seconds.
PORTS_TIMEOUT_S = 60
STOP_TIMEOUT_S = 120


def step(title: str) -> None:
    print(f"\n=== {title}", flush=True)


def thermotilt(*arguments: str, expect_exit: int = 0, **options) -> subprocess.CompletedProcess:
    print("$ thermotilt " + " ".join(shlex.quote(a) for a in arguments), flush=True)
    result = subprocess.run([*THERMOTILT, *arguments], text=True, **options)
    if result.returncode != expect_exit:
        sys.exit(f"demo: thermotilt {arguments[0]} exited {result.returncode}, not {expect_exit}")
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


@contextmanager
def idle_twin(board_dir: Path, eeprom: Path | None = None) -> Iterator[dict[str, str]]:
    """The twin's boards idling behind pseudo-terminals, by board name, the
    IMU starting from eeprom if given; a command talks to the IMU as to a
    Nano on USB."""
    print("$ thermotilt simulate idle --pty ...  (in the background)", flush=True)
    starting = ["--eeprom", str(eeprom)] if eeprom else []
    # preexec_fn runs between fork and exec; no other thread is running yet.
    twin = subprocess.Popen(
        [*THERMOTILT, "simulate", "idle", "--pty", *starting, "--out", str(board_dir), "--force"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        preexec_fn=default_sigint,
    )
    try:
        yield ports_of(twin)
    finally:
        stop(twin)


def upload_through_pty(fit: Path, board_dir: Path, sensor: str | None = None, eeprom: Path | None = None) -> Path:
    """`thermotilt upload` into the twin's IMU (given sensor's ID first, or
    starting from eeprom). Returns the EEPROM the IMU saved."""
    with idle_twin(board_dir, eeprom) as ports:
        if sensor is not None:
            thermotilt("assign-id", sensor, "--port", ports["imu_reader"])
        thermotilt("upload", str(fit), "--port", ports["imu_reader"])
    eeprom = board_dir / "imu_reader_eeprom.bin"
    if not eeprom.is_file():
        sys.exit(f"demo: the twin stopped without writing {eeprom}")
    return eeprom


def refused_then_uploaded(batch_fit: Path, sensors: list[str], board_dir: Path) -> str:
    """A blank twin IMU is given the first sensor's ID; the second sensor's
    fit must be refused, the first's uploaded. Returns the refusal's line."""
    own, other = sensors[0], sensors[1]
    with idle_twin(board_dir) as ports:
        port = ports["imu_reader"]
        thermotilt("assign-id", own, "--port", port)
        refused = thermotilt("upload", str(batch_fit / other), "--port", port, expect_exit=1, capture_output=True)
        print(refused.stdout + refused.stderr, end="", flush=True)
        if own not in refused.stderr or other not in refused.stderr:
            sys.exit(f"demo: upload of {other}'s fit to {own}'s board was not refused for its ID")
        thermotilt("upload", str(batch_fit / own), "--port", port)
    return refused.stderr.strip()


def simulate_in_parallel(runs: dict[Path, tuple[str, ...]]) -> None:
    """`thermotilt simulate SCENARIO ... --duration FIELD_SECONDS --out RUN`
    for each run folder, two at a time; each one's output printed after its command."""

    def command(run: Path, arguments: tuple[str, ...]) -> list[str]:
        duration = [] if "--duration" in arguments else ["--duration", str(FIELD_SECONDS)]
        return ["simulate", *arguments, *duration, "--out", str(run), "--force"]

    def simulate(item: tuple[Path, tuple[str, ...]]) -> subprocess.CompletedProcess:
        return subprocess.run([*THERMOTILT, *command(*item)], capture_output=True, text=True)

    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(simulate, runs.items()))
    for (run, arguments), result in zip(runs.items(), results):
        print("$ thermotilt " + " ".join(command(run, arguments)))
        print(result.stdout, end="")
        if result.returncode != 0:
            sys.exit(f"demo: simulate {arguments[0]} failed: {result.stderr.strip()}")


def lsb(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.1f}"


def fit_section(fit: Path) -> list[str]:
    """The fitted surfaces' RMSE beside Tables 2-3, from coefficients.json and families.json."""
    document = json.loads((fit / "coefficients.json").read_text())
    rows = []
    for key, surface in document["fits"].items():
        set_name, axis = key[0], key[1]
        paper = TABLES[(axis, set_name)].rmse
        rmse = surface["rmse_lsb"]
        rows.append(
            (
                axis,
                SET_NAMES[set_name],
                surface["points"],
                "{:.1f} .. {:.1f}".format(*surface["temperature_range_c"]),
                f"{rmse:.2f}",
                f"{paper:.2f}",
                f"{rmse / paper:.2f}",
            )
        )
    lines = [
        "## The scatter the fitted surfaces leave (Tables 2–3)",
        "",
        "`thermotilt fit` on the campaign: RMSE = √(SSE / (n − 6)) of each set and axis, beside the "
        "paper's. What the surfaces cannot take up is the twin sensor's scatter terms "
        "(`drift_repeatability`, `bias_instability`: docs/physics-model.md), and a few positions are a "
        "few draws of them.",
        "",
        *generated_page.table(
            ("axis", "set", "points", "IMU temperature, °C", "RMSE, LSB", "Tables 2–3, LSB", "twin / paper"), rows
        ),
    ]
    families = fit / "families.json"
    if families.is_file():
        recommended = json.loads(families.read_text())["recommended"]
        lines += [
            "",
            "`fit --compare-families` (leave-one-position-out CV RMSE) recommends "
            + ", ".join(f"{family} on {axis}" for axis, family in recommended.items())
            + "; the paper chose poly22 (§3.3).",
        ]
    return lines


def compare_section(fit: Path) -> list[str]:
    """`thermotilt compare`'s figures, against the paper and against the model the twin ran."""
    fitted = read_fit(fit)
    against_model = {c.key: c for c in compare(fitted, str(DEFAULT_MODEL))}
    rows = []
    for paper in compare(fitted, "paper"):
        model = against_model[paper.key]
        sigmas = ", ".join(f"{term} {value:+.1f}" for term, value in paper.coefficient_sigmas.items())
        rows.append(
            (
                paper.key,
                "{:.1f} .. {:.1f}".format(*paper.temperature_range_c),
                f"{paper.rms_lsb:.2f} / {paper.max_lsb:.2f}",
                sigmas,
                f"{model.rms_lsb:.2f} / {model.max_lsb:.2f}",
            )
        )
    return [
        "## The fitted surfaces beside the paper's and the model's",
        "",
        "`thermotilt compare`: the difference of two surfaces, each relative to its value at 25 °C, "
        "over the fit's acceleration range and its part of −10…45 °C (docs/calibration.md, "
        '"Comparing"). The twin\'s model drifts by Tables 2–3 (`models/default.toml`); the coefficient '
        "differences are in units of the paper's own 95 % half-widths, which assume independent rows.",
        "",
        *generated_page.table(
            (
                "fit",
                "°C compared",
                "against Tables 2–3: RMS / max, LSB",
                "coefficient difference / the paper's half-width",
                "against the model: RMS / max, LSB",
            ),
            rows,
        ),
    ]


def field_section(fit: Path, runs: dict[str, Path]) -> list[str]:
    """`thermotilt validate --coefficients FIT` on each field run, beside
    section 4.3 and the fit's certificate."""
    # `fit` issues a certificate only for an identified item; the single-sensor twin campaign records no ID.
    certificate = json.loads((fit / "certificate.json").read_text()) if (fit / "certificate.json").is_file() else None
    rows, runs_read, firmware, tilt = [], [], [], []
    for name, run in runs.items():
        validation = validate(run, load_coefficients(str(fit)))
        tilt.append(f"{validation.tilt_error_p95_deg:.4f}° on {name}")
        simulated_s = read_summary(run).sim_seconds
        runs_read.append(
            f"{name} {simulated_s:.0f} s simulated, the IMU reading {{:.1f}}…{{:.1f}} °C".format(
                *validation.temperature_range_c
            )
        )
        for result in validation.results:
            paper = FIELD_RMS_LSB.get((name, result.axis)) if FIELD_TEST_SET[name] == result.set_name else None
            rows.append(
                (
                    name,
                    SET_NAMES[result.set_name],
                    result.axis,
                    result.rows,
                    lsb(result.rms_before_lsb),
                    f"{paper[0]:.0f}" if paper else "—",
                    lsb(result.rms_after_lsb),
                    f"{paper[1]:.0f}" if paper else "—",
                )
            )
        if validation.firmware_difference_lsb is not None:
            firmware.append(f"{validation.firmware_difference_lsb:.2f} LSB on {name}")
    return [
        "## Field validation (§4.3)",
        "",
        "`thermotilt validate --coefficients FIT`: the RMS over a field run of each axis's reading minus "
        "its reading at 25 °C, before and after compensation with the fitted surfaces (on the host, as "
        "the paper post-processed its field data). The paper's field days took 3 h (warming) and 9 h "
        f"(cooling); here {'; '.join(runs_read)}. Section 4.3 compensated each run with one set's "
        "surfaces; the other set's rows have no paper figure (—).",
        "",
        *generated_page.table(
            ("run", "set", "axis", "rows", "before, LSB", "§4.3 before", "after, LSB", "§4.3 after"), rows
        ),
        "",
        "The IMU ran the same surfaces from its EEPROM after `thermotilt upload`; its own compensated "
        f"output is within {' and '.join(firmware)} of the host's.",
        "",
        (
            f"The fit's certificate states U = {certificate['tilt_u95_deg']:#.2g}° (k = "
            f"{certificate['coverage_factor']:.2f}, 95 %) as the largest over the calibrated domain"
            if certificate
            else "The campaign's IMU has no sensor ID, so `fit` issued no certificate (the batch below has one "
            "per sensor)"
        )
        + ' (docs/calibration.md, "The certificate"); the field runs\' 95th '
        f"percentile of the tilt error: {' and '.join(tilt)}.",
    ]


def reading_section(out: Path, sensor: str) -> list[str]:
    """What a monitoring user reads from a batch sensor through Figure 17's
    alternation: the change from the installation reading, the set switches
    and the figure, and the sensor's certificate."""
    run, fit = out / f"field-alternating-{sensor}", out / "batch-fit" / sensor
    validation = json.loads((run / "validation.json").read_text())
    certificate = json.loads((fit / "certificate.json").read_text())
    FIGURES.mkdir(exist_ok=True)
    figure = FIGURES / "field-alternating-change.png"
    figure.write_bytes((run / "validation" / "change.png").read_bytes())
    change, switches = validation["tilt_change"], validation["set_switches"]
    rows = [
        (
            axis["axis"],
            axis["rows"],
            axis["outside_rows"],
            f"{axis['p95_lsb']:.1f}",
            f"{axis['p95_mg']:.2f}",
            f"{axis['p95_deg']:.4f}",
            f"{axis['max_deg']:.4f}",
            f"{axis['u95_max_deg']:#.2g}" if axis["u95_max_deg"] is not None else "—",
            f"{100 * axis['within_u_share']:.1f} %" if axis["within_u_share"] is not None else "—",
        )
        for axis in change["axes"]
    ]
    largest = switches["largest_step_lsb"] or {}
    bands = []
    for axis, table in certificate["uncertainty_table"].items():
        grid = np.array(table["u95_deg"], dtype=float)  # [installation][reading][tilt]
        for k, tilt_band in enumerate(table["tilt_bands_deg"]):
            same, every = np.diagonal(grid[:, :, k]), grid[:, :, k]
            bands.append(
                (
                    axis,
                    "{:g}…{:g}".format(*tilt_band),
                    f"{np.nanmin(same):#.2g}…{np.nanmax(same):#.2g}",
                    f"{np.nanmin(every):#.2g}…{np.nanmax(every):#.2g}",
                )
            )
    return [
        "## The reading a monitoring user takes",
        "",
        f"Batch sensor {sensor} at X {ALTERNATING_INCL_X_DEG}° through Figure 17's alternation "
        f"(`simulate field-alternating`, its 12 h in {ALTERNATING_SECONDS // 3600} h), compensated with its "
        "own fit and read as a monitoring user reads a node: the change of each axis from the installation "
        "reading (the first settled minute), whichever set the device is in (`validate`, docs/calibration.md, "
        "\"Field check\"), held row by row against the certificate's U for the row's change: at the "
        "installation reading's temperature and the row's temperature and tilt.",
        "",
        *generated_page.table(
            ("axis", "rows", "outside", "p95, LSB", "p95, mg", "p95, °", "max, °", "U there, °", "rows within U"),
            rows,
        ),
        "",
        f"The device switched between its sets {switches['count']} times; the largest step of the "
        "compensated reading there (60 s medians either side, 30 s away): "
        + (", ".join(f"{axis} {step:.1f} LSB" for axis, step in largest.items()) or "none measured")
        + ". The compensation blends the sets' surfaces over 1.5 °C after each reversal (lib/Compensation "
        "`SetBlend`) while the twin's sensor crosses over 1.5 °C of its die temperature (docs/physics-model.md).",
        "",
        f"![the change of tilt from the installation reading](figures/{figure.name})",
        "",
        f"Its certificate {certificate['certificate_number']}: U = {certificate['tilt_u95_deg']:#.2g}° "
        f"(k = {certificate['coverage_factor']:.2f}, p = 95 %) as the largest over the domain; by band of "
        "|nominal tilt|, the range of U for a change installed and read in one IMU-temperature band, and "
        "for any installation and reading band:",
        "",
        *generated_page.table(("axis", "\\|tilt\\|, °", "U in one band, °", "U, any two bands, °"), bands),
        "",
        "The budget behind each band, its Type B rows and how the mounting-to-mounting part is taken out of "
        'sample are in the sensor\'s certificate.html/.pdf (docs/calibration.md, "The certificate").',
    ]


def mounting_miss(model: Model, positions: list[dict]) -> float:
    """What the sensor's drift_repeatability alone leaves a fit over these
    positions off its drift, expected; the worse of X and Y."""
    if not model.enabled("drift_repeatability"):
        return 0.0
    sigmas = model.terms["drift_repeatability"]["sigma_lsb_per_c"]
    return max(
        expected_mounting_miss_lsb(
            sigmas[axis],
            CALIBRATED_C,
            [LSB_PER_G * math.sin(math.radians(position[f"incl_{axis}_deg"])) for position in positions],
        )
        for axis in ("x", "y")
    )


def batch_section(out: Path, refusal: str) -> list[str]:
    """Each batch sensor's fit against its own drift and the others', and its certificate."""
    batch = json.loads((out / "batch" / "batch.json").read_text())
    truths = str(out / "batch" / batch["model_file"])
    batch_model = Model.load(truths)
    rows, walls = [], []
    for sensor in batch["sensors"]:
        fit = out / "batch-fit" / sensor
        fitted = read_fit(fit)
        gaps = {truth: max(c.rms_lsb for c in compare(fitted, truths, truth)) for truth in batch["sensors"]}
        certificate = json.loads((fit / "certificate.json").read_text())
        field = json.loads((out / f"field-warming-{sensor}" / "validation.json").read_text())
        campaign = json.loads((out / "batch" / sensor / "campaign.json").read_text())
        rows.append(
            (
                sensor,
                f"{max(surface.rmse_lsb for surface in fitted.values()):.2f}",
                f"{gaps[sensor]:.2f}",
                f"{mounting_miss(batch_model.for_sensor(sensor), campaign['positions']):.1f}",
                f"{min(gap for truth, gap in gaps.items() if truth != sensor):.0f}",
                f"{certificate['tilt_u95_deg']:#.2g}",
                f"{field['tilt_error_p95_deg']:.4f}",
            )
        )
        walls += [position["wall_seconds"] for position in campaign["positions"] if position["wall_seconds"]]
    return [
        "## A batch on one tilt table",
        "",
        f"`campaign --twin --sensors {len(batch['sensors'])}` on the same positions and program: sensors drawn "
        'about the model with the unit-to-unit spreads of docs/physics-model.md ("A batch of sensors"), '
        "each position one chamber run carrying every sensor's IMU board "
        f"({min(walls):.0f}–{max(walls):.0f} s of wall time a position). `fit` on the batch writes a fit and "
        "a certificate per sensor; `compare FIT/<id> --reference` the batch's model.toml measures each fit "
        "against its own sensor's drift and the others' (RMS over the fit's domain relative to 25 °C, the "
        "worst of its sets and X/Y), beside what the sensor's `drift_repeatability` alone is expected to leave "
        "(each position a new mounting whose drift slope differs by N(0, σ) per °C: the fit's T and T·a terms "
        "take the positions' slopes as a line in a, so few positions leave σ·R·√(1/N + ⟨(a − ā)²⟩/Σ(aₘ − ā)²), "
        "R the RMS of T − 25 °C; `compare.expected_mounting_miss_lsb`, checked in `test_compare.py`). "
        "Each sensor then ran a field-warming day "
        f"({FIELD_SECONDS} s, `simulate field-warming --model` that file `--sensor ID`), compensated on the "
        "host with its own fit (`validate --coefficients FIT/<id>`): the 95th percentile of its tilt error "
        "beside its certificate's U.",
        "",
        *generated_page.table(
            (
                "sensor",
                "fit RMSE, worst, LSB",
                "against its own drift, LSB",
                "expected from drift_repeatability, LSB",
                "against the nearest other sensor's, LSB",
                "certificate U (95 %), °",
                "field-warming tilt error, 95th percentile, °",
            ),
            rows,
        ),
        "",
        f"A blank twin IMU given the ID {batch['sensors'][0]} (`assign-id`) refused the fit of "
        f"{batch['sensors'][1]} — `{refusal}` — and took its own.",
    ]


def write_paper_comparison(
    out: Path, runs: dict[str, Path], refusal: str, lab: list[str], started: datetime.datetime, load_at_start: str
) -> None:
    campaign = json.loads((out / "campaign" / "campaign.json").read_text())
    positions = campaign["positions"]
    program = campaign["program"]
    walls = [position["wall_seconds"] for position in positions if position["wall_seconds"] is not None]
    generated_page.write(
        PAGE,
        [
            "# The paper's figures beside the twin's",
            "",
            "`make demo` runs the paper's calibration (Sensors 2018, 18, 2536) end to end in the digital twin, "
            "with the commands a rig takes: `campaign`, `fit`, `compare`, `upload` into the twin's IMU, "
            "field-warming and field-cooling runs on the uploaded surfaces, `validate` "
            "([calibration](calibration.md)). The tables below come from its folders "
            f"(`{out}`). The campaign: {len(positions)} positions "
            f"({', '.join(position['label'] for position in positions)}; the paper has 37), each through the "
            f"{program['start_c']:g}…{program['max_c']:g}…{program['start_c']:g} °C staircase with "
            f"{program['hold_s']} s holds (the paper's: 60 s), seed {campaign['seed']}, "
            f"{min(walls):.0f}–{max(walls):.0f} s of wall time a position.",
            "",
            *generated_page.stamp("make demo", started, load_at_start),
            "",
            *fit_section(out / "fit"),
            "",
            *compare_section(out / "fit"),
            "",
            *field_section(out / "fit", runs),
            "",
            *batch_section(out, refusal),
            "",
            *reading_section(out, json.loads((out / "batch" / "batch.json").read_text())["sensors"][0]),
            "",
            *lab,
        ],
    )


def main() -> None:
    out = Path(os.environ.get("DEMO_DIR", "runs/demo"))
    begin = time.monotonic()
    started, load_at_start = generated_page.now(), generated_page.load_average()
    users_registry = demo_lab.use_own_registry(out)

    step(f"1. calibration campaign in the twin: {POSITIONS}, each -10 -> 45 -> -10 degC")
    program = ("--positions", POSITIONS, "--hold-seconds", str(HOLD_SECONDS), "--rest-seconds", "0")
    thermotilt("campaign", "--twin", *program, "--out", str(out / "campaign"), "--force")

    step("2. fit the paper's surfaces (Tables 2-3), with statistics and the model-family comparison")
    thermotilt("fit", str(out / "campaign"), "--out", str(out / "fit"), "--compare-families")

    step("3. compare with the paper's fits and with the model the twin ran")
    thermotilt("compare", str(out / "fit"))
    thermotilt("compare", str(out / "fit"), "--reference", str(DEFAULT_MODEL))

    step("4. upload the coefficients into the twin's IMU through its serial port")
    eeprom = upload_through_pty(out / "fit", out / "board")

    step("5. field tests with the uploaded coefficients, then the paper's RMS check")
    runs = {name: out / name for name in ("field-warming", "field-cooling")}
    simulate_in_parallel({run: (name, "--eeprom", str(eeprom)) for name, run in runs.items()})
    for run in runs.values():
        thermotilt("validate", str(run), "--coefficients", str(out / "fit"))

    step(f"6. a batch of {BATCH_SENSORS} sensors on one tilt table: one chamber run a position, a fit each")
    thermotilt("campaign", "--twin", "--sensors", str(BATCH_SENSORS), *program, "--out", str(out / "batch"), "--force")
    thermotilt("fit", str(out / "batch"), "--out", str(out / "batch-fit"))
    sensors = json.loads((out / "batch" / "batch.json").read_text())["sensors"]
    for sensor in sensors:
        thermotilt("compare", str(out / "batch-fit" / sensor), "--reference", str(out / "batch" / "model.toml"))
    field_runs = {sensor: out / f"field-warming-{sensor}" for sensor in sensors}
    batch_model = ("--model", str(out / "batch" / "model.toml"))
    alternating = out / f"field-alternating-{sensors[0]}"
    simulate_in_parallel(
        {
            **{run: ("field-warming", *batch_model, "--sensor", sensor) for sensor, run in field_runs.items()},
            alternating: (
                "field-alternating",
                *batch_model,
                "--sensor",
                sensors[0],
                "--incl-x",
                str(ALTERNATING_INCL_X_DEG),
                "--duration",
                str(ALTERNATING_SECONDS),
            ),
        }
    )
    for sensor, run in [*field_runs.items(), (sensors[0], alternating)]:
        thermotilt("validate", str(run), "--coefficients", str(out / "batch-fit" / sensor))

    step("7. sensor IDs: a board refuses another sensor's fit and takes its own; each sensor's onto its board")
    refusal = refused_then_uploaded(out / "batch-fit", sensors, out / "batch-board")
    for sensor in sensors[1:]:
        upload_through_pty(out / "batch-fit" / sensor, out / "boards" / sensor, sensor=sensor)

    step(f"8. the lab: {sensors[0]} calibrated again, watched live; the new fit onto its board")
    recalibration = demo_lab.recalibrate(thermotilt, THERMOTILT, out, sensors[0], program)
    board = out / "boards" / sensors[0]
    upload_through_pty(recalibration, board, eeprom=out / "batch-board" / "imu_reader_eeprom.bin")

    step(f"9. the fleet and {sensors[0]}'s history, from the registry")
    listing, history = demo_lab.fleet_and_history(thermotilt, out, sensors[0])
    demo_lab.into_users_registry(thermotilt, out, users_registry)

    lab = demo_lab.lab_section(out, sensors[0], listing, history)
    write_paper_comparison(out, runs, refusal, lab, started, load_at_start)
    minutes = (time.monotonic() - begin) / 60.0
    step(
        f"done in {minutes:.1f} min; reports: {out}/fit/report.md, "
        f"{out}/field-warming/validation/report.md, {out}/field-cooling/validation/report.md, "
        f"{out}/batch-fit/<id>/certificate.html, {PAGE}"
    )


if __name__ == "__main__":
    main()
