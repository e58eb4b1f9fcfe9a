"""Serve a virtual DYN CAN network on a CAN port (python-can bus, the socketcand hub's
in-process port): host frames in, the drives' replies and alarm pushes out."""

from __future__ import annotations

import asyncio
import contextlib

from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan.device import DynCanNetwork
from servobus.sim.can_requests import requests
from servobus.sim.wall_clock import RealtimeClock
from servobus.transport.can_bus import FramePort


async def serve(network: DynCanNetwork, port: FramePort, *,
                clock: RealtimeClock | None = None,
                stop: asyncio.Event | None = None) -> None:
    """Answer host frames on ``port`` until ``stop`` is set or the port closes.

    With a ``clock`` the drives run in wall-clock time (advanced before each frame and by
    the clock's ticker); without one the caller steps them (tests). Alarm pushes queued by
    the drives are sent as soon as they appear (checked after every frame and tick).
    """
    stop = stop or asyncio.Event()
    if clock is not None:
        clock.start()

    async def pump_outbox() -> None:
        while not stop.is_set():
            for frame in network.take_outbox():
                await port.send(*c.encode(frame))
            await asyncio.sleep(clock.tick_s if clock is not None else 0.005)

    pusher = asyncio.get_running_loop().create_task(pump_outbox())
    try:
        async for raw in requests(port, stop):
            if clock is not None:
                clock.sync()
            for frame in network.handle_raw(raw.arbitration_id, raw.data):
                await port.send(*c.encode(frame))
            for frame in network.take_outbox():  # an alarm tripped while catching up
                await port.send(*c.encode(frame))
    finally:
        pusher.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await pusher
        if clock is not None:
            await clock.stop()
