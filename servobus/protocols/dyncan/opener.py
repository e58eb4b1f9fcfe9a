"""Open a DYN CAN Axis from ``dyncan+<interface>://<channel>`` (docs/dyncan.md).

The part after ``+`` is a python-can interface name; the channel follows ``//``. For
socketcand the channel is ``host:port[/can0]``. ``?bitrate=`` goes to python-can where the
interface takes one; the client's own options (``timeout``, ``retries``, ...) too.
"""

from __future__ import annotations

from typing import Any

from servobus.axis.url import DriveUrl, can_spec, merge_options
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan.axis import DynCanAxis
from servobus.protocols.dyncan.client import open_can_client
from servobus.protocols.dyncan.commands import check_drive_id

OPTIONS: dict[str, type] = {
    "bitrate": int, "timeout": float, "retries": int, "eeprom_guard": object, "late_reply_s": float,
    "on_alarm": object,
}


async def open_axis(url: DriveUrl, *, drive_id: int | None = None, **keywords: Any) -> DynCanAxis:
    options = merge_options(url, keywords, OPTIONS)
    drive_id = c.MIN_DRIVE_ID if drive_id is None else check_drive_id(drive_id,
                                                                    allow_broadcast=False)
    spec, extra = can_spec(url)
    client = await open_can_client(spec, **extra, **options)  # type: ignore[arg-type]
    return DynCanAxis(client, drive_id)
