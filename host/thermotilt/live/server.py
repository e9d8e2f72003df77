"""The live view's web server: a Starlette app that answers GET only —
``/`` the page, ``/static/...`` its script, style and the vendored uPlot,
``/api/state`` the folder's whole view as JSON, ``/api/events`` Server-Sent
Events, a first one with the whole view and then, about every PUSH_EVERY_S,
what changed — served by uvicorn on a socket bound before anything runs,
in this thread (``watch``) or in a background thread (``campaign --serve``).
"""

from __future__ import annotations

import asyncio
import errno
import json
import socket
import threading
import time
from collections.abc import AsyncIterator
from pathlib import Path

import uvicorn
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, Response, StreamingResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from ..options import UsageError
from .address import Address
from .folder_state import Cursors, FolderState

STATIC = Path(__file__).resolve().parent / "static"
PUSH_EVERY_S = 0.5
STOP_CHECK_S = 0.05
# How long the server waits for open event streams when it stops.
GRACEFUL_STOP_S = 1
STARTUP_TIMEOUT_S = 10.0


def _dumps(document: object) -> str:
    # The tail turns NaN and infinities into gaps, so the JSON is strict.
    return json.dumps(document, separators=(",", ":"), allow_nan=False)


def create_app(
    state: FolderState, push_every_s: float = PUSH_EVERY_S, stopping: threading.Event | None = None
) -> Starlette:
    """The app over state; event streams end when stopping is set."""
    stopping = stopping or threading.Event()

    async def page(_request: Request) -> Response:
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def api_state(_request: Request) -> Response:
        await run_in_threadpool(state.refresh)
        document, _cursors = await run_in_threadpool(state.snapshot)
        return Response(_dumps(document), media_type="application/json", headers={"Cache-Control": "no-store"})

    async def events(_request: Request) -> Response:
        return StreamingResponse(
            _event_stream(state, push_every_s, stopping),
            media_type="text/event-stream",
            headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
        )

    return Starlette(
        routes=[
            Route("/", page),
            Route("/api/state", api_state),
            Route("/api/events", events),
            Mount("/static", StaticFiles(directory=STATIC), name="static"),
        ]
    )


async def _event_stream(state: FolderState, push_every_s: float, stopping: threading.Event) -> AsyncIterator[str]:
    """The whole view first, then each push what this reader lacks."""
    cursors: Cursors = {}
    while not stopping.is_set():
        await run_in_threadpool(state.refresh)
        document, cursors = await run_in_threadpool(state.snapshot, cursors)
        yield f"data: {_dumps(document)}\n\n"
        # Starlette ends the stream when the reader leaves. The wait looks at
        # stopping every STOP_CHECK_S, so a command that ends is not held up
        # by an open page; reading the folder more often would take the GIL
        # from a campaign in this process more often.
        waited = 0.0
        while waited < push_every_s and not stopping.is_set():
            await asyncio.sleep(STOP_CHECK_S)
            waited += STOP_CHECK_S


def bind(address: Address) -> socket.socket:
    """A listening socket at address; UsageError, one line, for a port in
    use, a host this machine is not, or a name that does not resolve."""
    family = socket.AF_INET6 if ":" in address.host else socket.AF_INET
    try:
        return socket.create_server((address.host, address.port), family=family)
    except OSError as error:
        if error.errno == errno.EADDRINUSE:
            why = "the port is in use (give another with --serve [HOST:]PORT)"
        else:
            why = error.strerror or str(error)
        raise UsageError(f"cannot serve the live view on {address.host}:{address.port}: {why}") from None


class LiveServer:
    """uvicorn serving the live view of state at address; the socket is
    bound on construction, so a port in use is known before a campaign starts."""

    def __init__(self, state: FolderState, address: Address) -> None:
        self.state = state
        self.stopping = threading.Event()
        self.socket = bind(address)
        self.url = address.url(self.socket.getsockname()[1])
        config = uvicorn.Config(
            create_app(state, stopping=self.stopping),
            log_level="warning",
            access_log=False,
            lifespan="off",
            timeout_graceful_shutdown=GRACEFUL_STOP_S,
        )
        self._server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None

    def serve_here(self) -> None:
        """Serves until Ctrl-C (uvicorn's own signal handling, then
        KeyboardInterrupt as from any command)."""
        self._start_reading()
        try:
            self._server.run(sockets=[self.socket])
        finally:
            self.stopping.set()
            self.socket.close()

    def _start_reading(self) -> None:
        """The folder read every PUSH_EVERY_S whether a page is open or not,
        so that a fault in a position that ends before anyone looks is seen."""

        def read() -> None:
            while not self.stopping.wait(PUSH_EVERY_S):
                self.state.refresh()

        self.state.refresh()
        threading.Thread(target=read, name="thermotilt-live-reader", daemon=True).start()

    def start_in_background(self) -> None:
        self._start_reading()
        self._thread = threading.Thread(
            target=self._server.run, kwargs={"sockets": [self.socket]}, name="thermotilt-live", daemon=True
        )
        self._thread.start()
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        while not self._server.started and self._thread.is_alive() and time.monotonic() < deadline:
            time.sleep(0.01)

    def stop(self) -> None:
        self.stopping.set()
        self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(timeout=GRACEFUL_STOP_S + 5)
        self.socket.close()
