"""``sim://dyncan``: virtual DYN CAN nodes on an in-process python-can virtual bus.

Each URL opened gets its own virtual channel, so two in-process buses never meet. Options:
``ids`` (default: the id asked for, else 1), ``fast=1`` (no 1 Mbit/s bit-timing model),
``state=FILE``, ``model=NAME``, plus the client's ``timeout`` and ``retries``.
"""

from __future__ import annotations

import asyncio
import itertools
from typing import TYPE_CHECKING

from servobus.axis.url import DriveUrl, merge_options
from servobus.errors import ArgumentRangeError
from servobus.families.dmm import units as U
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan.axis import DynCanAxis
from servobus.protocols.dyncan.client import open_can_client
from servobus.protocols.dyncan.commands import check_drive_id
from servobus.protocols.dyncan.device import DynCanNetwork
from servobus.protocols.dyncan.server import serve
from servobus.sim.core.ids import parse_ids
from servobus.sim.dmm.fleet import make_drives
from servobus.sim.wall_clock import RealtimeClock
from servobus.transport.can_bus import AsyncCanBus, BitTiming

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis

SIM_OPTIONS: dict[str, type] = {
    "ids": str, "fast": bool, "state": str, "model": str, "timeout": float, "retries": int,
    "eeprom_guard": object, "late_reply_s": float, "on_alarm": object,
}
_channels = itertools.count()


async def open_sim_axis(url: DriveUrl, *, drive_id: int | None = None,
                        **keywords: object) -> AsyncAxis:
    options = merge_options(url, dict(keywords), SIM_OPTIONS)
    if drive_id is not None:
        check_drive_id(drive_id)
    ids_text = options.pop("ids", None)
    ids = (parse_ids(str(ids_text), min_id=c.MIN_DRIVE_ID, max_id=c.MAX_DRIVE_ID)
           if ids_text is not None else (c.MIN_DRIVE_ID if drive_id is None else drive_id,))
    model = str(options.pop("model", U.DEFAULT_MODEL))
    if model not in U.MODELS:
        raise ArgumentRangeError(f"unknown model {model!r}; known: {', '.join(U.MODELS)}")
    state = options.pop("state", None)
    fast = bool(options.pop("fast", False))
    network = DynCanNetwork(make_drives(ids, state=str(state) if state else None, model=model))
    spec = f"virtual:servobus-sim-dyncan-{next(_channels)}"
    node_port = await AsyncCanBus.open(spec, timing=None if fast else BitTiming(1_000_000))
    stop = asyncio.Event()
    task = asyncio.create_task(serve(network, node_port, clock=RealtimeClock(network.drives),
                                     stop=stop))
    try:
        client = await open_can_client(spec, **options)  # type: ignore[arg-type]
    except BaseException:
        stop.set()
        await task
        await node_port.close()
        raise
    axis = DynCanAxis(client, ids[0] if drive_id is None else drive_id)

    async def shut_down() -> None:
        stop.set()
        await task
        await node_port.close()

    axis.on_close(shut_down)
    return axis
