"""Open a DYN232M Axis from a URL (registered in ``servobus.protocols.dyn232.SCHEMES``).

* ``socket://host:port`` / ``tcp://`` / ``dyn232+socket://`` -> asyncio TCP (TcpStream),
  faster than pyserial's socket handler; ``?transport=pyserial`` forces pyserial.
* anything else (``/dev/ttyUSB0``, ``COM3``, ``loop://``, ``rfc2217://``) -> pyserial.

Query pacing default (servobus decision, docs/dyn232.md): 0.02 s (50 queries/s) on serial
device ports, where a real drive is attached; off for loop:// and socket:// (simulators and
fast links). Pass ``query_interval_s=0.02`` for a real drive behind a serial-to-TCP bridge.
"""

from __future__ import annotations

from typing import Any

from servobus.axis.url import DriveUrl, merge_options
from servobus.errors import ArgumentRangeError
from servobus.link.opening import client_on
from servobus.protocols.dyn232 import codec as c
from servobus.protocols.dyn232.axis import Dyn232Axis
from servobus.protocols.dyn232.client import AsyncDyn232Client
from servobus.protocols.dyn232.commands import check_drive_id
from servobus.transport.base import ByteStream

HARDWARE_QUERY_INTERVAL_S = 0.02  # real drives may drop queries above ~50/s (docs/dyn232.md)
FAST_LINK_SCHEMES = ("loop", "socket", "tcp", "spy", "alt", "hwgrep")
OPTIONS: dict[str, type] = {
    "baud": int, "timeout": float, "retries": int, "turnaround_s": float,
    "query_interval_s": float, "transport": str, "eeprom_guard": object, "late_reply_s": float,
}


def pyserial_url(url: DriveUrl) -> str:
    """The port or pyserial URL behind a DYN232M drive URL (query options removed)."""
    if url.scheme == "dyn232":
        return url.inner
    if url.scheme:
        return f"{url.scheme}://{url.target}"
    return url.target


async def open_stream(port: str, *, baud: int = c.BAUD, transport: str = "auto") -> ByteStream:
    """The ByteStream for a port or pyserial URL."""
    scheme = port.split("://", 1)[0].lower() if "://" in port else ""
    if transport not in ("auto", "tcp", "pyserial"):
        raise ArgumentRangeError(f"transport={transport!r}: use 'auto', 'tcp' or 'pyserial'")
    if scheme in ("socket", "tcp") and transport != "pyserial":
        from servobus.transport.tcp_stream import TcpStream

        return await TcpStream.open_url(port)
    if scheme == "tcp":
        port = "socket://" + port.split("://", 1)[1]
    from servobus.transport.serial_stream import SerialStream

    return await SerialStream.open(port, baud=baud)


async def open_axis(url: DriveUrl, *, drive_id: int | None = None, **keywords: Any) -> Dyn232Axis:
    """The Dyn232Axis of ``drive_id`` (default: the factory id 0) on the line ``url`` names."""
    options = merge_options(url, keywords, OPTIONS)
    drive_id = c.FACTORY_ID if drive_id is None else check_drive_id(drive_id)
    port = pyserial_url(url)
    baud = int(options.pop("baud", c.BAUD))  # type: ignore[call-overload]
    transport = str(options.pop("transport", "auto"))
    scheme = port.split("://", 1)[0].lower() if "://" in port else ""
    options.setdefault("query_interval_s",
                       0.0 if scheme in FAST_LINK_SCHEMES else HARDWARE_QUERY_INTERVAL_S)
    stream = await open_stream(port, baud=baud, transport=transport)
    client = await client_on(stream, lambda s: AsyncDyn232Client(
        s, baud=baud, **options))  # type: ignore[arg-type]
    return Dyn232Axis(client, drive_id)
