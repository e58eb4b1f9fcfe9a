"""asyncio EtherNet/IP explicit-messaging client: one TCP session to one adapter (docs/enip.md).

The DYN5 answers unconnected explicit messages only (manual 1: "Explicit messaging is
Unconnected"): every request is a SendRRData carrying a null address item and an
unconnected data item with one Message Router request. The client registers a session
(RegisterSession), then sends Get_Attribute_Single / Set_Attribute_Single /
Get_Attributes_All, and the Connection Manager's Forward_Open / Forward_Close for cyclic I/O
(:mod:`servobus.protocols.enip.scanner`). UnregisterSession on close.

Matching: every request carries its own sender context (a 64-bit counter), which the
adapter echoes (CIP Vol. 2 2-3). A reply whose context is not awaited any more (it came
after its deadline) is counted in ``stats.late_replies`` and dropped, so a late reply
never answers a later request.

Policy (:class:`RequestPolicy`, the one place to change it): each attempt has a deadline
(``timeout``, default 0.5 s: a DYN5 answers within milliseconds on a LAN, 7); reads
(Get services, ListIdentity) are retried up to ``retries`` times (default 2) with a fresh
context; a Set or a Connection Manager request is sent once and never re-sent (a resend
could move twice). Errors are typed: no reply -> DriveTimeout; a refused request (CIP
general status, e.g. the DYN5's "05 error") -> DriveError with ``code`` = the general
status; a bad encapsulation status or malformed reply -> ProtocolError; the TCP
connection gone -> ConnectionLost, at once for a waiting request and for every call after.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass

from servobus.axis import checks
from servobus.errors import (
    ConnectionLost,
    DriveError,
    DriveTimeout,
    FramingError,
    ProtocolError,
    ServobusError,
)
from servobus.protocols.enip import discovery, epath
from servobus.protocols.enip.cip import (
    GeneralStatus,
    MessageRouterRequest,
    MessageRouterResponse,
    Service,
    request_target,
)
from servobus.protocols.enip.cpf import CpfItem, ItemType, RRData, UnconnectedMessage
from servobus.protocols.enip.encap import (
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
DEFAULT_RETRIES = 2
CONNECT_TIMEOUT_S = 2.0
#: Replies are small; a bound well above any DYN5 reply keeps the framer's memory bounded.
MAX_REPLY_DATA = 4096
_CONTEXT = struct.Struct("<Q")
_ITEM = struct.Struct("<HH")
#: SendRRData data before the message: interface handle 0, timeout 0 (the encapsulation
#: layer adds no timeout of its own), 2 items, null address item (type 0, length 0).
_RR_HEAD = struct.pack("<IHH", 0, 0, 2) + _ITEM.pack(ItemType.NULL_ADDRESS, 0)
_READ_SERVICES = frozenset({Service.GET_ATTRIBUTES_ALL, Service.GET_ATTRIBUTE_SINGLE})

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


@dataclass
class ClientStats:
    requests: int = 0
    replies: int = 0
    retries: int = 0
    timeouts: int = 0
    late_replies: int = 0
    refused: int = 0


class RequestPolicy:
    """Per-attempt deadline and read retries of one client (see the module docstring).

    Kept in one class so that the policy can move to a shared transaction manager without
    touching the request path.
    """

    def __init__(self, timeout: float = DEFAULT_TIMEOUT_S, retries: int = DEFAULT_RETRIES) -> None:
        self.timeout = checks.seconds("timeout", timeout)
        self.retries = checks.count("retries", retries)

    def attempts(self, *, read: bool, retries: int | None = None) -> int:
        """1 for anything but a read; 1 + retries for a read."""
        if not read:
            return 1
        return 1 + (self.retries if retries is None else checks.count("retries", retries))

    def deadline_s(self, timeout: float | None = None) -> float:
        return self.timeout if timeout is None else checks.seconds("timeout", timeout)


def status_text(status: int) -> str:
    return STATUS_TEXT.get(status, f"CIP status 0x{status:02X}")


class AsyncEnipClient:
    """One registered session on one adapter; every method runs on one event loop."""

    def __init__(self, stream: TcpStream, host: str, port: int = TCP_PORT, *,
                 timeout: float = DEFAULT_TIMEOUT_S, retries: int = DEFAULT_RETRIES) -> None:
        self.stream = stream
        self.host = host
        self.port = port
        self.policy = RequestPolicy(timeout, retries)
        self.stats = ClientStats()
        self.session = 0
        self._framer = EncapFramer(MAX_REPLY_DATA)
        self._pending: dict[bytes, asyncio.Future[EncapPacket | None]] = {}
        self._context = 0
        self._dead: ConnectionLost | None = None
        self._hooks: list[TraceHook] = []
        self._messages: dict[tuple[int, int, int, int | None], bytes] = {}
        stream.set_receiver(self._received)

    # ---------------------------------------------------------------- lifecycle
    @classmethod
    async def connect(cls, host: str, port: int = TCP_PORT, *,
                      timeout: float = DEFAULT_TIMEOUT_S, retries: int = DEFAULT_RETRIES,
                      connect_timeout: float = CONNECT_TIMEOUT_S) -> AsyncEnipClient:
        """Open TCP and register a session. Nothing listening, or no answer within
        ``connect_timeout``: DriveTimeout naming the address (nothing was sent)."""
        RequestPolicy(timeout, retries)  # checked before anything is opened
        checks.seconds("connect_timeout", connect_timeout)
        try:
            stream = await TcpStream.connect(host, port, timeout=connect_timeout)
        except ServobusError as exc:
            reason = exc.__cause__ if exc.__cause__ is not None else exc
            text = str(reason) or type(reason).__name__
            raise DriveTimeout(f"no EtherNet/IP adapter answers at {host}:{port} ({text})"
                               ) from exc
        client = cls(stream, host, port, timeout=timeout, retries=retries)
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
        return self._dead is not None

    async def close(self) -> None:
        """UnregisterSession (no reply is sent by the target), then close; idempotent."""
        if self._dead is not None:
            return
        if self.session:
            with contextlib.suppress(ServobusError):
                await self.stream.write(self._packet(Command.UNREGISTER_SESSION, b""))
        self._die(ConnectionLost(f"connection to {self.host}:{self.port} is closed"))
        await self.stream.close()

    def _die(self, error: ConnectionLost) -> None:
        if self._dead is None:
            self._dead = error
        pending, self._pending = self._pending, {}
        for fut in pending.values():
            if not fut.done():
                fut.set_exception(self._dead)

    # ---------------------------------------------------------------- tracing
    def add_trace(self, hook: TraceHook) -> None:
        """``hook(direction, item, t)``: each Message Router request/response (decoded) and
        each encapsulation packet of another kind."""
        self._hooks.append(hook)

    def _trace(self, direction: Direction, item: object) -> None:
        t = time.monotonic()
        for hook in self._hooks:
            hook(direction, item, t)

    # ---------------------------------------------------------------- reception
    def _received(self, data: bytes | None) -> None:
        if data is None:
            self._die(ConnectionLost(f"{self.host}:{self.port} closed the connection"))
            return
        for item in self._framer.feed(data):
            if isinstance(item, EncapReject):
                fut = self._pending.pop(item.header.context, None)
                if fut is not None and not fut.done():
                    fut.set_exception(FramingError(
                        f"reply of {item.header.length} bytes exceeds {MAX_REPLY_DATA}"))
                continue
            fut = self._pending.pop(item.context, None)
            if fut is None or fut.done():
                self.stats.late_replies += 1
                log.debug("late or unsolicited reply (command 0x%04X) dropped", item.command)
                continue
            fut.set_result(item)

    # ---------------------------------------------------------------- requests
    def _packet(self, command: int, data: bytes, context: bytes = bytes(8)) -> bytes:
        return HEADER.pack(command, len(data), self.session, 0, context, 0) + data

    def _next_context(self) -> bytes:
        self._context = (self._context + 1) & 0xFFFF_FFFF_FFFF_FFFF
        return _CONTEXT.pack(self._context)

    async def _exchange(self, command: int, data: bytes, *, read: bool,
                        timeout: float | None = None, retries: int | None = None,
                        what: str = "") -> EncapPacket:
        """Send one encapsulation packet and wait for the reply with its context."""
        if self._dead is not None:
            raise ConnectionLost(str(self._dead))
        attempts = self.policy.attempts(read=read, retries=retries)
        deadline_s = self.policy.deadline_s(timeout)
        loop = asyncio.get_running_loop()
        for attempt in range(attempts):
            if attempt:
                self.stats.retries += 1
                log.debug("retry %d of %s", attempt, what or f"command 0x{command:04X}")
            context = self._next_context()
            fut: asyncio.Future[EncapPacket | None] = loop.create_future()
            self._pending[context] = fut
            timer = loop.call_later(deadline_s, _expire, fut)
            try:
                await self.stream.write(self._packet(command, data, context))
                reply = await fut
            except OSError as exc:
                error = ConnectionLost(f"{self.host}:{self.port}: {exc}")
                self._die(error)
                raise error from exc
            finally:
                timer.cancel()
                self._pending.pop(context, None)
            if reply is not None:
                return reply
            self.stats.timeouts += 1
        detail = what or f"encapsulation command 0x{command:04X}"
        sent = (f"{attempts} attempt(s)" if read else
                "sent once and not re-sent (it may have been carried out)")
        raise DriveTimeout(f"no reply from {self.host}:{self.port} to {detail} within "
                           f"{deadline_s:g} s ({sent})")

    def _rr_data(self, message: bytes, extra: tuple[CpfItem, ...]) -> bytes:
        data = _RR_HEAD + _ITEM.pack(ItemType.UNCONNECTED_DATA, len(message)) + message
        if not extra:
            return data
        out = bytearray(data)
        out[6:8] = struct.pack("<H", 2 + len(extra))  # the CPF item count
        for item in extra:
            out += _ITEM.pack(item.type_id, len(item.data)) + item.data
        return bytes(out)

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
            read = service in _READ_SERVICES
        self.stats.requests += 1
        if self._hooks:
            self._trace(Direction.TX, _decoded_request(message))
        reply = await self._exchange(Command.SEND_RR_DATA, self._rr_data(message, extra),
                                     read=read, timeout=timeout, retries=retries,
                                     what=f"service 0x{service:02X}")
        if reply.status != EncapStatus.SUCCESS:
            raise ProtocolError(f"{self.host}:{self.port} answered encapsulation status "
                                f"0x{reply.status:04X} to a SendRRData")
        try:
            items = RRData.decode(reply.data).items
            unconnected = UnconnectedMessage.from_items(items)
            response = MessageRouterResponse.decode(unconnected.message)
        except FramingError as exc:
            raise FramingError(f"malformed SendRRData reply from {self.host}: {exc}") from None
        if response.service != service:
            raise ProtocolError(f"reply to service 0x{response.service:02X}, expected "
                                f"0x{service:02X}")
        self.stats.replies += 1
        if self._hooks:
            self._trace(Direction.RX, response)
        return response, unconnected

    async def call(self, message: bytes, *, read: bool | None = None,
                   timeout: float | None = None, retries: int | None = None) -> bytes:
        """:meth:`request`, then the response data; DriveError when the target refuses."""
        response, _ = await self.request(message, read=read, timeout=timeout, retries=retries)
        if not response.ok:
            self.stats.refused += 1
            raise DriveError(f"{self.host} refused {describe(message)}: "
                             f"{status_text(response.general_status)}",
                             code=response.general_status)
        return response.data

    def message(self, service: int, class_id: int, instance: int,
                attribute: int | None = None) -> bytes:
        """Encoded Message Router request without data (built once per target)."""
        key = (service, class_id, instance, attribute)
        raw = self._messages.get(key)
        if raw is None:
            path = epath.request_path(class_id, instance, attribute)
            raw = self._messages[key] = MessageRouterRequest(service, path).encode()
        return raw

    async def get_attribute_single(self, class_id: int, instance: int, attribute: int, *,
                                   timeout: float | None = None,
                                   retries: int | None = None) -> bytes:
        message = self.message(Service.GET_ATTRIBUTE_SINGLE, class_id, instance, attribute)
        return await self.call(message, timeout=timeout, retries=retries)

    async def set_attribute_single(self, class_id: int, instance: int, attribute: int,
                                   data: bytes, *, timeout: float | None = None) -> None:
        message = self.message(Service.SET_ATTRIBUTE_SINGLE, class_id, instance, attribute)
        await self.call(message + data, read=False, timeout=timeout)

    async def get_attributes_all(self, class_id: int, instance: int, *,
                                 timeout: float | None = None) -> bytes:
        message = self.message(Service.GET_ATTRIBUTES_ALL, class_id, instance)
        return await self.call(message, timeout=timeout)

    async def list_identity(self, timeout: float | None = None) -> discovery.IdentityItem:
        """ListIdentity over this TCP connection (a read: retried)."""
        reply = await self._exchange(Command.LIST_IDENTITY, b"", read=True, timeout=timeout,
                                     what="ListIdentity")
        if reply.status != EncapStatus.SUCCESS:
            raise ProtocolError(f"ListIdentity answered status 0x{reply.status:04X}")
        return discovery.decode_identity_reply(reply.data)

    def __repr__(self) -> str:
        return f"<AsyncEnipClient {self.host}:{self.port} session 0x{self.session:08X}>"


def _expire(fut: asyncio.Future[EncapPacket | None]) -> None:
    if not fut.done():
        fut.set_result(None)


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


def _decoded_request(message: bytes) -> object:
    try:
        return MessageRouterRequest.decode(message)
    except FramingError as exc:
        return exc
