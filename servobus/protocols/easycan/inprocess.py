"""``sim://easycan``: virtual YZ-AIM motors on an in-process python-can virtual bus.

Each URL opened gets its own virtual channel, so two in-process buses never meet. Options:
``ids`` (motor addresses 1..254; default: the one asked for, else 1), ``fast=1`` (no
1 Mbit/s bit-timing model), ``state=FILE`` (saved registers and positions), ``model=NAME``
(a YZ-AIM model of the manual's tables, default 57AIM30C), plus the client's ``timeout``,
``retries``, ``late_reply_s`` and ``eeprom_guard``. The motors come set up for
communication control (gear numerator 0 saved, so modbus_enable is 1 at power-on:
servobus.sim.yzaim.motor).
"""

from __future__ import annotations

import asyncio
import itertools
from typing import Any

from servobus.axis.url import DriveUrl, merge_options
from servobus.families.yzaim import registers as yzaim
from servobus.protocols.easycan import commands as cmds
from servobus.protocols.easycan.axis import EasyCanAxis
from servobus.protocols.easycan.client import open_easycan_client
from servobus.protocols.easycan.device import EasyCanNetwork
from servobus.protocols.easycan.functions import BITRATE
from servobus.protocols.easycan.server import serve
from servobus.sim.wall_clock import RealtimeClock
from servobus.sim.yzaim.fleet import FACTORY_ADDRESS, make_motors, parse_addresses
from servobus.transport.can_bus import AsyncCanBus, BitTiming

SIM_OPTIONS: dict[str, type] = {
    "ids": str, "fast": bool, "state": str, "model": str, "timeout": float, "retries": int,
    "late_reply_s": float, "eeprom_guard": object,
}
_channels = itertools.count()


async def open_sim_network(network: EasyCanNetwork, address: int, *, fast: bool = False,
                           **client_options: Any) -> EasyCanAxis:
    """Serve ``network`` on a fresh virtual channel; the axis of ``address`` owns it all."""
    spec = f"virtual:servobus-sim-easycan-{next(_channels)}"
    node_port = await AsyncCanBus.open(spec, timing=None if fast else BitTiming(BITRATE))
    stop = asyncio.Event()
    task = asyncio.create_task(serve(network, node_port, clock=RealtimeClock(network.motors),
                                     stop=stop))

    async def shut_down() -> None:
        stop.set()
        await task
        await node_port.close()

    try:
        client = await open_easycan_client(spec, **client_options)
    except BaseException:
        await shut_down()
        raise
    axis = EasyCanAxis(client, address)
    axis.on_close(shut_down)
    return axis


async def open_sim_axis(url: DriveUrl, *, drive_id: int | None = None,
                        **keywords: object) -> EasyCanAxis:
    options = merge_options(url, dict(keywords), SIM_OPTIONS)
    if drive_id is not None:
        cmds.check_address(drive_id)
    ids_text = options.pop("ids", None)
    ids = (parse_addresses(str(ids_text)) if ids_text is not None
           else (FACTORY_ADDRESS if drive_id is None else drive_id,))
    state = options.pop("state", None)
    motors = make_motors(ids, state=str(state) if state else None,
                         model=str(options.pop("model", yzaim.DEFAULT_MODEL)))
    fast = bool(options.pop("fast", False))
    return await open_sim_network(EasyCanNetwork(motors), ids[0] if drive_id is None
                                  else drive_id, fast=fast, **options)
