"""Open an EasyCan Axis from ``easycan+<interface>://<channel>`` (docs/easycan.md).

The part after ``+`` is a python-can interface name; the channel follows ``//``. For
socketcand the channel is ``host:port[/can0]``. ``?bitrate=`` goes to python-can where the
interface takes one (EasyCan runs at 1 Mbit/s, manual 1); the client's own options
(``timeout``, ``retries``, ``late_reply_s``; ``eeprom_guard=`` as a keyword) too. Without
an id the motor at address 1.
Decision: over socketcand the client asks python-can for ``tcp_tune`` (TCP_NODELAY and
QUICKACK) unless ``?tcp_tune=0``: without it Nagle's algorithm holds small frames back and
sends them in bursts, which the 2 ms position cache cannot take (two values in one cycle).
"""

from __future__ import annotations

from typing import Any

from servobus.axis.url import DriveUrl, can_spec, merge_options
from servobus.protocols.easycan import commands as cmds
from servobus.protocols.easycan.axis import EasyCanAxis
from servobus.protocols.easycan.client import open_easycan_client

FACTORY_ADDRESS = 1
OPTIONS: dict[str, type] = {
    "bitrate": int, "timeout": float, "retries": int, "late_reply_s": float, "tcp_tune": bool,
    "eeprom_guard": object,
}


async def open_axis(url: DriveUrl, *, drive_id: int | None = None,
                    **keywords: Any) -> EasyCanAxis:
    options = merge_options(url, keywords, OPTIONS)
    address = FACTORY_ADDRESS if drive_id is None else cmds.check_address(drive_id)
    spec, extra = can_spec(url)
    if url.transport == "socketcand":
        options.setdefault("tcp_tune", True)
    client = await open_easycan_client(spec, **extra, **options)  # type: ignore[arg-type]
    return EasyCanAxis(client, address)
