"""Run the GUI: open the drives, serve the app with uvicorn, print the address, open a browser.

Decisions: the server binds 127.0.0.1 unless told otherwise; on any other address a token
is required (a generated one when none is given, printed in the URL) and a warning says
that whoever reaches the address with the token can move the drives. The drives are opened
before the server starts, so a drive that cannot be opened is one error line (exit 2), not
a server without axes. On exit (Ctrl-C, SIGTERM) every axis is stopped before the
connection closes (servobus.gui.state.GuiState.shut_down).
"""

from __future__ import annotations

import asyncio
import contextlib
import secrets
import signal
import socket
import threading
import webbrowser
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from types import FrameType

import uvicorn
from starlette.applications import Starlette as ASGIApplication

from servobus.errors import ArgumentRangeError
from servobus.gui.app import create_app
from servobus.gui.fleet import DEFAULT_URL, Fleet
from servobus.gui.limits import UVICORN_LIMITS
from servobus.gui.state import GuiState
from servobus.transport.address import is_loopback

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8080


@dataclass(frozen=True)
class ServeOptions:
    url: str | None
    ids: Sequence[int] | None
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    token: str | None = None
    open_browser: bool = True
    machine: str | None = None  # a machine file (servobus.machine)

    @property
    def on_machine(self) -> bool:
        """A machine file, or nothing named at all: the built-in virtual machine."""
        return self.machine is not None or (self.url is None and self.ids is None)


def page_url(host: str, port: int, token: str | None) -> str:
    shown = DEFAULT_HOST if host in ("0.0.0.0", "::", "") else host
    if ":" in shown and not shown.startswith("["):
        shown = f"[{shown}]"
    return f"http://{shown}:{port}/" + (f"?token={token}" if token else "")


def bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host.strip("[]"), port))
    except OSError as exc:
        sock.close()
        raise OSError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    sock.listen(128)
    sock.set_inheritable(True)
    return sock


@dataclass
class ServeOutcome:
    """How the server ended: the signal that stopped it and the stop of every axis."""

    signal: str | None = None  # "Ctrl-C", "SIGTERM"; None: the server ended by itself
    halted: dict[int, BaseException | None] | None = None  # GuiState.halted


def uvicorn_config(app: ASGIApplication) -> uvicorn.Config:
    """How the GUI app is served (also by tests and benchmarks): quiet, bounded inputs."""
    return uvicorn.Config(app, log_level="warning", lifespan="on", access_log=False,
                          ws_per_message_deflate=False,  # scope frames do not compress
                          **UVICORN_LIMITS)  # type: ignore[arg-type]


def serve(options: ServeOptions, say: Callable[[str], None]) -> ServeOutcome:
    """Serve until interrupted (Ctrl-C, SIGTERM); every axis is stopped before it returns.

    Decision: an interrupt is how a server is meant to end, so it is an outcome here (the
    command exits 0 on it), not an error; a stop that failed is in ``halted``.
    """
    token = options.token
    loopback = is_loopback(options.host)
    if token is not None and not token.strip():
        raise ArgumentRangeError("--token must not be empty")
    if not loopback and token is None:
        token = secrets.token_urlsafe(18)
    sock = bind(options.host, options.port)
    outcome = ServeOutcome()
    try:
        asyncio.run(_serve(options, token, loopback, sock, say, outcome))
    except KeyboardInterrupt as exc:  # before the server listened (opening the drives)
        outcome.signal = getattr(exc, "signal_name", "Ctrl-C")
    finally:
        sock.close()
    return outcome


class _Server(uvicorn.Server):
    """uvicorn's server, except that Ctrl-C and SIGTERM are not raised again once it has
    shut down: the GUI reports them as its outcome. (uvicorn re-raises them; under
    asyncio.run a second Ctrl-C then cancels the shutdown half-way and logs tracebacks.)"""

    def __init__(self, config: uvicorn.Config) -> None:
        super().__init__(config)
        self.signals: list[int] = []

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        handled = (signal.SIGINT, signal.SIGTERM)
        original = {sig: signal.signal(sig, self._on_signal) for sig in handled}
        try:
            yield
        finally:
            for sig, handler in original.items():
                signal.signal(sig, handler)

    def _on_signal(self, sig: int, frame: FrameType | None) -> None:
        self.signals.append(sig)
        self.handle_exit(sig, frame)


async def _serve(options: ServeOptions, token: str | None, loopback: bool,
                 sock: socket.socket, say: Callable[[str], None], outcome: ServeOutcome) -> None:
    if options.on_machine:
        fleet = await Fleet.open_machine(options.machine)
    else:
        fleet = await Fleet.open(options.url, options.ids)
    app = create_app(fleet=fleet, token=token)
    server = _Server(uvicorn_config(app))
    port = sock.getsockname()[1]
    url = page_url(options.host, port, token)

    async def announce() -> None:
        while not server.started:
            if server.should_exit:
                return
            await asyncio.sleep(0.02)
        axes = ", ".join(str(i) for i in fleet.handles)
        if fleet.machine_file:
            axes = ", ".join(f"{i} {h.machine_axis.name}" for i, h in fleet.handles.items()
                             if h.machine_axis is not None)
        if not loopback:
            say(f"warning: listening on {options.host}: anyone who can reach this address "
                "and has the token can move the drives")
        say(f"servobus gui: {url}")
        if fleet.machine is not None and fleet.machine_file:
            offline = [h.machine_axis.name for h in fleet.handles.values()
                       if h.machine_axis is not None and not h.machine_axis.online]
            say(f"drives: machine {fleet.machine.name} ({fleet.url}); axes {axes}"
                + (f"; offline, retrying: {', '.join(offline)}" if offline else "")
                + ". Ctrl-C stops every axis and the server.")
        else:
            drives = fleet.url if options.url else f"{DEFAULT_URL} (built-in virtual drives)"
            say(f"drives: {drives}; axes {axes}. Ctrl-C stops every axis and the server.")
        if options.open_browser:
            await asyncio.get_running_loop().run_in_executor(None, webbrowser.open, url)

    task = asyncio.create_task(announce())
    try:
        await server.serve(sockets=[sock])
    finally:
        task.cancel()
        if server.signals:
            outcome.signal = "Ctrl-C" if server.signals[0] == signal.SIGINT else "SIGTERM"
        gui: GuiState | None = getattr(app.state, "gui", None)
        if gui is not None:
            if not gui.closed:  # a second Ctrl-C: uvicorn skipped the app's shutdown
                await server.lifespan.shutdown()
            await gui.shut_down()  # done by the app's shutdown; here if even that failed
            outcome.halted = gui.halted
        else:
            await fleet.close()
