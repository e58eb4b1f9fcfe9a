"""Test rig (not a test module): virtual DYN5 adapters on this event loop and a servobus
EnipAxis connected to one of them, for ``async def`` tests (tests/conftest.py runs them)."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from servobus.axis import connect_async
from servobus.protocols.enip.axis import EnipAxis
from servobus.protocols.enip.server import EnipFleet, start_fleet

DOWNTIME_S = 0.3  # the adapters' silence after a Reset (3 s on the drive)


def url_of(fleet: EnipFleet, index: int = 0) -> str:
    server = fleet.servers[index]
    return f"enip://{server.host}:{server.tcp_port}"


@asynccontextmanager
async def adapters(hosts: str = "127.0.0.1", **kw: Any) -> AsyncIterator[EnipFleet]:
    fleet = await start_fleet(hosts, 0, 0, reset_downtime_s=kw.pop("downtime", DOWNTIME_S),
                              **kw)
    try:
        yield fleet
    finally:
        await fleet.stop()


@asynccontextmanager
async def rig(hosts: str = "127.0.0.1", **options: Any) -> AsyncIterator[tuple[EnipFleet,
                                                                               EnipAxis]]:
    """Adapters on ``hosts`` and an axis on the first one (``options`` go to connect)."""
    async with adapters(hosts) as fleet:
        axis = await connect_async(url_of(fleet), **{"timeout": 0.3, **options})
        assert isinstance(axis, EnipAxis)
        try:
            yield fleet, axis
        finally:
            await axis.close()
