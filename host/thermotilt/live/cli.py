"""``thermotilt watch CAMPAIGN_OR_RUN [--serve [HOST:]PORT]``, and for the
command line the live view of a command's ``--out`` served while the
command runs (``campaign --serve``). Starlette and uvicorn load only when
something is served, so a bad address or folder is answered at once."""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ..options import as_usage_error
from ..registry import ENVIRONMENT_VARIABLE
from .address import DEFAULT_HOST, DEFAULT_PORT, bind, parse_address

# uvicorn's graceful stop (server.GRACEFUL_STOP_S) and then some.
STOP_WAIT_S = 5.0


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
    watch.add_argument(
        "--registry",
        metavar="URL",
        help=f"the registry whose line of each sensor the page shows (default: ${ENVIRONMENT_VARIABLE}, "
        "else runs/registry.sqlite3 here)",
    )
    watch.add_argument("--listening-fd", type=int, help=argparse.SUPPRESS)
    watch.add_argument("--for-pid", type=int, help=argparse.SUPPRESS)
    watch.set_defaults(run=_watch)


def _watch(args: argparse.Namespace) -> int:
    from .folder_state import FolderState, WatchError, folder_kind
    from .registry_lines import RegistryLines

    folder = Path(args.folder)
    lines = RegistryLines(args.registry)
    if args.listening_fd is not None:
        # A command's own folder, served for it (serving_while_it_runs): the
        # folder may not exist yet, and the command prints the address.
        from .server import LiveServer

        listening = socket.socket(fileno=args.listening_fd)
        LiveServer(FolderState(folder, lines), listening).serve_here(while_parent=args.for_pid)
        return 0
    address = parse_address(args.address)
    with as_usage_error(WatchError):
        kind = folder_kind(folder)
    listening = bind(address)
    from .server import LiveServer

    server = LiveServer(FolderState(folder, lines), listening)
    print(
        f"live view of the {kind} {folder}: {address.url(listening.getsockname()[1])} (read-only; Ctrl-C stops)",
        flush=True,
    )
    server.serve_here()
    return 0


@contextmanager
def serving_while_it_runs(args: argparse.Namespace) -> Iterator[None]:
    """The live view of args.out served while the command runs, when args
    carry serve; nothing otherwise. The socket is bound here, so a port in
    use stops the command before it starts; a ``watch`` child process
    serves it, so the page costs the command's interpreter nothing."""
    text = getattr(args, "serve", None)
    if not text:
        yield
        return
    address = parse_address(text)
    with bind(address) as listening:
        command = [
            sys.executable,
            "-m",
            "thermotilt",
            "watch",
            str(args.out),
            "--listening-fd",
            str(listening.fileno()),
            "--for-pid",
            str(os.getpid()),
        ]
        if getattr(args, "registry", None):
            command += ["--registry", args.registry]
        # Its own session: Ctrl-C reaches the command, which stops the server.
        server = subprocess.Popen(command, pass_fds=[listening.fileno()], start_new_session=True)
        url = address.url(listening.getsockname()[1])
    try:
        print(f"live view: {url} (read-only, while this command runs)", flush=True)
        yield
    finally:
        server.terminate()
        try:
            server.wait(timeout=STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
