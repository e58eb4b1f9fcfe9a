"""Open a ModbusAxis from a URL (registered in ``servobus.protocols.modbus.SCHEMES``).

* ``modbus:///dev/ttyUSB0?baud=19200``, ``modbus:COM3``: a serial port through pyserial
  (8N1; 19200 baud by default, the YZ-AIM TTL port, spec 004 section 1);
* ``modbus+socket://HOST:PORT`` (or ``+tcp``): a serial-to-TCP bridge or ``servobus sim
  modbus`` through asyncio TCP; ``?transport=pyserial`` uses pyserial's socket handler;
* ``modbus+rfc2217://...``, ``modbus+loop://`` ...: any other pyserial URL.

``baud`` also sets the client's frame gap and deadlines on TCP (the line behind the bridge
runs at it). The default drive id is 1 (decision: a YZ-AIM's address register 0x15 has no
factory value in the manual, and 1 is what its examples use).
"""

from __future__ import annotations

from typing import Any

from servobus import checks
from servobus.axis.url import DriveUrl, merge_options
from servobus.errors import ArgumentRangeError
from servobus.link.opening import client_on
from servobus.protocols.modbus.axis import ModbusAxis, check_address
from servobus.protocols.modbus.client import AsyncModbusClient
from servobus.protocols.modbus.timing import DEFAULT_BAUD
from servobus.transport.base import ByteStream

DEFAULT_ADDRESS = 1
TCP_TRANSPORTS = ("socket", "tcp")
OPTIONS: dict[str, type] = {
    "baud": int, "timeout": float, "retries": int, "turnaround_s": float,
    "late_reply_s": float, "frame_gap_s": float, "transport": str, "eeprom_guard": object,
}


def port_url(url: DriveUrl) -> str:
    """The port or pyserial URL behind a Modbus drive URL (query options removed)."""
    if not url.target:
        raise ArgumentRangeError(f"{url.raw!r} names no port: write modbus:///dev/ttyUSB0, "
                                 "modbus:COM3 or modbus+socket://HOST:PORT")
    return url.inner


async def open_stream(port: str, *, baud: int = DEFAULT_BAUD,
                      transport: str = "auto") -> ByteStream:
    """The ByteStream for a serial port or pyserial URL."""
    if transport not in ("auto", "tcp", "pyserial"):
        raise ArgumentRangeError(f"transport={transport!r}: use 'auto', 'tcp' or 'pyserial'")
    scheme = port.split("://", 1)[0].lower() if "://" in port else ""
    if scheme in TCP_TRANSPORTS and transport != "pyserial":
        from servobus.transport.tcp_stream import TcpStream

        return await TcpStream.open_url(port)
    if scheme == "tcp":
        port = "socket://" + port.split("://", 1)[1]
    from servobus.transport.serial_stream import SerialStream

    return await SerialStream.open(port, baud=baud)


async def open_axis(url: DriveUrl, *, drive_id: int | None = None,
                    **keywords: Any) -> ModbusAxis:
    """The ModbusAxis of motor ``drive_id`` (default 1) on the line ``url`` names.

    Every argument is checked before the port is opened."""
    options = merge_options(url, keywords, OPTIONS)
    address = DEFAULT_ADDRESS if drive_id is None else check_address(drive_id)
    port = port_url(url)
    baud = checks.positive_int("baud", options.pop("baud", DEFAULT_BAUD))
    transport = str(options.pop("transport", "auto"))
    if transport not in ("auto", "tcp", "pyserial"):
        raise ArgumentRangeError(f"transport={transport!r}: use 'auto', 'tcp' or 'pyserial'")
    AsyncModbusClient.check_options(options)
    stream = await open_stream(port, baud=baud, transport=transport)
    client = await client_on(stream, lambda s: AsyncModbusClient(
        s, baud=baud, **options))  # type: ignore[arg-type]
    return ModbusAxis(client, address)
