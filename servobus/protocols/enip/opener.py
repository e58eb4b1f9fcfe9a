"""Open a DYN5 Axis from ``enip://HOST[:PORT]`` (registered in ``servobus.protocols.enip``).

HOST is the drive's IPv4 address or a name that resolves to one; PORT defaults to 44818.
Options (query or keywords): ``timeout``, ``retries``, ``connect_timeout``,
``peak_current_a`` (amperes at torque 2000, default 20 A, the DYN5-H01), ``reset_timeout``,
``max_in_flight`` (requests outstanding at once on the session, default 1).

``drive_id`` (the CLI's ``--id``) is the last address byte B0 (docs/enip.md): with an id,
the axis opens B3.B2.B1.<id> of the URL's address, the drive of the same daisy chain;
without, the URL's address itself.
"""

from __future__ import annotations

import asyncio
import socket
from typing import Any

from servobus.axis.url import DriveUrl, merge_options
from servobus.errors import ArgumentRangeError
from servobus.protocols.enip.axis import EnipAxis, EnipOptions, with_last_octet
from servobus.protocols.enip.client import AsyncEnipClient
from servobus.protocols.enip.codec.encap import TCP_PORT

OPTIONS: dict[str, type] = {
    "timeout": float, "retries": int, "connect_timeout": float, "peak_current_a": float,
    "reset_timeout": float, "max_in_flight": int,
}


def split_target(url: DriveUrl) -> tuple[str, int]:
    """``HOST[:PORT]`` of an ``enip://`` URL (no path)."""
    target = url.target.rstrip("/")
    if not target or "/" in target:
        raise ArgumentRangeError(f"{url.raw!r}: write enip://HOST[:PORT], e.g. "
                                 "enip://192.168.50.18 or enip://127.0.0.1:44818")
    host, sep, port_text = target.rpartition(":")
    if not sep:
        return target, TCP_PORT
    if not host or not port_text.isdigit() or not 0 < int(port_text) <= 0xFFFF:
        raise ArgumentRangeError(f"{url.raw!r}: the port must be 1..65535")
    return host, int(port_text)


async def resolve(host: str, port: int) -> str:
    """The IPv4 address of ``host`` (DYN5 addresses are static IPv4, manual 1)."""
    loop = asyncio.get_running_loop()
    try:
        infos = await loop.getaddrinfo(host, port, family=socket.AF_INET,
                                       type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise ArgumentRangeError(f"cannot resolve {host!r}: {exc.strerror or exc}") from None
    return str(infos[0][4][0])


def axis_options(options: dict[str, object], port: int) -> EnipOptions:
    kw: dict[str, Any] = {k: options[k] for k in OPTIONS if k in options}
    return EnipOptions(port=port, **kw).checked()


async def open_axis(url: DriveUrl, *, drive_id: int | None = None,
                    **keywords: Any) -> EnipAxis:
    """The EnipAxis of the drive ``url`` names (its session registered)."""
    options = merge_options(url, keywords, OPTIONS)
    host, port = split_target(url)
    checked = axis_options(options, port)
    if drive_id is not None:
        with_last_octet("0.0.0.0", drive_id)  # checked before the name is resolved
    ip = await resolve(host, port)
    if drive_id is not None:
        ip = with_last_octet(ip, drive_id)
    client = await AsyncEnipClient.connect(ip, port, timeout=checked.timeout,
                                           retries=checked.retries,
                                           connect_timeout=checked.connect_timeout,
                                           max_in_flight=checked.max_in_flight)
    return EnipAxis(client, ip, checked)
