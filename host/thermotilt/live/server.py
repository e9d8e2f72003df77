"""The live view's web server: a Starlette app that answers GET only —
``/`` the page, ``/static/...`` its script, style and the vendored uPlot,
``/api/state`` the folder's whole view as JSON, ``/api/events`` Server-Sent
Events, a first one with the whole view and then, about every PUSH_EVERY_S,
what changed — served by uvicorn on a socket bound before anything runs. ``watch``
serves in its main thread; ``campaign --serve`` binds the socket and hands
it to a ``watch`` child process, so the page never takes the campaign's
interpreter from the twin.
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import threading
from collections.abc import AsyncIterator
from pathlib import Path
from types import FrameType

import uvicorn
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, Response, StreamingResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from .folder_state import Cursors, FolderState

STATIC = Path(__file__).resolve().parent / "static"
PUSH_EVERY_S = 0.5
STOP_CHECK_S = 0.05
# How long the server waits for open event streams when it stops.
GRACEFUL_STOP_S = 1


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


class _Server(uvicorn.Server):
    """uvicorn's server whose Ctrl-C or SIGTERM ends the open event streams
    first, so its graceful stop does not wait GRACEFUL_STOP_S for them."""

    def __init__(self, config: uvicorn.Config, stopping: threading.Event) -> None:
        super().__init__(config)
        self.stopping = stopping

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        self.stopping.set()
        super().handle_exit(sig, frame)


class LiveServer:
    """uvicorn serving the live view of state on a listening socket."""

    def __init__(self, state: FolderState, listening: socket.socket) -> None:
        self.state = state
        self.stopping = threading.Event()
        self.socket = listening
        config = uvicorn.Config(
            create_app(state, stopping=self.stopping),
            log_level="warning",
            access_log=False,
            lifespan="off",
            timeout_graceful_shutdown=GRACEFUL_STOP_S,
        )
        self._server = _Server(config, self.stopping)

    def serve_here(self, while_parent: int | None = None) -> None:
        """Serves until Ctrl-C or SIGTERM (uvicorn's own signal handling),
        or, given while_parent, until that process is no longer this one's
        parent: a campaign killed outright leaves no server behind."""
        self._start_reading(while_parent)
        try:
            self._server.run(sockets=[self.socket])
        finally:
            self.stopping.set()
            self.socket.close()

    def _start_reading(self, while_parent: int | None) -> None:
        """The folder read every PUSH_EVERY_S whether a page is open or not,
        so that a fault in a position that ends before anyone looks is seen."""

        def read() -> None:
            while not self.stopping.wait(PUSH_EVERY_S):
                if while_parent is not None and os.getppid() != while_parent:
                    self.stopping.set()
                    self._server.should_exit = True
                    return
                self.state.refresh()

        self.state.refresh()
        threading.Thread(target=read, name="thermotilt-live-reader", daemon=True).start()
