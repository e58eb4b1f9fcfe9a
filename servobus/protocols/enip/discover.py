"""Discovery from the host side: ListIdentity on UDP (CIP Vol. 2 2-4.2), docs/enip.md.

:func:`discover` sends one ListIdentity request to each given address, or one broadcast
(255.255.255.255 by default), on the encapsulation port (44818), then collects replies
until ``timeout`` passes (targets may delay a broadcast reply on purpose), or until every
given address answered. Each adapter is
reported once, by the address and port its reply came from, with the identity it reports
(the item's own socket address may be 0.0.0.0 or a NAT-side address: not trusted for where
it is). A reply that does not parse is counted and skipped, never raised.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

from servobus import checks
from servobus.errors import ArgumentRangeError, FramingError
from servobus.protocols.enip.axis import check_ip
from servobus.protocols.enip.codec import discovery
from servobus.protocols.enip.codec.encap import TCP_PORT, Command, EncapPacket, EncapStatus
from servobus.protocols.enip.scanner import local_address_for

BROADCAST = "255.255.255.255"
DEFAULT_TIMEOUT_S = 1.0
_CONTEXT = b"servobus"


@dataclass(frozen=True)
class Found:
    """One adapter that answered: where from, and what it says it is."""

    address: str
    port: int
    identity: discovery.IdentityItem
    seconds: float  # after the request

    def as_dict(self) -> dict[str, object]:
        i = self.identity
        return {"address": self.address, "port": self.port, "product_name": i.product_name,
                "vendor_id": i.vendor_id, "device_type": i.device_type,
                "product_code": i.product_code, "revision": f"{i.revision[0]}.{i.revision[1]}",
                "serial_number": f"{i.serial_number:08X}", "status": i.status,
                "state": i.state, "reply_ms": round(self.seconds * 1e3, 2)}


@dataclass
class _Collector(asyncio.DatagramProtocol):
    started: float
    expected: frozenset[str] = frozenset()  # unicast: stop once each of these answered
    found: dict[tuple[str, int], Found] = field(default_factory=dict)
    malformed: int = 0
    complete: asyncio.Event = field(default_factory=asyncio.Event)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        try:
            pkt = EncapPacket.decode(data)
            if pkt.command != Command.LIST_IDENTITY or pkt.status != EncapStatus.SUCCESS:
                raise FramingError("not a successful ListIdentity reply")
            identity = discovery.decode_identity_reply(pkt.data)
        except FramingError:
            self.malformed += 1
            return
        key = (addr[0], addr[1])
        if key not in self.found:
            self.found[key] = Found(addr[0], addr[1], identity, time.monotonic() - self.started)
        if self.expected and self.expected <= {f.address for f in self.found.values()}:
            self.complete.set()


async def discover(addresses: Sequence[str] | None = None, *, port: int = TCP_PORT,
                   timeout: float = DEFAULT_TIMEOUT_S, broadcast: str = BROADCAST
                   ) -> list[Found]:
    """Adapters answering ListIdentity, sorted by address (module docstring)."""
    limit = checks.seconds("timeout", timeout)
    if isinstance(port, bool) or not isinstance(port, int) or not 0 < port <= 0xFFFF:
        raise ArgumentRangeError(f"port must be 1..65535, got {port!r}")
    targets = [check_ip(a) for a in addresses] if addresses else [check_ip(broadcast)]
    loop = asyncio.get_running_loop()
    unicast = bool(addresses)
    local = local_address_for(targets[0]) if unicast else "0.0.0.0"
    collector = _Collector(time.monotonic(), frozenset(targets) if unicast else frozenset())
    transport, _ = await loop.create_datagram_endpoint(
        lambda: collector, local_addr=(local, 0), allow_broadcast=not unicast)
    udp = transport
    request = EncapPacket(Command.LIST_IDENTITY, context=_CONTEXT).encode()
    try:
        collector.started = time.monotonic()
        for target in targets:
            with contextlib.suppress(OSError):
                udp.sendto(request, (target, port))
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(collector.complete.wait(), limit)
    finally:
        udp.close()
    return sorted(collector.found.values(), key=lambda f: (tuple(
        int(b) for b in f.address.split(".")), f.port))
