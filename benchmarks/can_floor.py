"""The least any asyncio client pays per CAN round trip on the same bus and node: one
request frame through :class:`AsyncCanBus`, one future resolved by the port's push receiver,
no protocol, no transaction rules. Printed beside the python-can raw figure so that a
reader sees which share of a gap is asyncio's and which is the client's."""

from __future__ import annotations

import asyncio
import time

from servobus.transport.can_bus import AsyncCanBus, CanFrame


async def floor_round_trips(channel: str, ident: int, data: bytes, n: int) -> float:
    """Round trips/s on python-can virtual bus ``channel`` (any reply frame completes one)."""
    port = await AsyncCanBus.open(f"virtual:{channel}")
    loop = asyncio.get_running_loop()
    waiter: list[asyncio.Future[None]] = []

    def received(frame: CanFrame | None) -> None:
        if waiter and not waiter[0].done():
            waiter[0].set_result(None)

    port.set_receiver(received)

    async def one() -> None:
        waiter[:] = [loop.create_future()]
        await port.send(ident, data)
        await asyncio.wait_for(waiter[0], 1.0)

    try:
        for _ in range(50):
            await one()
        t = time.perf_counter()
        for _ in range(n):
            await one()
        return n / (time.perf_counter() - t)
    finally:
        await port.close()
