"""``thermotilt watch CAMPAIGN_OR_RUN [--serve [HOST:]PORT]``, and for the
command line the live view of a command's ``--out`` served while the
command runs (``campaign --serve``). Starlette and uvicorn load only when
something is served, so a bad address or folder is answered at once."""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..options import as_usage_error
from .address import DEFAULT_HOST, DEFAULT_PORT, parse_address


def add_commands(commands: argparse._SubParsersAction) -> None:
    watch = commands.add_parser(
        "watch", help="follow a campaign or a run folder live in the browser (read-only; docs/live.md)"
    )
    watch.add_argument(
        "folder",
        metavar="CAMPAIGN_OR_RUN",
        help="a campaign folder (campaign.json, or batch.json for a batch) or a run folder (run.csv)",
    )
    watch.add_argument(
        "--serve",
        dest="address",
        metavar="[HOST:]PORT",
        default=str(DEFAULT_PORT),
        help=f"where to serve the page (default {DEFAULT_PORT}, host {DEFAULT_HOST}; port 0: any free port)",
    )
    watch.set_defaults(run=_watch)


def _watch(args: argparse.Namespace) -> int:
    address = parse_address(args.address)
    from .folder_state import FolderState, WatchError, folder_kind

    folder = Path(args.folder)
    with as_usage_error(WatchError):
        kind = folder_kind(folder)
    from .registry_lines import RegistryLines
    from .server import LiveServer

    server = LiveServer(FolderState(folder, RegistryLines()), address)
    print(f"live view of the {kind} {folder}: {server.url} (read-only; Ctrl-C stops)", flush=True)
    server.serve_here()
    return 0


@contextmanager
def serving_while_it_runs(args: argparse.Namespace) -> Iterator[None]:
    """The live view of args.out served in a background thread while the
    command runs, when args carry serve; nothing otherwise."""
    text = getattr(args, "serve", None)
    if not text:
        yield
        return
    address = parse_address(text)
    from .folder_state import FolderState
    from .registry_lines import RegistryLines
    from .server import LiveServer

    server = LiveServer(FolderState(Path(args.out), RegistryLines()), address)
    print(f"live view: {server.url} (read-only, while this command runs)", flush=True)
    server.start_in_background()
    try:
        yield
    finally:
        server.stop()
