"""Command line: ``thermotilt SUBCOMMAND ...``. Errors are one line on stderr
(docs/reliability.md lists them)."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, TYPE_CHECKING, NoReturn, Sequence, TypeVar

from tqdm import tqdm

from . import __version__
from .wire.coefficients import BLOCK_SIZE, CoefficientBlockError, decode_block, encode_block, setcoe_frames
from .surfaces import PAPER_DEFAULTS
from .wire.protocol import PROTOCOL_VERSION, FrameReader
from .twin.scenarios import CONTROLLERS, DEFAULT_HOLD_START, HOLD_STARTS

if TYPE_CHECKING:
    from .calibration.campaign import CampaignOutcome, PositionRecord

PROGRAM = "thermotilt"
# 128 + SIGINT, what a shell reports for a command stopped by Ctrl-C.
EXIT_INTERRUPTED = 130
_READ_CHUNK = 65536

# The LSM9DS0's operating range: the ambient of any rig it works in lies within it.
AMBIENT_RANGE_C = (-40.0, 85.0)
INCLINATION_RANGE_DEG = (-90.0, 90.0)
# The boards count time in uint32 milliseconds, which wrap after 49.7 days.
BOARD_SECONDS_RANGE = (0.001, (2**32 - 1) / 1000.0)
# The twin's UART corruption generator takes a 64-bit seed.
SEED_RANGE = (0, 2**64 - 1)
# An hour per step and a day of rest keep the paper's longest cycle (57
# steps) within the chamber firmware's uint32 milliseconds.
HOLD_SECONDS_RANGE = (1, 3600)
REST_SECONDS_RANGE = (0, 86400)

_Number = TypeVar("_Number", int, float)


class UsageError(Exception):
    """Bad input that the user can fix; reported as one line."""


class _ArgumentParser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:
        # argparse would print the usage too; one line is easier to read in logs.
        self.exit(2, f"{PROGRAM}: error: {_one_line(message)} (see --help)\n")

    def _print_message(self, message: str, file: IO[str] | None = None) -> None:
        # argparse drops write errors; --help on a full disk is reported like any output.
        if message:
            (file or sys.stderr).write(message)


def _within(
    parse: Callable[[str], _Number], low: _Number, high: _Number | None = None, unit: str = ""
) -> Callable[[str], _Number]:
    """An argparse type: a number from low to high (None: no upper limit)."""

    def show(value: _Number) -> str:
        return f"{value:.10g}" if isinstance(value, float) else str(value)

    def checked(text: str) -> _Number:
        value = parse(text)
        if not (low <= value and (high is None or value <= high)):
            span = f"at least {show(low)}" if high is None else f"from {show(low)} to {show(high)}"
            raise argparse.ArgumentTypeError(f"must be {span}{unit}, got {text}")
        return value

    # argparse names the type in "invalid float value: 'x'".
    checked.__name__ = parse.__name__
    return checked


def _interrupted() -> int:
    print(f"{PROGRAM}: interrupted", file=sys.stderr)
    return EXIT_INTERRUPTED


def _input_chunks(path: str) -> Iterator[bytes]:
    """The bytes of a file, or of standard input for "-", as they arrive
    (unbuffered, so a live stream is counted up to the moment it stops)."""
    name = "standard input" if path == "-" else path
    if path == "-" and sys.stdin is None:
        raise UsageError("standard input is closed")
    try:
        if path == "-":
            stream = open(sys.stdin.fileno(), "rb", buffering=0, closefd=False)
        else:
            stream = open(path, "rb", buffering=0)
        with stream:
            while chunk := stream.read(_READ_CHUNK):
                yield chunk
    except OSError as error:
        raise UsageError(f"cannot read {name}: {error.strerror or error}") from None


def _print_frame_counts(reader: FrameReader) -> None:
    print(f"frames: {reader.frames}")
    for frame_type, count in sorted(reader.frames_by_type.items()):
        print(f"  {frame_type}: {count}")
    print(f"malformed: {reader.malformed}")
    for reason, count in sorted(reader.malformed_by_reason.items()):
        print(f"  {reason}: {count}")
    print(f"gaps: {reader.gaps} (lost frames: {reader.lost_frames})")


def _command_frames(args: argparse.Namespace) -> int:
    reader = FrameReader()
    try:
        for chunk in _input_chunks(args.capture):
            reader.feed(chunk)
    except KeyboardInterrupt:
        _print_frame_counts(reader)
        return _interrupted()
    # A capture may end without a line end: the last line still counts.
    reader.feed(b"\n")
    if reader.frames == 0:
        raise UsageError(f"{args.capture}: no valid frames ({reader.malformed} malformed)")
    _print_frame_counts(reader)
    return 0


def _command_coefficients(args: argparse.Namespace) -> int:
    if args.block:
        data = b""
        # Enough to tell a wrong size; a device file is not read forever.
        for chunk in _input_chunks(args.block):
            data += chunk
            if len(data) > BLOCK_SIZE:
                break
        try:
            table = decode_block(data)
        except CoefficientBlockError as error:
            raise UsageError(f"{args.block}: {error}") from None
    else:
        table = PAPER_DEFAULTS
    if args.write_block:
        try:
            with open(args.write_block, "wb") as output:
                output.write(encode_block(table))
        except OSError as error:
            raise UsageError(
                f"cannot write {args.write_block}: {error.strerror or error}"
            ) from None
    for line in setcoe_frames(table):
        sys.stdout.write(line.rstrip("\r\n") + "\n")
    return 0


def _command_simulate(args: argparse.Namespace) -> int:
    from .twin import simulate
    from .physics import Model, ModelError, parse_fault
    from .run.log import RunLogError, read_run_log
    from .twin.scenarios import ScenarioError, ScenarioOptions, build
    from .twin.boards import TwinError

    try:
        model = Model.load(args.model)
        changes = {name: True for name in args.enable} | {name: False for name in args.disable}
        model = model.with_terms(changes).with_faults(parse_fault(text) for text in args.fault)
        scenario = build(
            args.scenario,
            ScenarioOptions(
                hold_s=args.hold_seconds,
                rest_s=args.rest_seconds,
                incl_x_deg=args.incl_x,
                incl_y_deg=args.incl_y,
                positions=tuple(args.positions.split(",")) if args.positions else None,
                ambient_c=args.ambient,
                duration_s=args.duration,
                hold_start=args.hold_start,
                controller=args.controller,
            ),
        )
    except (ModelError, ScenarioError) as error:
        raise UsageError(str(error)) from None
    eeprom = _eeprom_block(args.eeprom) if args.eeprom else None
    out_dir = Path(args.out or f"runs/{scenario.name}-{time.strftime('%Y%m%d-%H%M%S')}")
    if os.path.exists(out_dir / "run.csv") and not args.force:
        raise UsageError(f"{out_dir}/run.csv exists; choose another --out or add --force")

    def announce_pty(board: str, path: str) -> None:
        print(f"{board}: {path}", flush=True)

    realtime = args.pty if args.realtime is None else args.realtime == "on"
    in_real_time = " in real time" if realtime else ""
    print(f"{scenario.description}: {scenario.duration_s:.0f} s simulated{in_real_time} -> {out_dir}", flush=True)
    with tqdm(total=round(scenario.duration_s), unit="sim s", disable=None, file=sys.stderr) as bar:
        try:
            result = simulate.run(
                scenario, model, out_dir, seed=args.seed, pty=args.pty, on_pty=announce_pty,
                progress=lambda t: bar.update(round(t) - bar.n), eeprom=eeprom, realtime=realtime,
            )
        except (TwinError, simulate.SimulationError) as error:
            raise UsageError(str(error)) from None
        except OSError as error:
            raise UsageError(f"cannot write {out_dir}: {error.strerror or error}") from None
    summary = result.summary
    print(f"rows: {summary['rows']}  simulated: {summary['sim_seconds']:.0f} s  "
          f"wall: {summary['wall_seconds']:.1f} s  ({summary['speed_x_real_time']}x real time)")
    for board, report in summary["boards"].items():
        print(f"{board}: {report['frames']} frames, {report['rejected']} rejected, "
              f"{report['cycles']} cycles")
        for refusal in report["refused_commands"]:
            print(f"{board} refused {refusal}")
        for error in report["reported_errors"]:
            print(f"{board} reported {error}")
    if summary["interrupted"]:
        return _interrupted()
    try:
        rows = read_run_log(str(out_dir / "run.csv"))
    except RunLogError as error:
        raise UsageError(str(error)) from None
    _print_figures(scenario.name, rows)
    return 0


def _eeprom_block(path: str) -> bytes:
    """The --eeprom file: a coefficient block (coefficients.bin) or the whole
    EEPROM a twin run saved (imu_reader_eeprom.bin). What it holds is the
    firmware's to judge at boot, as with a real EEPROM."""
    from .twin.simulate import IMU_EEPROM_BYTES, IMU_EEPROM_FILE

    data = b""
    for chunk in _input_chunks(path):
        data += chunk
        if len(data) > IMU_EEPROM_BYTES:
            break
    if len(data) not in (BLOCK_SIZE, IMU_EEPROM_BYTES):
        size = f"more than {IMU_EEPROM_BYTES}" if len(data) > IMU_EEPROM_BYTES else str(len(data))
        raise UsageError(f"{path}: {size} bytes; --eeprom takes the {BLOCK_SIZE}-byte coefficient block "
                         f"that thermotilt fit writes (coefficients.bin) or the {IMU_EEPROM_BYTES}-byte "
                         f"EEPROM a run saved ({IMU_EEPROM_FILE})")
    return data


