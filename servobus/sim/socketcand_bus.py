"""The startup every ``servobus sim <CAN protocol>`` server shares (protocol-free): a
socketcand hub announced on stdout, the nodes' gated port on it, and a stop event set by
SIGINT/SIGTERM or after ``--duration``.

stdout gets exactly one line, flushed at once, so scripts and tests can read the port::

    listening on socketcand 127.0.0.1:40123

The banner (drive list, timing) goes to stderr after it.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import sys
from collections.abc import AsyncIterator
from dataclasses import dataclass

import click

from servobus.sim.server_limits import DEFAULT_MAX_CLIENTS
from servobus.sim.socketcand_hub import HubPort, SocketcandHub
from servobus.transport.can_bus import BitTiming


def stop_event(duration: float | None) -> asyncio.Event:
    """An event set by SIGINT/SIGTERM, or after ``duration`` seconds (None: never)."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    if duration is not None:
        loop.call_later(duration, stop.set)
    return stop


@dataclass(frozen=True)
class SocketcandBus:
    """A running hub, the port the virtual nodes use on it, and when to stop."""

    hub: SocketcandHub
    node_port: HubPort
    stop: asyncio.Event


@contextlib.asynccontextmanager
async def socketcand_bus(host: str, port: int, *, fast: bool, bitrate: int,
                         duration: float | None, max_clients: int = DEFAULT_MAX_CLIENTS,
                         banner: str | None = None) -> AsyncIterator[SocketcandBus]:
    """Start the hub, print where, open the nodes' port (bit-timed at ``bitrate`` unless
    ``fast``), yield; the hub is closed on the way out."""
    hub = SocketcandHub(host, port, lossless=fast, max_clients=max_clients)
    host, port = await hub.start()
    try:
        click.echo(f"listening on socketcand {host}:{port}")
        sys.stdout.flush()
        if banner is not None:
            click.echo(banner, err=True)
        node_port = hub.open_port(timing=None if fast else BitTiming(bitrate), gate=True)
        yield SocketcandBus(hub, node_port, stop_event(duration))
    finally:
        await hub.close()
