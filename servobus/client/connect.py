"""connect() / connect_async(): one entry point for every protocol (AXIS_API.md).

URL dispatch:

* ``None`` (and no ``can=``) -> ``sim://dyn2``: the in-process virtual line
  (:mod:`servobus.sim.inprocess`; ``sim://dyn2?ids=0,1,2&fast=1``); without ``ids`` its one
  drive has the ``drive_id`` asked for.
* ``socket://host:port`` / ``tcp://host:port`` -> asyncio TCP (:class:`TcpStream`), faster
  than pyserial's socket handler (no reader thread; benchmarks/bench_dyn232_client.py);
  ``transport="pyserial"`` forces pyserial.
* anything else (/dev/ttyUSB0, COM3, loop://, rfc2217://...) -> pyserial (:class:`SerialStream`).
* ``can="INTERFACE:CHANNEL"`` -> ``servobus.client.dyncan.open_can_axis``.

Options (keywords) for DYN232M: ``retries`` (reads only, default 2), ``turnaround_s``,
``query_interval_s``, ``eeprom_guard`` (an EepromGuard), ``late_reply_s`` (the late-reply
drain after a timeout, servobus.client.late_replies), ``transport`` ("auto", "tcp",
"pyserial"). ``timeout`` is the per-attempt reply deadline (default: from the baud rate).

Query pacing default (servobus decision): 0.02 s (50 queries/s, NOTES.md) on serial device
ports (/dev/..., COMn, rfc2217://), where a real drive is attached; off for sim://, loop://
and socket:// (the simulator and fast links). Pass ``query_interval_s=0.02`` for a real drive
behind a serial-to-TCP bridge. A dropped query is detected and retried either way.
"""

from __future__ import annotations

from typing import Any

from servobus.client.axis import AsyncAxis, Axis
from servobus.client.dyn232 import AsyncDyn232Client, Dyn232Axis
from servobus.client.sync import LoopThread
from servobus.codec import dyn232 as c
from servobus.errors import ArgumentRangeError, ServobusError
from servobus.transport.base import ByteStream

DEFAULT_URL = "sim://dyn2"
HARDWARE_QUERY_INTERVAL_S = 0.02  # NOTES.md: real drives may drop queries above ~50/s
_CLIENT_OPTIONS = ("retries", "turnaround_s", "query_interval_s", "eeprom_guard",
                   "late_reply_s")


async def connect_async(
    url: str | None = None,
    *,
    drive_id: int = 0,
    baud: int = c.BAUD,
    can: str | None = None,
    timeout: float | None = None,
    **options: Any,
) -> AsyncAxis:
    """Open a connection and return the AsyncAxis for ``drive_id`` (close it when done)."""
    if can is not None:
        if url is not None:
            raise ArgumentRangeError("give either a serial url or can=..., not both")
        return await _open_can(can, drive_id=drive_id, timeout=timeout, **options)
    url = DEFAULT_URL if url is None else url
    transport = options.pop("transport", "auto")
    client_kw = {k: options.pop(k) for k in _CLIENT_OPTIONS if k in options}
    if options:
        raise ArgumentRangeError(f"unknown connect option(s): {', '.join(sorted(options))}")
    client_kw.setdefault("query_interval_s", _default_query_interval(url))
    from servobus.client.dyn232_commands import check_drive_id

    check_drive_id(drive_id)  # before opening anything
    stream = await open_stream(url, baud=baud, transport=transport, drive_id=drive_id)
    try:
        client = AsyncDyn232Client(stream, baud=baud, timeout=timeout, **client_kw)
    except BaseException:  # a bad option (ArgumentRangeError): nothing sent, port released
        await stream.close()
        raise
    return Dyn232Axis(client, drive_id)


def connect(
    url: str | None = None,
    *,
    drive_id: int = 0,
    baud: int = c.BAUD,
    can: str | None = None,
    timeout: float | None = None,
    **options: Any,
) -> Axis:
    """Synchronous :func:`connect_async`: the Axis runs on a private event-loop thread."""
    runner = LoopThread()
    try:
        core = runner.run(connect_async(url, drive_id=drive_id, baud=baud, can=can,
                                        timeout=timeout, **options))
    except BaseException:
        runner.stop()
        raise
    return Axis(core, runner)


async def open_stream(url: str, *, baud: int = c.BAUD, transport: str = "auto",
                      drive_id: int = c.FACTORY_ID) -> ByteStream:
    """The ByteStream a DYN232M url names (see module doc); ``drive_id`` is the id of the
    one virtual drive of a ``sim://`` url without ``ids``."""
    scheme = url.split("://", 1)[0].lower() if "://" in url else ""
    if transport not in ("auto", "tcp", "pyserial"):
        raise ArgumentRangeError(f"transport={transport!r}: use 'auto', 'tcp' or 'pyserial'")
    if scheme == "sim":
        return await _open_sim(url, baud, drive_id)
    if scheme in ("socket", "tcp") and transport != "pyserial":
        from servobus.transport.tcp_stream import TcpStream

        return await TcpStream.open_url(url)
    if scheme == "tcp":
        url = "socket://" + url.split("://", 1)[1]
    from servobus.transport.serial_stream import SerialStream

    return await SerialStream.open(url, baud=baud)


def _default_query_interval(url: str) -> float:
    scheme = url.split("://", 1)[0].lower() if "://" in url else ""
    if scheme in ("sim", "loop", "socket", "tcp", "spy", "alt", "hwgrep"):
        return 0.0
    return HARDWARE_QUERY_INTERVAL_S


async def _open_sim(url: str, baud: int, drive_id: int) -> ByteStream:
    try:
        from servobus.sim.inprocess import open_sim_stream, parse_sim_url
    except ImportError as exc:
        raise ServobusError(f"the in-process simulator is not available: {exc}") from exc
    u = parse_sim_url(url, default_id=drive_id)
    stream: ByteStream = open_sim_stream(u.kind, ids=u.ids, paced=u.paced, state=u.state,
                                         model=u.model)
    return stream


async def _open_can(can: str, *, drive_id: int, timeout: float | None,
                    **options: Any) -> AsyncAxis:
    try:
        from servobus.client.dyncan import open_can_axis
    except ImportError as exc:
        raise ServobusError(
            f"DYN CAN support is not available (servobus.client.dyncan: {exc})"
        ) from exc
    axis: AsyncAxis = await open_can_axis(can, drive_id=drive_id, timeout=timeout, **options)
    return axis