def announced_ports(lines: Iterable[str], boards: int = 2) -> dict[str, str]:
    """The pseudo-terminals `simulate --pty` announces ("imu_reader:
    /dev/pts/3") among its output lines, by board; EOFError when the lines
    end first."""
    ports = {}
    for line in lines:
        board, _, path = line.strip().partition(": ")
        if path.startswith("/dev/"):
            ports[board] = path
            if len(ports) == boards:
                return ports
    raise EOFError("the twin ended before announcing its ports")


def _print_figures(scenario_name: str, rows: list[dict[str, str]]) -> None:
    """The paper's numbers for the scenarios that have them."""
    from .twin.figures import drift_figures, fig8_figures, fig8_table, holds

    if scenario_name == "fig8":
        figures = fig8_figures(rows)
        for hold in figures["holds"]:
            print(f"hold {hold['setpoint_c']:g} degC: settled {hold['settled_c']:.2f}, "
                  f"offset (programmed - measured) {hold['offset_c']:+.2f} degC")
        for step in figures["steps"]:
            print(f"step {step['from_c']:g} -> {step['to_c']:g} degC: {step['completion_s']:.1f} s, "
                  f"overshoot {step['overshoot_c']:.2f} degC")
        for line in fig8_table(figures):
            print(line)
    # Holds shorter than the settling window give no drift to measure.
    elif scenario_name == "cycle" and holds(rows):
        figures = drift_figures(rows)
        for axis in ("x", "y"):
            print(f"{axis.upper()}: raw drift {figures[axis]['raw_span_lsb']:.0f} LSB, "
                  f"compensated {figures[axis]['compensated_span_lsb']:.0f} LSB")


