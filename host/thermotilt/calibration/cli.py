"""The calibration's commands: ``campaign`` (every tilt position through the
chamber's staircase, in the twin or on real boards), ``fit``, ``compare``,
``validate``, ``upload`` and ``assign-id`` (docs/calibration.md). Each
parses its arguments and calls one workflow, whose result writes its files
and says what it did."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..options import (
    as_usage_error,
    existing_folder,
    existing_run,
    settle_seconds,
    within,
)
from ..surfaces import sensor_id_problem
from .campaign.cli import add_campaign


def add_commands(commands: argparse._SubParsersAction) -> None:
    for add in (add_campaign, _add_fit, _add_compare, _add_validate, _add_upload, _add_assign_id):
        add(commands)


def sensor_id(text: str) -> str:
    """An argparse type: a sensor ID (lib/Compensation's rule), not empty."""
    problem = sensor_id_problem(text) if text else "a sensor ID cannot be empty"
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return text


def _add_fit(commands: argparse._SubParsersAction) -> None:
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
        "--previous-fit",
        type=existing_folder,
        metavar="FIT_DIR",
        help="the sensor's calibration before this one (a fit folder, or a batch's with a folder per sensor): "
        "the change of its drift surfaces since enters the certificate as the long-term stability component "
        "(default: each sensor's latest calibration in the registry)",
    )
    fit.add_argument(
        "--compare-families",
        action="store_true",
        help="also score poly11, poly22 (the paper's), poly22+rate and poly33 by "
        "leave-one-position-out CV RMSE and BIC; writes families.json",
    )
    # The command line gives find_previous_fit from the registry (registry.recalibration).
    fit.set_defaults(run=_fit, find_previous_fit=None)


def _add_compare(commands: argparse._SubParsersAction) -> None:
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


def _add_validate(commands: argparse._SubParsersAction) -> None:
    validate = commands.add_parser(
        "validate",
        help="a field run as a monitoring user reads it: the change of tilt from the installation reading, "
        "against the certificate's U; --paper adds the paper's RMS about the 25 degC reading",
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
    validate.add_argument(
        "--baseline",
        metavar="TIME",
        type=within(float, 0.0, unit="s"),
        help="the installation reading is the minute from this run time (run.csv's time_s); "
        "default: the first settled minute",
    )
    validate.add_argument(
        "--certificate",
        metavar="PATH",
        help="hold each row against this certificate.json (or a fit folder's); default: the --coefficients fit's",
    )
    validate.add_argument(
        "--paper",
        action="store_true",
        help="also print the paper's measure (section 4.3): each set about its own 25 degC reading",
    )
    validate.add_argument("--out", help="folder for report.md and its figures (default RUN/validation)")
    validate.set_defaults(run=_validate)


def _add_upload(commands: argparse._SubParsersAction) -> None:
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


def _add_assign_id(commands: argparse._SubParsersAction) -> None:
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


def _fit(args: argparse.Namespace) -> int:
    from .dataset import CalibrationDataError
    from .fitting import FitOptions, fit_folder, fits_by_sensor

    with as_usage_error(CalibrationDataError):
        previous = fits_by_sensor(Path(args.previous_fit)) if args.previous_fit else {}
        options = FitOptions(
            tuple(args.axes),
            args.settle_seconds,
            args.sensor_id,
            args.compare_families,
            previous,
            args.find_previous_fit,
        )
        fit = fit_folder(Path(args.campaign), Path(args.out), options)
        fitted = {sensor.fitted_for for sensor in fit.sensors.values()}
        if args.previous_fit and not fitted & previous.keys():
            raise CalibrationDataError(
                f"--previous-fit {args.previous_fit}: its fits are of {', '.join(sorted(previous))}, "
                f"not of {', '.join(sorted(fitted - {''})) or 'the sensor fitted (it has no ID)'}"
            )
        fit.write()
    print(fit.summary())
    return 0


def _compare(args: argparse.Namespace) -> int:
    from .compare import compare_fit
    from .dataset import CalibrationDataError

    with as_usage_error(CalibrationDataError):
        comparison = compare_fit(Path(args.fit_dir), args.reference)
    print(comparison.summary())
    return 0


def _validate(args: argparse.Namespace) -> int:
    from .dataset import CalibrationDataError
    from .validate import ValidateOptions, validate_run

    options = ValidateOptions(
        args.coefficients,
        Path(args.out) if args.out else None,
        args.baseline,
        Path(args.certificate) if args.certificate else None,
        args.paper,
    )
    with as_usage_error(CalibrationDataError):
        validation = validate_run(Path(args.run_path), options)
        validation.write()
    print(validation.summary())
    return 0


def _upload(args: argparse.Namespace) -> int:
    from .upload import UploadError, format_result, upload
    from .upload_record import record_upload

    with as_usage_error(UploadError):
        result = upload(Path(args.fit_dir), args.port, baud=args.baud, save=not args.no_save)
    print(format_result(result))
    try:
        print(f"recorded in {record_upload(Path(args.fit_dir), result)}")
    except OSError as error:
        print(
            f"thermotilt: warning: uploaded, but not recorded in {args.fit_dir}: {error.strerror or error}",
            file=sys.stderr,
        )
    return 0


def _assign_id(args: argparse.Namespace) -> int:
    from .upload import UploadError, assign_id, format_assignment

    with as_usage_error(UploadError):
        result = assign_id(args.port, args.sensor_id, baud=args.baud, replace=args.replace)
    print(format_assignment(result))
    return 0
