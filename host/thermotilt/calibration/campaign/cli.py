"""``thermotilt campaign``'s arguments: in the twin (``--twin``) or on real
boards (``--imu-port``, ``--chamber-port``), and the workflow they start
(``session``)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from ...options import UsageError, add_model_options, add_program_options, as_usage_error, interrupted, within


def add_campaign(commands: argparse._SubParsersAction) -> None:
    campaign = commands.add_parser(
        "campaign", help="the paper's calibration: every tilt position through a -10..45..-10 degC cycle"
    )
    option = campaign.add_argument
    option("--out", required=True, help="campaign folder: one run folder per position and campaign.json")
    option("--twin", action="store_true", help="run it in the digital twin")
    option("--positions", default="all", help="all (default, the paper's 37) or labels, e.g. 0,X+15,X-15,Y+30")
    option(
        "--jobs",
        type=within(int, 1, 256),
        default=os.cpu_count() or 1,
        help="twin positions run at once (default: the CPU count)",
    )
    option(
        "--scheduler",
        metavar="ADDRESS",
        help="run the twin positions on the Dask cluster of this scheduler, "
        "e.g. tcp://HOST:8786, instead of --jobs local processes",
    )
    option(
        "--sensors",
        type=within(int, 1, 8),
        help="twin: draw a batch of this many sensors about the model (IDs TT-01...) and run each; "
        "a model with [[sensors]] runs its batch without this",
    )
    option("--sensor", metavar="ID", help="twin: run only this sensor of the model's [[sensors]]")
    option(
        "--imu-port",
        action="append",
        help="real boards: an IMU reader's serial port; repeat it for each board the tilt table carries "
        "(a batch: each board needs its own sensor ID, see assign-id)",
    )
    option("--chamber-port", help="real boards: the thermal chamber's serial port")
    option("--baud", type=int, default=115200, help="real boards' line speed (default 115200)")
    option(
        "--heartbeat-seconds",
        type=within(int, 0, 3600),
        default=60,
        help="real boards: the chamber stops itself after this long without a frame "
        "from the host (default 60; 0 turns it off)",
    )
    option(
        "--resume", action="store_true", help="finish an interrupted campaign in --out, keeping its finished positions"
    )
    option("--force", action="store_true", help="start --out again from nothing")
    option(
        "--serve",
        metavar="[HOST:]PORT",
        help="serve the live view of --out (read-only) on this address while the campaign runs, "
        "e.g. 8765 or 0.0.0.0:8765 (host 127.0.0.1 unless given; docs/live.md)",
    )
    add_model_options(campaign)
    add_program_options(campaign)
    campaign.set_defaults(run=_campaign)


def _campaign_errors() -> tuple[type[Exception], ...]:
    from ...cluster import ClusterError
    from ...physics import ModelError
    from .folder import CampaignError

    return CampaignError, ClusterError, ModelError


def _campaign(args: argparse.Namespace) -> int:
    from ...twin.scenarios import ScenarioOptions
    from .session import CampaignRequest, ask_at_the_terminal, run_boards_campaign, run_twin_campaign

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
    request = CampaignRequest(Path(args.out), args.positions, program, args.resume, args.force)
    with as_usage_error(*_campaign_errors()):
        if boards:
            ports = tuple(args.imu_port), args.chamber_port
            outcome = run_boards_campaign(request, *ports, ask_at_the_terminal, args.baud, args.heartbeat_seconds)
        else:
            twin = {"seed": args.seed, "model_path": args.model, "enable": tuple(args.enable)}
            twin |= {"disable": tuple(args.disable), "sensor": args.sensor, "population": args.sensors or 0}
            outcome = run_twin_campaign(request, twin, args.jobs, args.scheduler)
    problem = outcome.problem()
    if problem is not None:
        raise UsageError(problem)
    print(outcome.summary())
    return interrupted() if outcome.interrupted else 0