def _command_log(args: argparse.Namespace) -> int:
    from .wire.logger import INTERRUPTED, LogError, log_boards
    from .run.log import format_number

    try:
        result = log_boards(
            imu_port=args.port,
            out_path=Path(args.out),
            chamber_port=args.chamber_port,
            baud=args.baud,
            duration_s=args.duration,
            max_rows=args.rows,
            raw_dir=Path(args.raw_dir) if args.raw_dir else None,
            context={
                "ambient_c": format_number(args.ambient, 3),
                "incl_x_deg": format_number(args.incl_x, 2),
                "incl_y_deg": format_number(args.incl_y, 2),
            },
            force=args.force,
        )
    except LogError as error:
        raise UsageError(str(error)) from None
    print(f"rows: {result.rows}  frames: {result.frames}  rejected: {result.rejected}  "
          f"gaps: {result.gaps}  ({result.end_reason})")
    return _interrupted() if result.end_reason == INTERRUPTED else 0


def _command_campaign(args: argparse.Namespace) -> int:
    from contextlib import ExitStack

    from .calibration.campaign import (
        BoardsCampaign,
        BoardsSetup,
        CampaignError,
        Position,
        TwinCampaign,
        TwinSetup,
        connect_cluster,
        select_positions,
    )
    from .twin.scenarios import ScenarioOptions

    boards = args.imu_port is not None or args.chamber_port is not None
    if args.twin == boards or (boards and not (args.imu_port and args.chamber_port)):
        raise UsageError("campaign needs --twin, or --imu-port and --chamber-port for real boards")
    if boards and args.scheduler:
        raise UsageError("--scheduler runs twin positions on a Dask cluster; it needs --twin")
    program = ScenarioOptions(hold_s=args.hold_seconds, rest_s=args.rest_seconds, ambient_c=args.ambient,
                              hold_start=args.hold_start, controller=args.controller)

    def confirm(position: Position) -> bool:
        prompt = (f"Set the tilt table to {position.label} (X {position.incl_x_deg:+g} deg, "
                  f"Y {position.incl_y_deg:+g} deg), then press Enter (q stops): ")
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
            cluster = resources.enter_context(connect_cluster(args.scheduler)) if args.scheduler else None
            if boards:
                campaign = BoardsCampaign(out_dir, positions, BoardsSetup(
                    args.imu_port, args.chamber_port, program, confirm, baud=args.baud,
                    heartbeat_s=args.heartbeat_seconds), resume=args.resume, force=args.force)
            else:
                campaign = TwinCampaign(out_dir, positions, TwinSetup(
                    program, seed=args.seed, model_path=args.model, enable=tuple(args.enable),
                    disable=tuple(args.disable)), resume=args.resume, force=args.force)
        except CampaignError as error:
            raise UsageError(str(error)) from None
        done = len(campaign.positions) - len(campaign.todo)
        where = f" on {args.imu_port} and {args.chamber_port}" if boards else ""
        print(f"campaign of {len(campaign.positions)} positions{where} -> {out_dir}"
              + (f" ({done} already done)" if done else "") + f": {len(campaign.todo)} to run", end="")
        if boards:
            print(flush=True)
            return _finish_campaign(campaign.run(on_position=_report_position), out_dir)
        jobs = min(args.jobs, max(1, len(campaign.todo)))
        if cluster is None:
            running_on = f"{jobs} at a time"
        else:
            threads = sum(cluster.nthreads().values())
            running_on = f"on the Dask cluster at {args.scheduler} ({threads} worker threads)"
        print(f", {campaign.position_seconds:.0f} s simulated each at most, {running_on}", flush=True)
        total = round(len(campaign.todo) * campaign.position_seconds)
        with tqdm(total=total, unit="sim s", disable=None, file=sys.stderr) as bar:
            outcome = campaign.run(jobs, progress=bar.update, on_position=_report_position, cluster=cluster)
        return _finish_campaign(outcome, out_dir)


