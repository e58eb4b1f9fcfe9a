"""Test rig (not a test module): a DYN CAN client and virtual nodes on python-can's virtual bus.

Each harness gets its own virtual channel; the nodes run ``servobus.protocols.dyncan.server.serve``
on the loop, in stepped time unless ``realtime=True``.
"""

from __future__ import annotations

import asyncio
import itertools
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass

from servobus.protocols.dyncan.axis import DynCanAxis
from servobus.protocols.dyncan.client import AsyncDynCanClient, open_can_client
from servobus.protocols.dyncan.device import DynCanNetwork
from servobus.protocols.dyncan.server import serve
from servobus.sim.dmm.drive import VirtualDrive
from servobus.sim.wall_clock import RealtimeClock
from servobus.transport.can_bus import AsyncCanBus

_channels = itertools.count()


@dataclass
class Harness:
    network: DynCanNetwork
    client: AsyncDynCanClient
    spec: str

    def axis(self, drive_id: int) -> DynCanAxis:
        return DynCanAxis(self.client, drive_id, owns_client=False)


@asynccontextmanager
async def harness(*ids: int, realtime: bool = False, **client_kw: object
                  ) -> AsyncIterator[Harness]:
    spec = f"virtual:servobus-dyncan-test-{next(_channels)}"
    network = DynCanNetwork([VirtualDrive(i) for i in ids])
    node_port = await AsyncCanBus.open(spec)
    clock = RealtimeClock(network.drives) if realtime else None
    stop = asyncio.Event()
    server = asyncio.create_task(serve(network, node_port, clock=clock, stop=stop))
    client = await open_can_client(spec, **client_kw)  # type: ignore[arg-type]
    try:
        yield Harness(network, client, spec)
    finally:
        await client.close()
        stop.set()
        await server
        await node_port.close()
