"""The receive side every virtual CAN network's server shares (DYN CAN, EasyCan)."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

from servobus.transport.can_bus import CanFrame, FramePort

POLL_S = 0.1  # how often a quiet port looks at ``stop``


async def requests(port: FramePort, stop: asyncio.Event) -> AsyncIterator[CanFrame]:
    """Every standard (11-bit) frame the host sends on ``port``, until ``stop`` is set or
    the port closes; extended frames are no request of these protocols and are skipped."""
    while not stop.is_set():
        try:
            raw = await port.recv(POLL_S)
        except ConnectionError:
            return
        if raw is None or raw.is_extended_id:
            continue
        yield raw