@contextmanager
def _ctrl_c_after_block() -> Iterator[None]:
    """Ctrl-C during the block is raised when it ends. tqdm.write turns a
    KeyboardInterrupt that lands while it takes its lock into a
    RuntimeError, a traceback instead of exit 130."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pressed: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, _frame: pressed.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if pressed:
        raise KeyboardInterrupt


def _report_position(record: PositionRecord) -> None:
    from .calibration.campaign import DONE

    line = f"{record.label}: {record.status}"
    if record.status == DONE:
        line += f" in {record.wall_seconds:.0f} s"
    if record.error:
        line += f" ({record.error})"
    with _ctrl_c_after_block():
        # Above the progress bar, if one is running.
        tqdm.write(line, file=sys.stdout)
        for error in record.reported_errors:
            tqdm.write(f"{record.label}: reported {error}", file=sys.stdout)
        sys.stdout.flush()


def _finish_campaign(outcome: CampaignOutcome, out_dir: Path) -> int:
    from .calibration.campaign import DONE, FAILED

    if outcome.interrupted:
        print("kept every finished position; add --resume to run the others")
        return _interrupted()
    failed = [record for record in outcome.records if record.status == FAILED]
    if failed:
        raise UsageError(f"{len(failed)} position(s) failed: "
                         + "; ".join(f"{record.label}: {record.error}" for record in failed)
                         + "; fix it, then add --resume")
    left = [record.label for record in outcome.records if record.status != DONE]
    if left:
        raise UsageError(f"stopped with {len(left)} position(s) to run ({', '.join(left)}); "
                         "add --resume to run them")
    print(f"all {len(outcome.records)} positions done; fit them with: thermotilt fit {out_dir} --out FIT_DIR")
    return 0


def _command_fit(args: argparse.Namespace) -> int:
    from .calibration.dataset import CalibrationDataError, load
    from .calibration.fit import fit_campaign, format_table, write_outputs
    from .calibration.families import compare_families, format_families, recommend
    from .calibration.report import write_fit_report

    try:
        campaign = load(Path(args.campaign), settle_s=args.settle_seconds)
        fits = fit_campaign(campaign, tuple(args.axes))
        families = compare_families(campaign, tuple(args.axes)) if args.compare_families else None
    except CalibrationDataError as error:
        raise UsageError(str(error)) from None
    out_dir = Path(args.out)
    try:
        write_outputs(fits, campaign, out_dir)
        if families is not None:
            (out_dir / "families.json").write_text(json.dumps(
                {"recommended": recommend(families), "scores": [vars(score) for score in families]}, indent=2) + "\n")
        report = write_fit_report(out_dir, fits, campaign, format_families(families) if families else None)
    except OSError as error:
        raise UsageError(f"cannot write {out_dir}: {error.strerror or error}") from None
    print(f"{len(campaign.positions)} positions, {sum(fit.points for fit in fits)} points"
          + (f" ({campaign.skipped_rows} rows with empty cells skipped)" if campaign.skipped_rows else ""))
    if campaign.stabilizing_rows:
        print(f"{campaign.stabilizing_rows} rows left out: the chamber had not yet reached its "
              f"program's setpoint (docs/calibration.md)")
    print(format_table(fits))
    print("bounds: Newey-West (HAC) 95 % within each position; coefficients.json also has the "
          "OLS bounds, which ignore the rows' autocorrelation")
    if families is not None:
        print(format_families(families))
    print(f"wrote {out_dir / 'coefficients.json'}, coefficients.bin (EEPROM block), coefficients.h, "
          f"{report.name} with figures")
    return 0


def _command_compare(args: argparse.Namespace) -> int:
    from .calibration.compare import compare, format_comparison, read_fit
    from .calibration.dataset import CalibrationDataError

    try:
        comparisons = compare(read_fit(Path(args.fit_dir)), args.reference)
    except CalibrationDataError as error:
        raise UsageError(str(error)) from None
    print(format_comparison(comparisons, args.reference))
    return 0


def _command_discover(args: argparse.Namespace) -> int:
    from .discovery import report
    from .discovery.replay import DiscoveryDataError, load_measured
    from .discovery.search import Search
    from .native import NativeLibraryError
    from .physics import Model, ModelError

    try:
        model = Model.load(args.model)
        measured = load_measured(Path(args.measured), settle_s=args.settle_seconds)
    except (ModelError, DiscoveryDataError) as error:
        raise UsageError(str(error)) from None
    for channel, why in measured.skipped_channels.items():
        print(f"channel {channel} skipped: {why}")
    if measured.skipped_rows:
        print(f"{measured.skipped_rows} rows without chamber_c, time or angles skipped")
    print(f"{len(measured.time_s)} rows, channels {', '.join(measured.channels)}")
    try:
        outcome = Search(measured, model, progress=print).run()
    except NativeLibraryError as error:
        raise UsageError(str(error)) from None
    out_dir = Path(args.out)
    twin = model_path = None
    try:
        if args.twin:
            from .discovery.twin_gap import twin_gap

            model_path = report.write_model_file(outcome, measured, model.source, out_dir)
            twin = twin_gap(Path(args.measured), measured,
                            {"before": model, "after": Model.load(model_path)}, out_dir, progress=print)
        result = report.write(outcome, measured, model.source, out_dir, twin, model_path)
    except DiscoveryDataError as error:
        raise UsageError(str(error)) from None
    except OSError as error:
        raise UsageError(f"cannot write {out_dir}: {error.strerror or error}") from None
    print(f"verdict: {result['verdict']}")
    for effect in result["effects"]:
        (parameter, value), = effect["parameters"].items()
        low, high = effect["interval_95"][parameter]
        print(f"  {effect['name']} on {effect['channel']}: {parameter} = {value:.4g} {effect['unit']} "
              f"(95 % {low:.4g} .. {high:.4g}), adjusted p {effect['adjusted_p']:.2g}, "
              f"gap -{100 * effect['gap_reduction']:.0f} %")
    for group in result["ambiguous"]:
        print(f"  ambiguous on {group['channel']}: {', '.join(group['names'])}; "
              f"to separate them: {group['experiment']}")
    if result["not_testable"]:
        print(f"  not testable here: {', '.join(result['not_testable'])}")
    for channel, gap in result["gap"].items():
        twin_text = (f"; twin {gap['twin']['before']:.3f} -> {gap['twin']['after']:.3f}"
                     if "twin" in gap else "")
        print(f"  gap {channel}: {gap['replay']['before']:.3f} -> {gap['replay']['after']:.3f} "
              f"{gap['unit']} RMS{twin_text}")
    print(f"wrote {out_dir / 'discovery.json'}, model.toml, report.md, residuals.png")
    return 0


def _command_hide_effect(args: argparse.Namespace) -> int:
    from .discovery.hide import hide_effect
    from .discovery.replay import DiscoveryDataError
    from .native import NativeLibraryError
    from .physics import Model, ModelError

    try:
        model = Model.load(args.model)
        truth = hide_effect(Path(args.inputs), Path(args.out), args.effect, args.seed, snr=args.snr,
                            channel=args.channel, noise=args.noise, model=model, progress=print)
    except (ModelError, DiscoveryDataError, NativeLibraryError) as error:
        raise UsageError(str(error)) from None
    except OSError as error:
        raise UsageError(f"cannot write {args.out}: {error.strerror or error}") from None
    hidden = (f"{truth.effect} on {truth.channel} ({truth.parameter} {truth.value:.4g}, "
              f"SNR {truth.snr:.2f})" if truth.effect != "none" else "no effect")
    print(f"wrote {args.out}/run.csv with {hidden}, {truth.noise} noise "
          f"({truth.noise_rms:.3g} RMS); the truth is in truth.json")
    return 0


def _add_model_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=_within(int, *SEED_RANGE), default=1,
                        help="noise seed (default 1)")
    parser.add_argument("--model", help="physics model file (default: the packaged default.toml)")
    parser.add_argument("--enable", action="append", default=[], metavar="TERM",
                        help="switch a model term on (repeatable)")
    parser.add_argument("--disable", action="append", default=[], metavar="TERM",
                        help="switch a model term off (repeatable)")


def _add_program_options(parser: argparse.ArgumentParser, ambient: Callable[[str], float]) -> None:
    """The chamber program's settings, shared by simulate and campaign."""
    parser.add_argument("--hold-seconds", type=_within(int, *HOLD_SECONDS_RANGE), default=60,
                        help="time per chamber step (default 60, the paper's)")
    parser.add_argument("--rest-seconds", type=_within(int, *REST_SECONDS_RANGE), default=1200,
                        help="Peltier-off rest after each cycle (default 1200)")
    parser.add_argument("--ambient", type=ambient, help="ambient temperature for chamber scenarios")
    parser.add_argument("--controller", choices=tuple(CONTROLLERS), default="float",
                        help="chamber control law: float (the paper's P law, the firmware default) or "
                             "rounded-error (P on the error rounded to whole degC, a hypothesis about "
                             "the paper's code)")
    parser.add_argument("--hold-start", choices=HOLD_STARTS, default=DEFAULT_HOLD_START,
                        help="when a step's hold starts: T timed, F the first step of each cycle waits "
                             "for its setpoint, A every step waits (default)")


