"""The GUI's ASGI application: static page, REST API, WebSocket, behind the Guard.

``create_app(url, ids, token=...)`` opens the drives when the server starts (lifespan) and,
when it stops, stops every axis and closes the connection. Every request runs in its own
error boundary (servobus.gui.boundary) and passes the Guard (servobus.gui.auth), the body
limit (servobus.gui.limits) and the fair limits per page (servobus.gui.fair), in that
order.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Sequence
from pathlib import Path

from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import FileResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles

from servobus.gui import api_autotune, api_axes, api_io, api_params, ws
from servobus.gui.auth import Guard
from servobus.gui.boundary import ErrorBoundary
from servobus.gui.fair import RequestCaps
from servobus.gui.fleet import Fleet
from servobus.gui.jog import LEASE_S
from servobus.gui.limits import BodyLimit
from servobus.gui.state import GuiState

STATIC = Path(__file__).parent / "static"


async def index(request: Request) -> Response:
    return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})


async def favicon(request: Request) -> Response:
    """The page names /static/favicon.svg; a browser that asks /favicon.ico gets it too."""
    return FileResponse(STATIC / "favicon.svg", media_type="image/svg+xml",
                        headers={"Cache-Control": "max-age=86400"})


def create_app(url: str | None = None, ids: Sequence[int] | None = None, *,
               fleet: Fleet | None = None, token: str | None = None,
               jog_lease_s: float = LEASE_S, machine: str | Path | None = None) -> Starlette:
    """The app; it opens ``url`` or the ``machine`` file (or takes an opened ``fleet``) when
    the server starts."""

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        if fleet is not None:
            opened = fleet
        elif machine is not None:
            opened = await Fleet.open_machine(machine)
        else:
            opened = await Fleet.open(url, ids)
        gui = GuiState.build(opened, jog_lease_s)
        app.state.gui = gui
        gui.start()
        try:
            yield
        finally:
            await gui.shut_down()

    app = Starlette(routes=[
        Route("/", index),
        Route("/favicon.ico", favicon),
        *api_axes.ROUTES,
        *api_params.ROUTES,
        *api_autotune.ROUTES,
        *api_io.ROUTES,
        WebSocketRoute("/ws", ws.endpoint),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ], lifespan=lifespan, middleware=[Middleware(ErrorBoundary), Middleware(Guard, token=token),
                                      Middleware(BodyLimit), Middleware(RequestCaps)])
    return app
