"""EnipAxis: one DYN5 over EtherNet/IP explicit messaging: the wire of the DYN5 profile.

The mapping of the Axis API onto the DYN5 (GEAR_NUM, status word, currents, torque mode) is
:class:`servobus.families.dyn5.axis.Dyn5Axis`'s, on the DMM profile. What this module adds
is the wire: every instance read or write is a Get/Set_Attribute_Single on the Parameter
object (class 0x0F, attribute 1) through :class:`AsyncEnipClient`, sessions, and what only
EtherNet/IP has.

* A Set reply only says the module took the value (manual 4.1, 7: effective within 300 us);
  motion is seen in the status word. A move is never re-sent.
* The peak current is not readable over EtherNet/IP: ``peak_current_a`` (default 20 A, the
  DYN5-H01 of the manual's 4.4 example) scales the torque instances.
* Ids: a DYN5 has no drive id; it is addressed by its IP address, and the drives of one
  daisy chain share B3.B2.B1 (manual 2). Decision: the Axis's ``drive_id`` is B0, the last
  octet; ``sibling(n)`` opens its own session to B3.B2.B1.n on the same TCP port;
  ``drive_ids`` is 1..253 (the manual asks to avoid 0, 254 and 255); ``assign_id`` is
  NotSupported (the address is set in DMMDRV5, 3.1). A sibling connects on first use; a
  drive that does not accept the connection is a DriveTimeout (an absent drive).
* Reset (0x21 = 0xABCD): the adapter answers, then drops every session and is down for
  about 3 s (4.4). ``reset()`` reconnects until the adapter answers a status read again,
  within ``reset_timeout`` (default 15 s). The manual asks for 10 s before new commands
  after a Reset; a real drive may need that wait (``await asyncio.sleep``) before motion.
* Torque mode (0x25/0x26/0x27) and cyclic I/O (``io()``, section 5) are DYN5 extras.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from servobus import checks
from servobus.axis.base import AxisTraceHook
from servobus.axis.capabilities import Capability
from servobus.errors import (
    ArgumentRangeError,
    ConnectionLost,
    DriveError,
    DriveTimeout,
    FramingError,
    ProtocolError,
)
from servobus.families.dyn5 import params as dyn5
from servobus.families.dyn5.axis import Dyn5Axis
from servobus.families.dyn5.params import Instance
from servobus.link.stats import TransactionStats
from servobus.link.transaction import DEFAULT_RETRIES
from servobus.protocols.enip.client import CONNECT_TIMEOUT_S, DEFAULT_TIMEOUT_S, AsyncEnipClient
from servobus.protocols.enip.codec.cip import ClassCode, MessageRouterRequest, MessageRouterResponse
from servobus.protocols.enip.codec.encap import TCP_PORT, EncapPacket
from servobus.protocols.enip.codec.identity import IdentityReply
from servobus.protocols.enip.sniff import message_text, packet_text

if TYPE_CHECKING:
    from servobus.protocols.enip.scanner import CyclicIo, InputFrame

log = logging.getLogger("servobus.enip")

PROTOCOL = "enip"
#: DYN5-H01 peak output current (manual 4.4, 0x1F and 0x20 examples).
DEFAULT_PEAK_CURRENT_A = 20.0
DEFAULT_RESET_TIMEOUT_S = 15.0
RESET_RETRY_S = 0.2
#: B0 of a daisy chain's addresses (manual 2: avoid 0, 254 and 255).
DRIVE_IDS = range(1, 254)
STATUS_INSTANCE = dyn5.BY_NAME["drive_status"].number


@dataclass(frozen=True)
class EnipOptions:
    """How an EnipAxis (and each sibling) talks to its adapter."""

    port: int = TCP_PORT
    timeout: float = DEFAULT_TIMEOUT_S
    retries: int = DEFAULT_RETRIES
    connect_timeout: float = CONNECT_TIMEOUT_S
    peak_current_a: float = DEFAULT_PEAK_CURRENT_A
    reset_timeout: float = DEFAULT_RESET_TIMEOUT_S
    max_in_flight: int = 1

    def checked(self) -> EnipOptions:
        """Every field checked (ArgumentRangeError) before anything is opened."""
        if isinstance(self.port, bool) or not isinstance(self.port, int) or not (
                0 < self.port <= 0xFFFF):
            raise ArgumentRangeError(f"port must be 1..65535, got {self.port!r}")
        checks.seconds("timeout", self.timeout)
        checks.count("retries", self.retries)
        checks.seconds("connect_timeout", self.connect_timeout)
        checks.seconds("reset_timeout", self.reset_timeout)
        checks.positive_int("max_in_flight", self.max_in_flight)
        peak = checks.positive("peak_current_a", self.peak_current_a, "A")
        return replace(self, peak_current_a=peak)


def check_ip(host: str) -> str:
    """A dotted IPv4 address (DYN5: static IPv4 only, manual 1)."""
    try:
        return str(ipaddress.IPv4Address(host))
    except ValueError:
        raise ArgumentRangeError(f"{host!r} is not an IPv4 address") from None


def with_last_octet(ip: str, b0: int) -> str:
    """B3.B2.B1 of ``ip`` with B0 = ``b0`` (a drive of the same daisy chain)."""
    if isinstance(b0, bool) or not isinstance(b0, int) or not 0 <= b0 <= 255:
        raise ArgumentRangeError(f"a DYN5 drive id is the last address byte 0..255, got {b0!r}")
    return f"{ip.rsplit('.', 1)[0]}.{b0}"


class EnipAxis(Dyn5Axis):
    """One DYN5 on one EtherNet/IP session (module docstring)."""

    protocol_capabilities = frozenset({Capability.LINK_STATS})

    def __init__(self, client: AsyncEnipClient | None, ip: str,
                 options: EnipOptions = EnipOptions()) -> None:
        self._client = client
        self.ip = check_ip(ip)
        self.options = options
        self._hooks: list[AxisTraceHook] = []
        self._closers: list[Callable[[], Awaitable[None]]] = []
        self._closed = False

    def on_close(self, closer: Callable[[], Awaitable[None]]) -> None:
        """Run ``closer`` after the session closes (e.g. an in-process adapter's servers)."""
        self._closers.append(closer)

    # ------------------------------------------------------------- connection
    @property
    def address(self) -> tuple[str, int]:
        return self.ip, self.options.port

    async def _connect(self, connect_timeout: float | None = None) -> AsyncEnipClient:
        o = self.options
        client = await AsyncEnipClient.connect(
            self.ip, o.port, timeout=o.timeout, retries=o.retries,
            connect_timeout=o.connect_timeout if connect_timeout is None else connect_timeout,
            max_in_flight=o.max_in_flight)
        for hook in self._hooks:
            client.add_trace(hook)
        return client

    def link_stats(self) -> TransactionStats:
        """The current session's counters (zeros before the first connection; a reconnect
        starts a new session and new counters)."""
        return TransactionStats() if self._client is None else self._client.stats

    async def client(self, connect_timeout: float | None = None) -> AsyncEnipClient:
        """The session; a sibling (or an axis after ``reset``) connects on first use."""
        if self._closed:
            raise ConnectionLost(f"the axis of {self.ip} is closed")
        if self._client is None:
            self._client = await self._connect(connect_timeout)
        return self._client

    async def reconnect(self) -> None:
        """Close the session (if any) and register a new one (e.g. after ConnectionLost)."""
        old, self._client = self._client, None
        if old is not None:
            await old.close()
        await self.client()

    # ------------------------------------------------------------- identity
    @property
    def drive_id(self) -> int:
        return int(self.ip.rsplit(".", 1)[1])

    @property
    def protocol(self) -> str:
        return PROTOCOL

    @property
    def drive_ids(self) -> range:
        return DRIVE_IDS

    # ------------------------------------------------------------- Parameter object
    async def read_instance(self, key: int | str, *, timeout: float | None = None,
                            retries: int | None = None) -> int:
        """Attribute 1 of a Parameter instance (number or table name), signed where the
        instance's range is. Write-only and missing instances read 0x12345 (4.1)."""
        inst = dyn5.instance(key) if isinstance(key, str) else dyn5.BY_NUMBER.get(key)
        number = inst.number if inst is not None else _instance_number(key)
        client = await self.client()
        data = await client.get_attribute_single(ClassCode.PARAMETER, number,
                                                 dyn5.PARAMETER_ATTRIBUTE, timeout=timeout,
                                                 retries=retries)
        if len(data) != 4:
            raise FramingError(f"instance 0x{number:02X} answered {len(data)} bytes, not a UDINT")
        return inst.decode(data) if inst is not None else dyn5.decode_udint(data)

    async def _write_instance(self, inst: Instance, value: int) -> None:
        data = inst.encode(inst.check(value))
        client = await self.client()
        await client.set_attribute_single(ClassCode.PARAMETER, inst.number,
                                          dyn5.PARAMETER_ATTRIBUTE, data)

    @property
    def peak_current_a(self) -> float:
        return self.options.peak_current_a

    @property
    def id_address(self) -> str:
        """B3.B2.B1.id: the drive id picks the drive of the URL's daisy chain (docs/enip.md)."""
        return self.ip

    # ------------------------------------------------------------- Reset and link
    async def reset(self) -> None:
        """0x21 = 0xABCD, then reconnect once the adapter is back (module docstring)."""
        await super().reset()  # 0x21 = 0xABCD; GEAR_NUM is forgotten (Dyn5Axis)
        old, self._client = self._client, None
        if old is not None:
            await old.close()
        deadline = time.monotonic() + self.options.reset_timeout
        last: Exception | None = None
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise DriveTimeout(f"{self.ip} did not come back within "
                                   f"{self.options.reset_timeout:g} s after Reset ({last})")
            await asyncio.sleep(min(RESET_RETRY_S, remaining))
            try:
                client = await self.client(min(self.options.connect_timeout,
                                               max(remaining, 0.05)))
                await self.status()
                log.info("%s answers again after Reset (session 0x%08X)", self.ip,
                         client.session)
                return
            except (DriveTimeout, ConnectionLost, ProtocolError) as exc:
                last = exc
                broken, self._client = self._client, None
                if broken is not None:
                    await broken.close()

    def on_link_lost(self, callback: Callable[[ConnectionLost], object]) -> bool:
        """The session open now (a sibling's, opened on first use, is not watched: its
        failed calls show the loss)."""
        if self._client is None:
            return False
        self._client.transactions.on_lost(callback)
        return True

    async def identity(self) -> IdentityReply:
        """Identity object instance 1, Get_Attributes_All (4.2)."""
        client = await self.client()
        return IdentityReply.decode(await client.get_attributes_all(ClassCode.IDENTITY, 1))

    # ------------------------------------------------------------- ids
    async def read_id(self) -> int:
        """B0 of the address, once the drive has answered a status read."""
        await self.status()
        return self.drive_id

    async def assign_id(self, new_id: int) -> None:
        raise self.unsupported(Capability.DRIVE_ID)

    async def ping(self, timeout: float = 0.05) -> bool:
        """One status read without retry (connecting first if needed). A refused request
        still proves that something answered."""
        checks.seconds("timeout", timeout)
        try:
            client = await self.client(connect_timeout=timeout)
            await client.get_attribute_single(ClassCode.PARAMETER, STATUS_INSTANCE,
                                              dyn5.PARAMETER_ATTRIBUTE, timeout=timeout,
                                              retries=0)
        except (DriveTimeout, ConnectionLost):
            return False
        except (ProtocolError, DriveError):
            return True
        return True

    async def sibling(self, drive_id: int) -> EnipAxis:
        """The drive at B3.B2.B1.``drive_id`` on the same port (its own session, opened on
        first use; closing it never closes this one)."""
        return EnipAxis(None, with_last_octet(self.ip, drive_id), self.options)

    # ------------------------------------------------------------- cyclic I/O
    def io(self, rpi_ms: float = 10.0, **options: object) -> CyclicIo:
        """Class 1 implicit I/O (``async with axis.io(rpi_ms=10) as io``), see
        :class:`servobus.protocols.enip.scanner.CyclicIo`."""
        from servobus.protocols.enip.scanner import CyclicIo

        return CyclicIo(self, rpi_ms=rpi_ms, **options)  # type: ignore[arg-type]

    async def monitor_io(self, on_frame: Callable[[InputFrame], None], *,
                         rpi_ms: float = 10.0, frames: int | None = None,
                         duration: float | None = None) -> dict[str, int]:
        """Open cyclic I/O and call ``on_frame`` for each input frame until ``frames`` have
        arrived or ``duration`` passed (or the call is cancelled); the I/O statistics."""
        if frames is not None:
            checks.positive_int("frames", frames)
        limit = checks.optional_seconds("duration", duration)
        cyclic = self.io(rpi_ms=rpi_ms)
        stream = cyclic.frames()  # before the open: from the very first frame
        async with cyclic:
            seen = 0
            deadline = asyncio.timeout(limit)
            try:
                async with deadline:
                    async for frame in stream:
                        on_frame(frame)
                        seen += 1
                        if frames is not None and seen >= frames:
                            break
            except TimeoutError:
                if not deadline.expired():
                    raise
            return cyclic.stats.as_dict()

    # ------------------------------------------------------------- housekeeping
    def describe_traced(self, item: object, from_drive: bool) -> str | None:
        """A traced Message Router request or reply (or another encapsulation packet) in
        the sniff decoder's words (not its repr)."""
        try:
            if isinstance(item, MessageRouterRequest | MessageRouterResponse):
                return message_text(item.encode())
            if isinstance(item, EncapPacket):
                return packet_text(item)
        except FramingError as exc:
            return f"malformed: {exc}"
        return None

    async def add_trace(self, hook: AxisTraceHook) -> None:
        self._hooks.append(hook)
        if self._client is not None:
            self._client.add_trace(hook)

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        client, self._client = self._client, None
        try:
            if client is not None:
                await client.close()
        finally:
            closers, self._closers = self._closers, []
            for closer in closers:
                await closer()

    def __repr__(self) -> str:
        return f"<EnipAxis {self.ip}:{self.options.port}>"


def _instance_number(key: object) -> int:
    if isinstance(key, bool) or not isinstance(key, int) or not 1 <= key <= dyn5.INSTANCE_MAX:
        raise ArgumentRangeError(f"a Parameter instance is 1..{dyn5.INSTANCE_MAX}, got {key!r}")
    return key
