"""The calibration's commands: ``campaign`` (every tilt position through the
chamber's staircase, in the twin or on real boards), ``fit``, ``compare``,
``validate``, ``upload`` and ``assign-id`` (docs/calibration.md)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from ..ctrl_c import ctrl_c_after_block
from ..options import (
    UsageError,
    add_model_options,
    add_program_options,
    existing_folder,
    existing_run,
    interrupted,
    settle_seconds,
    within,
)

if TYPE_CHECKING:
    from distributed import Client

    from .campaign import CampaignOutcome, Position, PositionRecord, TwinSetup


def add_commands(commands: argparse._SubParsersAction) -> None:
    campaign = commands.add_parser(
        "campaign", help="the paper's calibration: every tilt position through a -10..45..-10 degC cycle"
    )
    campaign.add_argument("--out", required=True, help="campaign folder: one run folder per position and campaign.json")
    campaign.add_argument("--twin", action="store_true", help="run it in the digital twin")
    campaign.add_argument(
        "--positions", default="all", help="all (default, the paper's 37) or labels, e.g. 0,X+15,X-15,Y+30"
    )
    campaign.add_argument(
        "--jobs",
        type=within(int, 1, 256),
        default=os.cpu_count() or 1,
        help="twin positions run at once (default: the CPU count)",
    )
    campaign.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run the twin positions on the Dask cluster of this scheduler, "
        "e.g. tcp://HOST:8786, instead of --jobs local processes",
    )
    campaign.add_argument(
        "--sensors",
        type=within(int, 1, 8),
        help="twin: draw a batch of this many sensors about the model (IDs TT-01...) and run each; "
        "a model with [[sensors]] runs its batch without this",
    )
    campaign.add_argument("--sensor", metavar="ID", help="twin: run only this sensor of the model's [[sensors]]")
    campaign.add_argument(
        "--imu-port",
        action="append",
        help="real boards: an IMU reader's serial port; repeat it for each board the tilt table carries "
        "(a batch: each board needs its own sensor ID, see assign-id)",
    )
    campaign.add_argument("--chamber-port", help="real boards: the thermal chamber's serial port")
    campaign.add_argument("--baud", type=int, default=115200, help="real boards' line speed (default 115200)")
    campaign.add_argument(
        "--heartbeat-seconds",
        type=within(int, 0, 3600),
        default=60,
        help="real boards: the chamber stops itself after this long without a frame "
        "from the host (default 60; 0 turns it off)",
    )
    campaign.add_argument(
        "--resume", action="store_true", help="finish an interrupted campaign in --out, keeping its finished positions"
    )
    campaign.add_argument("--force", action="store_true", help="start --out again from nothing")
    add_model_options(campaign)
    add_program_options(campaign)
    campaign.set_defaults(run=_campaign)

    fit = commands.add_parser("fit", help="fit the paper's drift surfaces to a campaign's run logs, with statistics")
    fit.add_argument(
        "campaign", type=existing_folder, help="folder of run logs (*/run.csv, *.csv); positions by their incl_x/y_deg"
    )
    fit.add_argument("--out", required=True, help="folder for coefficients.json, .bin and .h")
    fit.add_argument(
        "--settle-seconds", type=settle_seconds, help="skip rows this soon after a table move (default 120)"
    )
    fit.add_argument(
        "--axes",
        nargs="+",
        choices=("X", "Y"),
        default=["X", "Y"],
        help="axes to fit (default X Y); the others stay uncorrected",
    )
    fit.add_argument(
        "--sensor-id",
        type=sensor_id,
        help="the sensor the campaign calibrated, for a campaign that did not record it "
        "(campaign.json from real boards records the IMU's ID; upload refuses a fit for another sensor)",
    )
    fit.add_argument(
        "--compare-families",
        action="store_true",
        help="also score poly11, poly22 (the paper's), poly22+rate and poly33 by "
        "leave-one-position-out CV RMSE and BIC; writes families.json",
    )
    fit.set_defaults(run=_fit)

    compare = commands.add_parser(
        "compare", help="a fit beside the paper's Tables 2-3 or a model's surfaces: surface and coefficient differences"
    )
    compare.add_argument("fit_dir", type=existing_folder, help="a folder written by thermotilt fit")
    compare.add_argument(
        "--reference",
        default="paper",
        help="paper (default) or a model file (TOML) whose drift surfaces to compare with; of a batch "
        "model (a batch campaign's model.toml), the fitted sensor's",
    )
    compare.set_defaults(run=_compare)

    validate = commands.add_parser(
        "validate", help="the paper's field check: RMS about the 25 degC reading before and after compensation"
    )
    validate.add_argument(
        "run_path",
        metavar="RUN",
        type=existing_run,
        help="a run folder or run.csv (e.g. simulate field-warming, or a real log)",
    )
    validate.add_argument(
        "--coefficients",
        metavar="FIT_DIR",
        help="compensate here with a fit's surfaces (a folder from thermotilt fit) or "
        "'paper'; default: the firmware's own compensated output",
    )
    validate.add_argument("--out", help="folder for report.md and its figures (default RUN/validation)")
    validate.set_defaults(run=_validate)

    upload = commands.add_parser(
        "upload", help="write a fit's surfaces into the IMU reader: SETCOE, read back, SAVECOE, reset, check"
    )
    upload.add_argument("fit_dir", help="a folder written by thermotilt fit (its coefficients.json)")
    upload.add_argument("--port", required=True, help="the IMU reader's serial port (or the twin's --pty port)")
    upload.add_argument("--baud", type=within(int, 1), default=115200, help="line speed (default 115200)")
    upload.add_argument(
        "--no-save", action="store_true", help="upload to RAM only (coef_source U): no SAVECOE, no reset"
    )
    upload.set_defaults(run=_upload)

    assign = commands.add_parser(
        "assign-id", help="give the IMU reader the sensor ID its fits are made for (kept in its EEPROM)"
    )
    assign.add_argument("sensor_id", metavar="ID", type=sensor_id, help="up to 8 letters, digits, '_' or '-'")
    assign.add_argument("--port", required=True, help="the IMU reader's serial port (or the twin's --pty port)")
    assign.add_argument("--baud", type=within(int, 1), default=115200, help="line speed (default 115200)")
    assign.add_argument(
        "--replace",
        action="store_true",
        help="replace another ID the board already has (coefficients fitted for that ID then stop loading)",
    )
    assign.set_defaults(run=_assign_id)


def sensor_id(text: str) -> str:
    """An argparse type: a sensor ID (lib/Compensation's rule), not empty."""
    from ..wire.coefficients import sensor_id_problem

    problem = sensor_id_problem(text) if text else "a sensor ID cannot be empty"
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return text


def _campaign(args: argparse.Namespace) -> int:
    from contextlib import ExitStack

    from ..cluster import ClusterError, connect_cluster
    from ..physics import ModelError
    from ..twin.scenarios import ScenarioOptions
    from .campaign import (
        BoardsCampaign,
        BoardsSetup,
        CampaignError,
        TwinSetup,
        select_positions,
        twin_build_problem,
    )

    boards = args.imu_port is not None or args.chamber_port is not None
    if args.twin == boards or (boards and not (args.imu_port and args.chamber_port)):
        raise UsageError("campaign needs --twin, or --imu-port and --chamber-port for real boards")
    if boards and args.scheduler:
        raise UsageError("--scheduler runs twin positions on a Dask cluster; it needs --twin")
    if boards and (args.sensor or args.sensors):
        raise UsageError("--sensor and --sensors choose the twin's sensors; real boards are the sensors on the ports")
    if args.sensor and args.sensors:
        raise UsageError("--sensors N draws a batch, --sensor ID runs one sensor of the model's batch: give one")
    program = ScenarioOptions(
        hold_s=args.hold_seconds,
        rest_s=args.rest_seconds,
        ambient_c=args.ambient,
        hold_start=args.hold_start,
        controller=args.controller,
    )

    def confirm(position: Position) -> bool:
        prompt = (
            f"Set the tilt table to {position.label} (X {position.incl_x_deg:+g} deg, "
            f"Y {position.incl_y_deg:+g} deg), then press Enter (q stops): "
        )
        try:
            return input(prompt).strip().lower() not in ("q", "quit")
        except EOFError:
            print("\nno answer: standard input is closed")
            return False

    out_dir = Path(args.out)
    with ExitStack() as resources:
        try:
            positions = select_positions(args.positions)
            # Connected before campaign.json is written, so a wrong address leaves nothing to --resume.
            cluster = (
                resources.enter_context(connect_cluster(args.scheduler, twin_build_problem, "run the twin"))
                if args.scheduler
                else None
            )
            if boards:
                campaign = BoardsCampaign(
                    out_dir,
                    positions,
                    BoardsSetup(
                        tuple(args.imu_port),
                        args.chamber_port,
                        program,
                        confirm,
                        baud=args.baud,
                        heartbeat_s=args.heartbeat_seconds,
                    ),
                    resume=args.resume,
                    force=args.force,
                )
                done = len(campaign.positions) - len(campaign.todo)
                if campaign.batch:
                    print(
                        f"a batch of {len(campaign.ports)} sensors on one tilt table, each its own campaign in "
                        f"{out_dir}/<ID>: "
                        + ", ".join(f"{unit.sensor} on {port}" for unit, port in campaign.ports.items())
                    )
                print(
                    f"campaign of {len(campaign.positions)} positions on {', '.join(args.imu_port)} and "
                    f"{args.chamber_port} -> {out_dir}"
                    + (f" ({done} already done)" if done else "")
                    + f": {len(campaign.todo)} to run",
                    flush=True,
                )
                return _finish_campaign(campaign.run(on_position=report_position), out_dir, campaign.batch)
            setup = TwinSetup(
                program,
                seed=args.seed,
                model_path=args.model,
                enable=tuple(args.enable),
                disable=tuple(args.disable),
                sensor=args.sensor,
                population=args.sensors or 0,
            )
        except (CampaignError, ClusterError, ModelError) as error:
            raise UsageError(str(error)) from None
        return _twin_campaign(out_dir, positions, setup, args, cluster)


def _twin_campaign(
    out_dir: Path, positions: list[Position], setup: TwinSetup, args: argparse.Namespace, cluster: Client | None
) -> int:
    from tqdm import tqdm

    from .campaign import CampaignError, TwinCampaign

    try:
        campaign = TwinCampaign(out_dir, positions, setup, resume=args.resume, force=args.force)
    except CampaignError as error:
        raise UsageError(str(error)) from None
    done = len(campaign.positions) - len(campaign.todo)
    jobs = min(args.jobs, max(1, len(campaign.todo)))
    if cluster is None:
        running_on = f"{jobs} at a time"
    else:
        threads = sum(cluster.nthreads().values())
        running_on = f"on the Dask cluster at {args.scheduler} ({threads} worker threads)"
    if campaign.batch:
        sensors = [unit.sensor for unit in campaign.units]
        print(
            f"a batch of {len(sensors)} sensors ({', '.join(sensors)}) on one tilt table, "
            f"each its own campaign in {out_dir}/<ID>"
        )
    print(
        f"campaign of {len(campaign.positions)} positions -> {out_dir}"
        + (f" ({done} already done)" if done else "")
        + f": {len(campaign.todo)} to run, {campaign.position_seconds:.0f} s simulated each at most, {running_on}",
        flush=True,
    )
    total = round(len(campaign.todo) * campaign.position_seconds)
    with tqdm(total=total, unit="sim s", disable=None, file=sys.stderr) as bar:
        outcome = campaign.run(jobs, progress=bar.update, on_position=report_position, cluster=cluster)
    return _finish_campaign(outcome, out_dir, campaign.batch)


def report_position(record: PositionRecord) -> None:
    """A finished position's line, above the progress bar if one is running."""
    from tqdm import tqdm

    from .campaign import DONE

    line = f"{_position_name(record)}: {record.status}"
    if record.status == DONE:
        line += f" in {record.wall_seconds:.0f} s"
    if record.error:
        line += f" ({record.error})"
    with ctrl_c_after_block():
        tqdm.write(line, file=sys.stdout)
        for error in record.reported_errors:
            tqdm.write(f"{_position_name(record)}: reported {error}", file=sys.stdout)
        sys.stdout.flush()


def _position_name(record: PositionRecord) -> str:
    """A position's label, after its sensor's ID where it has one."""
    return f"{record.sensor_id} {record.label}" if record.sensor_id else record.label


def _finish_campaign(outcome: CampaignOutcome, out_dir: Path, batch: bool = False) -> int:
    from .campaign import DONE, FAILED

    if outcome.interrupted:
        print("kept every finished position; add --resume to run the others")
        return interrupted()
    # A batch's sensors share each position's chamber run, and so its failure.
    failed = dict.fromkeys(
        f"{_position_name(record)}: {record.error}" for record in outcome.records if record.status == FAILED
    )
    if failed:
        raise UsageError(f"{len(failed)} position(s) failed: " + "; ".join(failed) + "; fix it, then add --resume")
    left = [_position_name(record) for record in outcome.records if record.status != DONE]
    if left:
        raise UsageError(f"stopped with {len(left)} position(s) to run ({', '.join(left)}); add --resume to run them")
    if batch:
        print(
            f"all {len(outcome.records)} sensor positions done; fit them with: "
            f"thermotilt fit {out_dir} --out FIT_DIR (a folder per sensor)"
        )
    else:
        print(f"all {len(outcome.records)} positions done; fit them with: thermotilt fit {out_dir} --out FIT_DIR")
    return 0


def _fit(args: argparse.Namespace) -> int:
    from .campaign import batch_of

    campaign_dir, out_dir = Path(args.campaign), Path(args.out)
    try:
        sensor_ids = batch_of(campaign_dir)
    except ValueError as error:
        raise UsageError(str(error)) from None
    if not sensor_ids:
        _fit_one(campaign_dir, out_dir, args)
        return 0
    if args.sensor_id is not None:
        raise UsageError(f"--sensor-id names one sensor; {campaign_dir} is a batch, each sensor named by its campaign")
    results = []
    for unit in sensor_ids:
        print(f"== sensor {unit}")
        results.append((unit, _fit_one(campaign_dir / unit, out_dir / unit, args)))
    print(f"{len(sensor_ids)} sensors fitted, one folder each in {out_dir}:")
    for unit, certificate in results:
        print(f"  {unit:<8}  U = {certificate['tilt_u95_deg']:.4f} deg  -> {out_dir / unit}")
    return 0


def _fit_one(campaign_dir: Path, out_dir: Path, args: argparse.Namespace) -> dict:
    """One sensor's campaign fitted into out_dir; its certificate."""
    from .certificate import certify, write_certificate
    from .dataset import CalibrationDataError, load
    from .families import compare_families, format_families, write_families
    from .fit import fit_campaign, format_table, write_outputs
    from .report import write_fit_report

    try:
        campaign = load(campaign_dir, settle_s=args.settle_seconds)
        fits = fit_campaign(campaign, tuple(args.axes))
    except CalibrationDataError as error:
        raise UsageError(str(error)) from None
    fitted_for = campaign.sensor_id or ""
    if args.sensor_id is not None:
        if fitted_for and args.sensor_id != fitted_for:
            raise UsageError(
                f"--sensor-id {args.sensor_id}: the campaign in {campaign_dir} was logged with sensor {fitted_for}"
            )
        fitted_for = args.sensor_id
    try:
        certificate, errors = certify(campaign, fits, campaign_dir, fitted_for)
        families = compare_families(campaign, tuple(args.axes)) if args.compare_families else None
    except CalibrationDataError as error:
        raise UsageError(str(error)) from None
    try:
        write_outputs(fits, campaign, out_dir, fitted_for)
        if families is not None:
            write_families(families, out_dir)
        report = write_fit_report(out_dir, fits, campaign, format_families(families) if families else None)
        write_certificate(out_dir, certificate, errors)
    except OSError as error:
        raise UsageError(f"cannot write {out_dir}: {error.strerror or error}") from None
    print(
        f"{len(campaign.positions)} positions, {sum(fit.points for fit in fits)} points"
        + (f" ({campaign.skipped_rows} rows with empty cells skipped)" if campaign.skipped_rows else "")
    )
    if campaign.stabilizing_rows:
        print(
            f"{campaign.stabilizing_rows} rows left out: the chamber had not yet reached its "
            f"program's setpoint (docs/calibration.md)"
        )
    print(format_table(fits))
    print(
        "bounds: Newey-West (HAC) 95 % within each position; coefficients.json also has the "
        "OLS bounds, which ignore the rows' autocorrelation"
    )
    if families is not None:
        print(format_families(families))
    print(f"fitted for sensor {fitted_for}" if fitted_for else "fitted for no particular sensor (no sensor ID)")
    uncertainty = certificate["uncertainty"]
    print(
        f"tilt uncertainty over the calibrated domain: U = {certificate['tilt_u95_deg']:.4f} deg "
        f"(95 %, k = {uncertainty['coverage_factor']:.2f}; {uncertainty['rows']} rows worth "
        f"{uncertainty['effective_rows']:.0f} independent values)"
    )
    print(
        f"wrote {out_dir / 'coefficients.json'}, coefficients.bin (EEPROM block), coefficients.h, "
        f"{report.name} with figures, certificate.json and certificate.html"
    )
    return certificate


def _compare(args: argparse.Namespace) -> int:
    from .compare import compare, fitted_sensor_id, format_comparison, read_fit
    from .dataset import CalibrationDataError

    fit_dir = Path(args.fit_dir)
    try:
        comparisons = compare(read_fit(fit_dir), args.reference, fitted_sensor_id(fit_dir))
    except CalibrationDataError as error:
        raise UsageError(str(error)) from None
    print(format_comparison(comparisons, args.reference))
    return 0


def _validate(args: argparse.Namespace) -> int:
    from ..run.folder import RunFolder
    from ..run.summary import RunSummaryError
    from .dataset import CalibrationDataError
    from .paper import field_rms_lsb
    from .report import write_validation_report
    from .validate import format_validation, load_coefficients, range_warnings, validate

    run = RunFolder.of(args.run_path)
    try:
        coefficients = load_coefficients(args.coefficients) if args.coefficients else None
        validation = validate(run.log, coefficients)
        summary = run.summary()
    except (CalibrationDataError, RunSummaryError) as error:
        raise UsageError(str(error)) from None
    paper = field_rms_lsb(summary.scenario if summary is not None else None)
    print(format_validation(validation, paper))
    for warning in range_warnings(validation):
        print(f"warning: {warning}")
    out_dir = Path(args.out) if args.out else run.path / "validation"
    document = run.path / "validation.json"
    try:
        report = write_validation_report(out_dir, validation, coefficients, paper)
        document.write_text(json.dumps(validation.document(), indent=2) + "\n", encoding="utf-8")
    except OSError as error:
        raise UsageError(f"cannot write {error.filename or out_dir}: {error.strerror or error}") from None
    print(f"wrote {report} and {document}")
    return 0


def _upload(args: argparse.Namespace) -> int:
    from .upload import UploadError, format_result, upload

    try:
        result = upload(Path(args.fit_dir), args.port, baud=args.baud, save=not args.no_save)
    except UploadError as error:
        raise UsageError(str(error)) from None
    print(format_result(result))
    return 0


def _assign_id(args: argparse.Namespace) -> int:
    from .upload import UploadError, assign_id, format_assignment

    try:
        result = assign_id(args.port, args.sensor_id, baud=args.baud, replace=args.replace)
    except UploadError as error:
        raise UsageError(str(error)) from None
    print(format_assignment(result))
    return 0
