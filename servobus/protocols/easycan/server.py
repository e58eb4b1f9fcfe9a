"""Serve a virtual EasyCan network of YZ-AIM motors on a CAN port (python-can bus, the
socketcand hub's in-process port), each frame judged by when it reached the bus."""

from __future__ import annotations

import asyncio
import time

from servobus.protocols.easycan.device import EasyCanNetwork
from servobus.sim.can_requests import requests
from servobus.sim.wall_clock import RealtimeClock
from servobus.transport.can_bus import CanFrame, FramePort


def arrival(frame: CanFrame) -> float:
    """The monotonic instant a frame reached the bus: the medium's own stamp (the socketcand
    hub's, one per TCP read), else from its wall-clock timestamp (python-can stamps frames
    on arrival; the node may handle them later)."""
    if frame.arrived is not None:
        return frame.arrived
    now = time.monotonic()
    if frame.timestamp <= 0:
        return now
    return min(now, now - (time.time() - frame.timestamp))


async def serve(network: EasyCanNetwork, port: FramePort, *,
                clock: RealtimeClock | None = None,
                stop: asyncio.Event | None = None) -> None:
    """Answer host frames on ``port`` until ``stop`` is set or the port closes.

    With a ``clock`` the motors run in wall-clock time (the addressed one advanced before
    each frame, all of them by the clock's ticker); without one the caller steps them.
    """
    stop = stop or asyncio.Event()
    if clock is not None:
        clock.start()
    try:
        async for raw in requests(port, stop):
            now = None if clock is None else clock.sim_time(arrival(raw))
            # the hub's stamp is one per TCP read: frames sharing it came together
            for arbitration_id, data in network.handle_raw(raw.arbitration_id, raw.data, now,
                                                           raw.arrived):
                await port.send(arbitration_id, data)
    finally:
        if clock is not None:
            await clock.stop()
