"""asyncio EtherNet/IP explicit-messaging client: one TCP session to one adapter (docs/enip.md).

The DYN5 answers unconnected explicit messages only (manual 1: "Explicit messaging is
Unconnected"): every request is a SendRRData carrying a null address item and an
unconnected data item with one Message Router request. The client registers a session
(RegisterSession), then sends Get_Attribute_Single / Set_Attribute_Single /
Get_Attributes_All, and the Connection Manager's Forward_Open / Forward_Close for cyclic I/O
(:mod:`servobus.protocols.enip.scanner`). UnregisterSession on close.

Transactions follow the shared policy, :class:`servobus.link.transaction.TransactionManager`:
every call carries its own sender context (a 64-bit counter), which the adapter echoes
(CIP Vol. 2 2-3) and which is the key its reply is matched on; each attempt waits
``timeout`` (default 0.5 s: a DYN5 answers within milliseconds on a LAN, manual 7) from
when the packet left; reads (Get services, ListIdentity) are re-sent up to ``retries``
times (default 2) with the same context; a Set or a Connection Manager request is sent
once and never re-sent (a resend could move twice). A reply that comes after its call gave
up is dropped (``stats.late_replies``): a context is never used by a later call, so a late
reply never answers one. Requests run one at a time on a session unless ``max_in_flight``
allows more: the encapsulation matches replies by context, so concurrent calls (several
asyncio tasks on one axis) may then have up to that many requests outstanding, pipelined
on the one TCP connection. Default 1: the manual says nothing about how many outstanding
requests a DYN5 queues, so a real drive is never asked to hold more than one. SendRRData
carries timeout 0 (the encapsulation layer adds no timeout of its own; CIP Vol. 2 2-4.7).

Errors are typed: no reply -> DriveTimeout; a refused request (CIP general status, e.g.
the DYN5's "05 error") -> DriveError with ``code`` = the general status
(``stats.error_replies``); a bad encapsulation status or a malformed reply -> ProtocolError;
the TCP connection gone -> ConnectionLost, at once for a waiting request and for every
call after.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
from collections.abc import Callable

from servobus import checks
from servobus.errors import (
    ConnectionLost,
    DriveError,
    DriveTimeout,
    FramingError,
    ProtocolError,
    ServobusError,
)
from servobus.link.stats import TransactionStats
from servobus.link.transaction import DEFAULT_RETRIES, TransactionManager
from servobus.protocols.enip import commands
from servobus.protocols.enip.codec import discovery
from servobus.protocols.enip.codec.cip import (
    REPLY_FLAG,
    GeneralStatus,
    MessageRouterRequest,
    MessageRouterResponse,
    Service,
    request_target,
)
from servobus.protocols.enip.codec.cpf import (
    CpfItem,
    RRData,
    UnconnectedMessage,
    plain_rr_data,
    unconnected,
    unconnected_message,
)
from servobus.protocols.enip.codec.encap import (
    HEADER,
    TCP_PORT,
    Command,
    EncapFramer,
    EncapPacket,
    EncapReject,
    EncapStatus,
    RegisterSessionData,
)
from servobus.transport.base import Direction
from servobus.transport.tcp_stream import TcpStream

log = logging.getLogger("servobus.enip")

DEFAULT_TIMEOUT_S = 0.5
CONNECT_TIMEOUT_S = 2.0
#: Replies are small; a bound well above any DYN5 reply keeps the framer's memory bounded.
MAX_REPLY_DATA = 4096
_CONTEXT = struct.Struct("<Q")
_HEAD = struct.Struct("<HHII")  # command, length, session, status: the header before the context
_U16 = struct.Struct("<H")
#: SendRRData reply data bytes 6..13 of the plain shape: 2 items, a null address item (type 0,
#: length 0), then the unconnected data item's type (0x00B2); its length follows.
_PLAIN_REPLY = bytes((2, 0, 0, 0, 0, 0, 0xB2, 0))
_READS_CACHE = 256  # read messages whose packet parts are kept (one per polled attribute)

TraceHook = Callable[[Direction, object, float], None]

_G = GeneralStatus
STATUS_TEXT: dict[int, str] = {
    _G.CONNECTION_FAILURE: "connection failure",
    _G.RESOURCE_UNAVAILABLE: "resource unavailable",
    _G.PATH_SEGMENT_ERROR: "path segment error",
    _G.PATH_DESTINATION_UNKNOWN: "refused: unsupported object or value out of range "
                                 "(DYN5 error 05)",
    _G.SERVICE_NOT_SUPPORTED: "service not supported",
    _G.NOT_ENOUGH_DATA: "not enough data",
    _G.ATTRIBUTE_NOT_SUPPORTED: "attribute not supported",
    _G.TOO_MUCH_DATA: "too much data",
    _G.OBJECT_DOES_NOT_EXIST: "object does not exist",
}


def status_text(status: int) -> str:
    return STATUS_TEXT.get(status, f"CIP status 0x{status:02X}")


class AsyncEnipClient:
    """One registered session on one adapter; every method runs on one event loop."""

    def __init__(self, stream: TcpStream, host: str, port: int = TCP_PORT, *,
                 timeout: float = DEFAULT_TIMEOUT_S, retries: int = DEFAULT_RETRIES,
                 max_in_flight: int = 1) -> None:
        self.stream = stream
        self.max_in_flight = checks.positive_int("max_in_flight", max_in_flight)
        self.host = host
        self.port = port
        self.timeout = checks.seconds("timeout", timeout)
        self.session = 0
        self.transactions: TransactionManager[bytes, bytes, EncapPacket] = TransactionManager(
            # one request at a time: straight to the stream (a coroutine frame less per call)
            self._write if self.max_in_flight > 1 else stream.write,
            link=f"EtherNet/IP session with {host}:{port}",
            describe_key=_describe_context, describe_request=self._describe_packet,
            trace_request=_trace_item, retries=retries)
        self._framer = EncapFramer(MAX_REPLY_DATA)
        self._out: list[bytes] = []
        self._context = 0
        self._messages: dict[tuple[int, int, int, int | None], bytes] = {}
        #: Per read message: (header before the context, options + SendRRData data, session).
        self._reads: dict[bytes, tuple[bytes, bytes, int]] = {}
        stream.set_receiver(self._received)

    @property
    def stats(self) -> TransactionStats:
        return self.transactions.stats

    # ---------------------------------------------------------------- lifecycle
    @classmethod
    async def connect(cls, host: str, port: int = TCP_PORT, *,
                      timeout: float = DEFAULT_TIMEOUT_S, retries: int = DEFAULT_RETRIES,
                      connect_timeout: float = CONNECT_TIMEOUT_S,
                      max_in_flight: int = 1) -> AsyncEnipClient:
        """Open TCP and register a session. Nothing listening, or no answer within
        ``connect_timeout``: DriveTimeout naming the address."""
        checks.seconds("timeout", timeout)  # checked before anything is opened
        checks.count("retries", retries)
        checks.seconds("connect_timeout", connect_timeout)
        checks.positive_int("max_in_flight", max_in_flight)
        try:
            stream = await TcpStream.connect(host, port, timeout=connect_timeout)
        except ServobusError as exc:
            reason = exc.__cause__ if exc.__cause__ is not None else exc
            text = str(reason) or type(reason).__name__
            raise DriveTimeout(f"no EtherNet/IP adapter answers at {host}:{port} ({text})"
                               ) from exc
        client = cls(stream, host, port, timeout=timeout, retries=retries,
                     max_in_flight=max_in_flight)
        try:
            await client.register_session(connect_timeout)
        except BaseException:
            await client.close()
            raise
        return client

    async def register_session(self, timeout: float | None = None) -> int:
        reply = await self._exchange(Command.REGISTER_SESSION, RegisterSessionData().encode(),
                                     read=False, timeout=timeout)
        if reply.status != EncapStatus.SUCCESS or not reply.session:
            raise ProtocolError(f"{self.host}:{self.port} refused RegisterSession "
                                f"(encapsulation status 0x{reply.status:04X})")
        self.session = reply.session
        log.debug("session 0x%08X registered on %s:%d", self.session, self.host, self.port)
        return self.session

    @property
    def closed(self) -> bool:
        return self.transactions.dead is not None

    async def close(self) -> None:
        """UnregisterSession (the target sends no reply), then close; idempotent."""
        if self.transactions.closed:
            return
        if self.session and self.transactions.dead is None:
            with contextlib.suppress(ServobusError, OSError):
                await self.stream.write(self._packet(Command.UNREGISTER_SESSION, b""))
        self.transactions.close()
        await self.stream.close()

    # ---------------------------------------------------------------- tracing
    def add_trace(self, hook: TraceHook) -> None:
        """``hook(direction, item, t)``: each Message Router request/response (decoded),
        other encapsulation packets, and each timeout."""
        self.transactions.add_trace(hook)

    # ---------------------------------------------------------------- reception
    def _received(self, data: bytes | None) -> None:
        tm = self.transactions
        if data is None:
            tm.lost(ConnectionLost(f"{self.host}:{self.port} closed the connection"))
            return
        for item in self._framer.feed(data):
            if isinstance(item, EncapReject):
                error = FramingError(f"reply of {item.header.length} bytes exceeds "
                                     f"{MAX_REPLY_DATA}")
                if not tm.reject(error, item.header.context):
                    tm.stray(error)
                continue
            if not (tm.answer(item.context, item) or tm.late(item.context)):
                tm.stray(item)

    # ---------------------------------------------------------------- requests
    def _packet(self, command: int, data: bytes, context: bytes = bytes(8)) -> bytes:
        return HEADER.pack(command, len(data), self.session, 0, context, 0) + data

    async def _write(self, packet: bytes) -> None:
        """Requests to the socket with ``max_in_flight`` > 1 (one at a time, the manager
        writes to the stream itself): the requests that tasks make in one event-loop pass
        leave in one write (the first waits one pass for the others), so a pipelined burst
        costs one system call, not one per request."""
        out = self._out
        out.append(packet)
        if len(out) > 1:
            return  # the first writer of this pass sends it
        await asyncio.sleep(0)
        data = b"".join(out)
        out.clear()
        await self.stream.write(data)

    def _next_context(self) -> bytes:
        self._context = (self._context + 1) & 0xFFFF_FFFF_FFFF_FFFF
        return _CONTEXT.pack(self._context)

    def _describe_packet(self, packet: bytes) -> str:
        where = f"{self.host}:{self.port}"
        try:
            pkt = EncapPacket.decode(packet)
            if pkt.command != Command.SEND_RR_DATA:
                return f"{where} to {Command(pkt.command).name}"
            items = RRData.decode(pkt.data).items
            return f"{where} to {describe(UnconnectedMessage.from_items(items).message)}"
        except (FramingError, ValueError):
            return where

    async def _exchange(self, command: int, data: bytes, *, read: bool,
                        timeout: float | None = None, retries: int | None = None) -> EncapPacket:
        """Send one encapsulation packet and return the reply carrying its context."""
        deadline_s = self.timeout if timeout is None else checks.seconds("timeout", timeout)
        if retries is not None:
            checks.count("retries", retries)
        context = self._next_context()
        lane = None if self.max_in_flight == 1 else self._context % self.max_in_flight
        try:
            return await self.transactions.request(
                context, self._packet(command, data, context), deadline_s=deadline_s,
                retry_safe=read, retries=retries, lane=lane)
        except DriveTimeout as exc:
            if read:
                raise
            raise DriveTimeout(f"{exc}; sent once and not re-sent (it may have been carried "
                               "out)") from None

    @staticmethod
    def _rr_data(message: bytes, extra: tuple[CpfItem, ...]) -> bytes:
        if not extra:
            return plain_rr_data(message)
        return RRData(unconnected(message, *extra)).encode()

    async def request(self, message: bytes, *, read: bool | None = None,
                      timeout: float | None = None, retries: int | None = None,
                      extra: tuple[CpfItem, ...] = ()) -> tuple[MessageRouterResponse,
                                                                 UnconnectedMessage]:
        """One Message Router request (encoded) in a SendRRData; the decoded response and
        the reply's items (a Forward_Open reply may name the O->T sockaddr). The response
        may carry an error status: :meth:`call` raises on it."""
        if not message:
            raise FramingError("empty Message Router request")
        service = message[0]
        if read is None:
            read = commands.is_read(service)
        reply = await self._exchange(Command.SEND_RR_DATA, self._rr_data(message, extra),
                                     read=read, timeout=timeout, retries=retries)
        return self._response(reply, service)

    def _response(self, reply: EncapPacket, service: int
                  ) -> tuple[MessageRouterResponse, UnconnectedMessage]:
        """A SendRRData reply, decoded and checked (and traced)."""
        if reply.status != EncapStatus.SUCCESS:
            raise ProtocolError(f"{self.host}:{self.port} answered encapsulation status "
                                f"0x{reply.status:04X} to a SendRRData")
        try:
            items, _ = unconnected_message(reply.data)
            response = MessageRouterResponse.decode(items.message)
        except FramingError as exc:
            raise FramingError(f"malformed SendRRData reply from {self.host}: {exc}") from None
        if response.service != service:
            raise ProtocolError(f"reply to service 0x{response.service:02X}, expected "
                                f"0x{service:02X}")
        if self.transactions.tracing:
            self.transactions.trace(Direction.RX, response)
        return response, items

    async def call(self, message: bytes, *, read: bool | None = None,
                   timeout: float | None = None, retries: int | None = None) -> bytes:
        """:meth:`request`, then the response data; DriveError when the target refuses."""
        response, _ = await self.request(message, read=read, timeout=timeout, retries=retries)
        return self._data(response, message)

    def _data(self, response: MessageRouterResponse, message: bytes) -> bytes:
        if not response.ok:
            self.stats.error_replies += 1
            raise DriveError(f"{self.host} refused {describe(message)}: "
                             f"{status_text(response.general_status)}",
                             code=response.general_status)
        return response.data

    async def _read(self, message: bytes, timeout: float | None,
                    retries: int | None) -> bytes:
        """:meth:`call` for a Get service (a read: retried), on the hot path of polling.

        The packet is joined from parts built once per message and session around the
        call's sender context, and a reply of the plain shape that succeeded (null address
        + unconnected data, general status 0, no additional status) is read at fixed
        offsets; anything else - an error status, another shape, tracing on - goes through
        :meth:`_response` and :meth:`_data` with every check. One coroutine frame instead of
        four per read; the transaction rules are the same ones (``transactions.request``).
        """
        deadline_s = self.timeout if timeout is None else checks.seconds("timeout", timeout)
        if retries is not None:
            checks.count("retries", retries)
        parts = self._reads.get(message)
        if parts is None or parts[2] != self.session:
            if len(self._reads) >= _READS_CACHE:
                self._reads.clear()
            rr = plain_rr_data(message)
            parts = self._reads[message] = (
                _HEAD.pack(Command.SEND_RR_DATA, len(rr), self.session, 0),
                bytes(4) + rr, self.session)
        context = self._next_context()
        lane = None if self.max_in_flight == 1 else self._context % self.max_in_flight
        reply = await self.transactions.request(
            context, parts[0] + context + parts[1], deadline_s=deadline_s, retry_safe=True,
            retries=retries, lane=lane)
        data = reply.data
        if (not reply.status and data[6:14] == _PLAIN_REPLY and len(data) >= 20
                and data[16] == message[0] | REPLY_FLAG and not data[18] and not data[19]
                and _U16.unpack_from(data, 14)[0] == len(data) - 16
                and not self.transactions.tracing):
            return data[20:]
        return self._data(self._response(reply, message[0])[0], message)

    def message(self, service: int, class_id: int, instance: int,
                attribute: int | None = None) -> bytes:
        """Encoded Message Router request without data (built once per target)."""
        key = (service, class_id, instance, attribute)
        raw = self._messages.get(key)
        if raw is None:
            raw = self._messages[key] = commands.make_message(service, class_id, instance,
                                                              attribute)
        return raw

    async def get_attribute_single(self, class_id: int, instance: int, attribute: int, *,
                                   timeout: float | None = None,
                                   retries: int | None = None) -> bytes:
        message = self.message(Service.GET_ATTRIBUTE_SINGLE, class_id, instance, attribute)
        return await self._read(message, timeout, retries)

    async def set_attribute_single(self, class_id: int, instance: int, attribute: int,
                                   data: bytes, *, timeout: float | None = None) -> None:
        message = self.message(Service.SET_ATTRIBUTE_SINGLE, class_id, instance, attribute)
        await self.call(message + data, read=False, timeout=timeout)

    async def get_attributes_all(self, class_id: int, instance: int, *,
                                 timeout: float | None = None) -> bytes:
        message = self.message(Service.GET_ATTRIBUTES_ALL, class_id, instance)
        return await self._read(message, timeout, None)

    async def list_identity(self, timeout: float | None = None) -> discovery.IdentityItem:
        """ListIdentity over this TCP connection (a read: retried)."""
        reply = await self._exchange(Command.LIST_IDENTITY, b"", read=True, timeout=timeout)
        if reply.status != EncapStatus.SUCCESS:
            raise ProtocolError(f"ListIdentity answered status 0x{reply.status:04X}")
        return discovery.decode_identity_reply(reply.data)

    def __repr__(self) -> str:
        return f"<AsyncEnipClient {self.host}:{self.port} session 0x{self.session:08X}>"


def _describe_context(context: bytes) -> str:
    return f"the reply with sender context {context.hex()}"


def _trace_item(packet: bytes) -> object:
    """What trace hooks get for a request: the decoded Message Router request of a
    SendRRData, else the encapsulation packet."""
    try:
        pkt = EncapPacket.decode(packet)
        if pkt.command == Command.SEND_RR_DATA:
            items = RRData.decode(pkt.data).items
            return MessageRouterRequest.decode(UnconnectedMessage.from_items(items).message)
        return pkt
    except FramingError as exc:
        return exc


def describe(message: bytes) -> str:
    """``Set_Attribute_Single class 0x0F instance 0x04 attribute 1`` for error messages."""
    try:
        req = MessageRouterRequest.decode(message)
        target = request_target(req.path)
    except FramingError:
        return f"request {message[:8].hex(' ')}"
    try:
        name = Service(req.service).name.title()
    except ValueError:
        name = f"service 0x{req.service:02X}"
    where = f"class 0x{target.class_id:02X} instance 0x{target.instance:02X}"
    return f"{name} {where}" + ("" if target.attribute is None else
                                f" attribute {target.attribute}")
