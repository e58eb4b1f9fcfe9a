"""Open a DYN CAN Axis from ``dyncan+<interface>://<channel>`` (docs/dyncan.md).

The part after ``+`` is a python-can interface name; the channel follows ``//``. For
socketcand the channel is ``host:port[/can0]``. ``?bitrate=`` goes to python-can where the
interface takes one; the client's own options (``timeout``, ``retries``, ...) too.
"""

from __future__ import annotations

from typing import Any

from servobus.axis.url import DriveUrl, merge_options
from servobus.errors import ArgumentRangeError
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan.client import DynCanAxis, open_can_client
from servobus.protocols.dyncan.commands import check_drive_id

OPTIONS: dict[str, type] = {
    "bitrate": int, "timeout": float, "retries": int, "eeprom_guard": object, "late_reply_s": float,
    "on_alarm": object,
}


def can_spec(url: DriveUrl) -> tuple[str, dict[str, str]]:
    """``INTERFACE:CHANNEL`` for python-can, and the socketcand bus name if the URL gives one."""
    if not url.transport:
        raise ArgumentRangeError(
            f"{url.raw!r} names no CAN interface: use dyncan+<interface>://<channel>, "
            "e.g. dyncan+pcan://PCAN_USBBUS1 or dyncan+socketcand://127.0.0.1:29536/can0")
    channel = url.target
    if url.transport == "socketcand" and "/" in channel:
        address, _, bus = channel.partition("/")
        return f"socketcand:{address}", ({"channel": bus} if bus else {})
    return f"{url.transport}:{channel}", {}


async def open_axis(url: DriveUrl, *, drive_id: int | None = None, **keywords: Any) -> DynCanAxis:
    options = merge_options(url, keywords, OPTIONS)
    drive_id = c.MIN_DRIVE_ID if drive_id is None else check_drive_id(drive_id,
                                                                    allow_broadcast=False)
    spec, extra = can_spec(url)
    client = await open_can_client(spec, **extra, **options)  # type: ignore[arg-type]
    return DynCanAxis(client, drive_id)