def _command_validate(args: argparse.Namespace) -> int:
    from .calibration.dataset import CalibrationDataError
    from .calibration.paper import FIELD_RMS_LSB, FIELD_TEST_SET
    from .calibration.report import write_validation_report
    from .calibration.validate import format_validation, load_coefficients, range_warnings, validate

    run = Path(args.run_path)
    try:
        coefficients = load_coefficients(args.coefficients) if args.coefficients else None
        validation = validate(run, coefficients)
    except CalibrationDataError as error:
        raise UsageError(str(error)) from None
    scenario = _scenario_of(run)
    paper = {(FIELD_TEST_SET[scenario], axis): FIELD_RMS_LSB[(scenario, axis)] for axis in ("X", "Y")
             if (scenario, axis) in FIELD_RMS_LSB}
    print(format_validation(validation, paper or None))
    for warning in range_warnings(validation):
        print(f"warning: {warning}")
    out_dir = Path(args.out) if args.out else (run if run.is_dir() else run.parent) / "validation"
    try:
        report = write_validation_report(out_dir, validation, coefficients, paper or None)
    except OSError as error:
        raise UsageError(f"cannot write {out_dir}: {error.strerror or error}") from None
    print(f"wrote {report}")
    return 0


def _scenario_of(run: Path) -> str | None:
    """The twin scenario a run folder holds, from its summary.json."""
    try:
        return json.loads(((run if run.is_dir() else run.parent) / "summary.json").read_text())["scenario"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _command_upload(args: argparse.Namespace) -> int:
    from .calibration.upload import UploadError, format_result, upload

    try:
        result = upload(Path(args.fit_dir), args.port, baud=args.baud, save=not args.no_save)
    except UploadError as error:
        raise UsageError(str(error)) from None
    print(format_result(result))
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _ArgumentParser(prog=PROGRAM, description="ThermoTilt host tools.")
    parser.add_argument(
        "--version",
        action="version",
        version=f"{PROGRAM} {__version__} (protocol {PROTOCOL_VERSION})",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    ambient = _within(float, *AMBIENT_RANGE_C, " degC")
    inclination = _within(float, *INCLINATION_RANGE_DEG, " deg")
    board_seconds = _within(float, *BOARD_SECONDS_RANGE, " s")

    frames = commands.add_parser(
        "frames", help="count the frames in a capture file: per type, malformed, sequence gaps"
    )
    frames.add_argument("capture", help="file of raw serial bytes, or - for standard input")
    frames.set_defaults(run=_command_frames)

    coefficients = commands.add_parser(
        "coefficients", help="print SETCOE frames for the paper's or a stored coefficient block"
    )
    coefficients.add_argument("--block", help="read a 148-byte EEPROM coefficient block")
    coefficients.add_argument("--write-block", help="also write the block to this file")
    coefficients.set_defaults(run=_command_coefficients)

    simulate = commands.add_parser(
        "simulate", help="run both firmware images in the digital twin against the physics model"
    )
    simulate.add_argument("scenario", help="fig8, cycle, campaign, field-warming, field-cooling, "
                          "field-alternating or idle (both boards, no commands: for --pty)")
    simulate.add_argument("--out", help="output folder (default runs/SCENARIO-DATE-TIME)")
    simulate.add_argument("--force", action="store_true", help="overwrite an earlier run in --out")
    _add_model_options(simulate)
    _add_program_options(simulate, ambient)
    simulate.add_argument("--incl-x", type=inclination, default=0.0,
                          help="table angle on X, degrees")
    simulate.add_argument("--incl-y", type=inclination, default=0.0,
                          help="table angle on Y, degrees")
    simulate.add_argument("--positions", help="campaign subset, e.g. 0,X+30,Y-15")
    simulate.add_argument("--duration", type=board_seconds,
                          help="field scenarios: compress the day's profile into this many seconds; "
                               "idle: run this long (default 3600)")
    simulate.add_argument("--fault", action="append", default=[], metavar="NAME[=RATE][@START[-END]]",
                          help="inject a fault, e.g. inner_open@120-180 or imu_uart_corrupt=0.001")
    simulate.add_argument("--pty", action="store_true",
                          help="also expose each board's serial port as a pseudo-terminal "
                               "(paced to the wall clock unless --realtime off)")
    simulate.add_argument("--realtime", choices=("on", "off"),
                          help="on: a simulated second takes a wall second, as on a board; "
                               "off: as fast as the host can (default on with --pty, off without)")
    simulate.add_argument("--eeprom", metavar="FILE",
                          help="start the IMU with this 148-byte coefficient block in its EEPROM "
                               "(coefficients.bin from thermotilt fit)")
    simulate.set_defaults(run=_command_simulate)

    campaign = commands.add_parser(
        "campaign", help="the paper's calibration: every tilt position through a -10..45..-10 degC cycle"
    )
    campaign.add_argument("--out", required=True, help="campaign folder: one run folder per position "
                          "and campaign.json")
    campaign.add_argument("--twin", action="store_true", help="run it in the digital twin")
    campaign.add_argument("--positions", default="all",
                          help="all (default, the paper's 37) or labels, e.g. 0,X+15,X-15,Y+30")
    campaign.add_argument("--jobs", type=_within(int, 1, 256), default=os.cpu_count() or 1,
                          help="twin positions run at once (default: the CPU count)")
    campaign.add_argument("--scheduler", metavar="ADDRESS",
                          help="run the twin positions on the Dask cluster of this scheduler, "
                               "e.g. tcp://HOST:8786, instead of --jobs local processes")
    campaign.add_argument("--imu-port", help="real boards: the IMU reader's serial port")
    campaign.add_argument("--chamber-port", help="real boards: the thermal chamber's serial port")
    campaign.add_argument("--baud", type=int, default=115200, help="real boards' line speed (default 115200)")
    campaign.add_argument("--heartbeat-seconds", type=_within(int, 0, 3600), default=60,
                          help="real boards: the chamber stops itself after this long without a frame "
                               "from the host (default 60; 0 turns it off)")
    campaign.add_argument("--resume", action="store_true",
                          help="finish an interrupted campaign in --out, keeping its finished positions")
    campaign.add_argument("--force", action="store_true", help="start --out again from nothing")
    _add_model_options(campaign)
    _add_program_options(campaign, ambient)
    campaign.set_defaults(run=_command_campaign)

    fit = commands.add_parser(
        "fit", help="fit the paper's drift surfaces to a campaign's run logs, with statistics"
    )
    fit.add_argument("campaign", help="folder of run logs (*/run.csv, *.csv); positions by their incl_x/y_deg")
    fit.add_argument("--out", required=True, help="folder for coefficients.json, .bin and .h")
    fit.add_argument("--settle-seconds", type=_within(float, 0.0, 3600.0, " s"),
                     help="skip rows this soon after a table move (default 120)")
    fit.add_argument("--axes", nargs="+", choices=("X", "Y"), default=["X", "Y"],
                     help="axes to fit (default X Y); the others stay uncorrected")
    fit.add_argument("--compare-families", action="store_true",
                     help="also score poly11, poly22 (the paper's), poly22+rate and poly33 by "
                          "leave-one-position-out CV RMSE and BIC; writes families.json")
    fit.set_defaults(run=_command_fit)

    compare = commands.add_parser(
        "compare", help="a fit beside the paper's Tables 2-3 or a model's surfaces: surface and coefficient differences"
    )
    compare.add_argument("fit_dir", help="a folder written by thermotilt fit")
    compare.add_argument("--reference", default="paper",
                         help="paper (default) or a model file (TOML) whose drift surfaces to compare with")
    compare.set_defaults(run=_command_compare)

    validate = commands.add_parser(
        "validate", help="the paper's field check: RMS about the 25 degC reading before and after compensation"
    )
    validate.add_argument("run_path", metavar="RUN", help="a run folder or run.csv (e.g. simulate field-warming, or a real log)")
    validate.add_argument("--coefficients", metavar="FIT_DIR",
                          help="compensate here with a fit's surfaces (a folder from thermotilt fit) or "
                               "'paper'; default: the firmware's own compensated output")
    validate.add_argument("--out", help="folder for report.md and its figures (default RUN/validation)")
    validate.set_defaults(run=_command_validate)

    upload = commands.add_parser(
        "upload", help="write a fit's surfaces into the IMU reader: SETCOE, read back, SAVECOE, reset, check"
    )
    upload.add_argument("fit_dir", help="a folder written by thermotilt fit (its coefficients.json)")
    upload.add_argument("--port", required=True, help="the IMU reader's serial port (or the twin's --pty port)")
    upload.add_argument("--baud", type=_within(int, 1), default=115200, help="line speed (default 115200)")
    upload.add_argument("--no-save", action="store_true",
                        help="upload to RAM only (coef_source U): no SAVECOE, no reset")
    upload.set_defaults(run=_command_upload)

    discover = commands.add_parser(
        "discover", help="where a measured run and the model's replay disagree, and which effect explains it"
    )
    discover.add_argument("measured", metavar="MEASURED", help="a run folder or run.csv (true_* columns are ignored)")
    discover.add_argument("--model", help="physics model file (default: the packaged default.toml)")
    discover.add_argument("--out", required=True, help="folder for discovery.json, model.toml, report.md")
    discover.add_argument("--settle-seconds", type=_within(float, 0.0, 3600.0), default=120.0,
                          help="leave out rows this close to the start and to a table move (default 120)")
    discover.add_argument("--twin", action="store_true",
                          help="MEASURED is a twin run: run its scenario (summary.json) again with the "
                               "model before and after discovery and report the gap to each")
    discover.set_defaults(run=_command_discover)

    hide = commands.add_parser(
        "hide-effect", help="a measured-looking run with one candidate effect hidden in it, for testing discover"
    )
    hide.add_argument("--inputs", required=True, metavar="RUN",
                      help="a run (folder or run.csv) whose chamber temperature, drive and table angles to reuse, "
                           "e.g. from thermotilt simulate")
    hide.add_argument("--effect", required=True, help="a candidate's name, none or random")
    hide.add_argument("--seed", type=_within(int, *SEED_RANGE), default=1, help="noise and draw seed")
    hide.add_argument("--snr", type=_within(float, 0.01, 1000.0),
                      help="effect RMS over noise RMS on its channel (default: drawn from 0.5..8)")
    hide.add_argument("--channel", choices=("temperature", "X", "Y", "Z", "inner", "outer"),
                      help="the channel the effect is sized on (default: drawn)")
    hide.add_argument("--noise", choices=("model", "white", "autocorrelated"), default="model",
                      help="the model's noise terms, white noise only, or 5x the model's flicker")
    hide.add_argument("--model", help="physics model file the effect is added to (default: the packaged one)")
    hide.add_argument("--out", required=True, help="folder for run.csv and truth.json")
    hide.set_defaults(run=_command_hide_effect)

    log = commands.add_parser("log", help="log real boards (or the twin's --pty ports) to run.csv")
    log.add_argument("--port", required=True, help="the IMU reader's serial port")
    log.add_argument("--out", required=True, help="run.csv to write")
    log.add_argument("--chamber-port", help="the thermal chamber's serial port, if logged too")
    log.add_argument("--baud", type=int, default=115200, help="line speed (default 115200)")
    log.add_argument("--duration", type=board_seconds,
                     help="stop after this many seconds of board time")
    log.add_argument("--rows", type=_within(int, 1), help="stop after this many rows")
    log.add_argument("--raw-dir", help="also save the raw bytes of each port in this folder")
    log.add_argument("--ambient", type=ambient, help="ambient temperature to record, degC")
    log.add_argument("--incl-x", type=inclination, help="table angle on X to record, degrees")
    log.add_argument("--incl-y", type=inclination, help="table angle on Y to record, degrees")
    log.add_argument("--force", action="store_true", help="overwrite an existing --out")
    log.set_defaults(run=_command_log)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    if sys.stdout is None:
        return _error("standard output is closed")
    try:
        return _run(argv)
    except KeyboardInterrupt:
        return _interrupted()
    except BrokenPipeError:
        # The reader left (`thermotilt ... | head`): nobody is left to tell.
        _discard_stdout()
        return 1
    except OSError as error:
        # Every file a command writes reports its own errors; what is left is
        # standard output, e.g. on a full disk.
        _discard_stdout()
        return _error(f"cannot write standard output: {error.strerror or error}")


def _run(argv: Sequence[str] | None) -> int:
    # A file name that is not UTF-8 is still printable.
    sys.stdout.reconfigure(errors="backslashreplace")
    try:
        args = build_parser().parse_args(argv)
    finally:
        # --help and --version print and exit: a failed write shows here.
        sys.stdout.flush()
    try:
        status = args.run(args)
    except UsageError as error:
        status = _error(str(error))
    sys.stdout.flush()
    return status


def _error(message: str) -> int:
    print(f"{PROGRAM}: error: {_one_line(message)}", file=sys.stderr)
    return 1


def _one_line(message: str) -> str:
    """An error with a file name or argument that holds a line break is
    still one line: control characters are escaped."""
    return "".join(char if char.isprintable() else repr(char)[1:-1] for char in message)


def _discard_stdout() -> None:
    """Point standard output at /dev/null, so the interpreter's last flush of
    what could not be written raises nothing more."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
