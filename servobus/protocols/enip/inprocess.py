"""``sim://enip``: virtual DYN5 adapters in this process, on loopback addresses.

Each drive id is the last byte of its address, as on a DYN5 daisy chain (docs/enip.md):
``sim://enip`` serves one adapter on 127.0.0.<id asked for, else 1>, ``ids=1,2,3`` serves
127.0.0.1 .. 127.0.0.3 (other loopback addresses than 127.0.0.1 need Linux). Every adapter
listens on the same free TCP port (picked by the system) and its own free UDP I/O port, so
nothing collides with a real 44818 or 2222. The adapters run on the caller's event loop
and stop when the axis closes. Options: ``ids``, ``state=FILE``, ``model=NAME``,
``reset_downtime_s`` (the Reset silence, default 3 s as on the drive), ``fast`` (accepted
for every sim://; EtherNet/IP has no wire pacing to remove), and the client's options.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from servobus import checks
from servobus.axis.url import DriveUrl, merge_options
from servobus.errors import ArgumentRangeError
from servobus.families.dmm import units as U
from servobus.families.dyn5 import params as dyn5
from servobus.protocols.enip.axis import DRIVE_IDS, EnipAxis, with_last_octet
from servobus.protocols.enip.client import AsyncEnipClient
from servobus.protocols.enip.opener import OPTIONS, axis_options
from servobus.protocols.enip.server import start_fleet
from servobus.sim.core.ids import parse_ids

if TYPE_CHECKING:
    from servobus.axis.base import AsyncAxis

LOOPBACK = "127.0.0.1"
SIM_OPTIONS: dict[str, type] = {
    "ids": str, "fast": bool, "state": str, "model": str, "reset_downtime_s": float, **OPTIONS,
}


async def open_sim_axis(url: DriveUrl, *, drive_id: int | None = None,
                        **keywords: Any) -> AsyncAxis:
    options = merge_options(url, dict(keywords), SIM_OPTIONS)
    if drive_id is not None:
        with_last_octet(LOOPBACK, drive_id)
    ids_text = options.pop("ids", None)
    first, last = DRIVE_IDS.start, DRIVE_IDS.stop - 1
    ids = (parse_ids(str(ids_text), min_id=first, max_id=last) if ids_text is not None
           else (first if drive_id is None else drive_id,))
    model = str(options.pop("model", U.DEFAULT_MODEL))
    if model not in U.MODELS:
        raise ArgumentRangeError(f"unknown model {model!r}; known: {', '.join(U.MODELS)}")
    state = options.pop("state", None)
    downtime = checks.non_negative_seconds(
        "reset_downtime_s", options.pop("reset_downtime_s", dyn5.RESET_DOWNTIME_S))
    options.pop("fast", None)
    checked = axis_options(options, 1)
    fleet = await start_fleet([with_last_octet(LOOPBACK, i) for i in ids], 0, 0,
                              str(state) if state else None, model=model,
                              reset_downtime_s=downtime)
    try:
        port = fleet.servers[0].tcp_port
        checked = axis_options(options, port)
        wanted = ids[0] if drive_id is None else drive_id
        ip = with_last_octet(LOOPBACK, wanted)
        client = None
        if wanted in ids:
            client = await AsyncEnipClient.connect(ip, port, timeout=checked.timeout,
                                                   retries=checked.retries,
                                                   connect_timeout=checked.connect_timeout,
                                                   max_in_flight=checked.max_in_flight)
    except BaseException:
        await fleet.stop()
        raise
    axis = EnipAxis(client, ip, checked)
    axis.on_close(fleet.stop)
    return axis
