"""``thermotilt campaign``'s workflow: the campaign started (or resumed) in
its folder, its plan said, its positions run with a progress bar and a line
for each position as it finishes; the outcome says what became of it."""

from __future__ import annotations

import sys
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

from ...ctrl_c import ctrl_c_after_block
from ...twin.scenarios import ScenarioOptions
from .folder import Position, PositionRecord
from .plan import CampaignOutcome, select_positions


@dataclass(frozen=True)
class CampaignRequest:
    out_dir: Path
    positions: str
    program: ScenarioOptions
    resume: bool = False
    force: bool = False


def report_position(record: PositionRecord) -> None:
    """A finished position's line, above the progress bar if one is running."""
    from tqdm import tqdm

    with ctrl_c_after_block():
        tqdm.write(record.line(), file=sys.stdout)
        for error in record.reported_errors:
            tqdm.write(f"{record.name()}: reported {error}", file=sys.stdout)
        sys.stdout.flush()


def run_twin_campaign(
    request: CampaignRequest, setup_options: dict, jobs: int, scheduler: str | None
) -> CampaignOutcome:
    """The campaign in the twin, its positions here, in jobs worker
    processes or on the Dask cluster at scheduler; setup_options are
    TwinSetup's (seed, model_path, enable, disable, sensor, population)."""
    from tqdm import tqdm

    from ...cluster import connect_cluster
    from .twin import TwinCampaign, TwinSetup, twin_build_problem

    with ExitStack() as resources:
        positions = select_positions(request.positions)
        # Connected before campaign.json is written, so a wrong address leaves nothing to --resume.
        cluster = (
            resources.enter_context(connect_cluster(scheduler, twin_build_problem, "run the twin"))
            if scheduler
            else None
        )
        setup = TwinSetup(request.program, **setup_options)
        campaign = TwinCampaign(request.out_dir, positions, setup, resume=request.resume, force=request.force)
        if cluster is None:
            running_on = f"{min(jobs, max(1, len(campaign.todo)))} at a time"
        else:
            threads = sum(cluster.nthreads().values())
            running_on = f"on the Dask cluster at {scheduler} ({threads} worker threads)"
        print(campaign.describe(running_on), flush=True)
        total = round(len(campaign.todo) * campaign.position_seconds)
        with tqdm(total=total, unit="sim s", disable=None, file=sys.stderr) as bar:
            return campaign.run(jobs, progress=bar.update, on_position=report_position, cluster=cluster)


def run_boards_campaign(
    request: CampaignRequest,
    imu_ports: tuple[str, ...],
    chamber_port: str,
    confirm: Callable[[Position], bool],
    baud: int,
    heartbeat_s: int,
) -> CampaignOutcome:
    """The campaign on real boards, the user moving the table when confirm asks."""
    from .rig import BoardsCampaign, BoardsSetup

    setup = BoardsSetup(imu_ports, chamber_port, request.program, confirm, baud=baud, heartbeat_s=heartbeat_s)
    positions = select_positions(request.positions)
    campaign = BoardsCampaign(request.out_dir, positions, setup, resume=request.resume, force=request.force)
    print(campaign.describe(), flush=True)
    return campaign.run(on_position=report_position)


def ask_at_the_terminal(position: Position) -> bool:
    """The user sets the table; Enter goes on, q (or a closed input) stops."""
    prompt = (
        f"Set the tilt table to {position.label} (X {position.incl_x_deg:+g} deg, "
        f"Y {position.incl_y_deg:+g} deg), then press Enter (q stops): "
    )
    try:
        return input(prompt).strip().lower() not in ("q", "quit")
    except EOFError:
        print("\nno answer: standard input is closed")
        return False
