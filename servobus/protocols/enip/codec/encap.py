"""EtherNet/IP encapsulation (CIP Vol. 2 ch. 2): 24-byte little-endian header. Pure.

Header: command UINT, length UINT (bytes after the header), session handle UDINT, status
UDINT, sender context 8 bytes (echoed unchanged in the reply), options UDINT (must be 0).

:class:`EncapFramer` splits a TCP byte stream into packets. TCP has no sync marker, so the
framer keeps alignment by the length field: a packet whose length exceeds the bound is
reported as an :class:`EncapReject` (status 0x0065) and its data is skipped without being
buffered, so memory stays bounded whatever arrives. It never raises.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from servobus.errors import FramingError

HEADER = struct.Struct("<HHII8sI")
HEADER_SIZE = HEADER.size  # 24
CONTEXT_SIZE = 8
PROTOCOL_VERSION = 1
TCP_PORT = 44818  # explicit messaging (TCP) and ListIdentity (UDP)
#: Largest data part the adapter accepts. The DYN5's messages are tiny; 600 bytes holds
#: any request it understands (decision: CIP's 504-byte explicit message limit + CPF).
MAX_DATA = 600
_REGISTER = struct.Struct("<HH")


class Command(IntEnum):
    NOP = 0x0000
    LIST_SERVICES = 0x0004
    LIST_IDENTITY = 0x0063
    LIST_INTERFACES = 0x0064
    REGISTER_SESSION = 0x0065
    UNREGISTER_SESSION = 0x0066
    SEND_RR_DATA = 0x006F
    SEND_UNIT_DATA = 0x0070
    INDICATE_STATUS = 0x0072
    CANCEL = 0x0073


#: Commands a target answers on UDP (the rest are TCP-only).
UDP_COMMANDS = frozenset({Command.LIST_SERVICES, Command.LIST_IDENTITY,
                          Command.LIST_INTERFACES})


class EncapStatus(IntEnum):
    SUCCESS = 0x0000
    INVALID_COMMAND = 0x0001  # unsupported or invalid encapsulation command
    INSUFFICIENT_MEMORY = 0x0002
    INCORRECT_DATA = 0x0003  # poorly formed or incorrect data in the data part
    INVALID_SESSION = 0x0064
    INVALID_LENGTH = 0x0065
    UNSUPPORTED_PROTOCOL = 0x0069


@dataclass(frozen=True)
class EncapHeader:
    command: int
    length: int
    session: int = 0
    status: int = 0
    context: bytes = bytes(CONTEXT_SIZE)
    options: int = 0

    def encode(self) -> bytes:
        if len(self.context) != CONTEXT_SIZE:
            raise FramingError(f"sender context must be 8 bytes, got {len(self.context)}")
        try:
            return HEADER.pack(self.command, self.length, self.session, self.status,
                               self.context, self.options)
        except struct.error as exc:
            raise FramingError(f"encapsulation header field out of range: {exc}") from None

    @classmethod
    def decode(cls, raw: bytes) -> EncapHeader:
        if len(raw) < HEADER_SIZE:
            raise FramingError(f"encapsulation header needs 24 bytes, got {len(raw)}")
        return cls(*HEADER.unpack_from(raw))


@dataclass(frozen=True)
class EncapPacket:
    command: int
    data: bytes = b""
    session: int = 0
    status: int = 0
    context: bytes = bytes(CONTEXT_SIZE)
    options: int = 0

    @property
    def header(self) -> EncapHeader:
        return EncapHeader(self.command, len(self.data), self.session, self.status,
                           self.context, self.options)

    def encode(self) -> bytes:
        return self.header.encode() + self.data

    @classmethod
    def decode(cls, raw: bytes) -> EncapPacket:
        """One whole packet (UDP datagram or a framed TCP packet); exact length."""
        head = EncapHeader.decode(raw)
        if len(raw) != HEADER_SIZE + head.length:
            raise FramingError(f"length field {head.length} but {len(raw) - HEADER_SIZE} "
                               "data bytes")
        return cls(head.command, bytes(raw[HEADER_SIZE:]), head.session, head.status,
                   head.context, head.options)

    def reply(self, data: bytes = b"", *, status: int = EncapStatus.SUCCESS,
              session: int | None = None) -> EncapPacket:
        """The reply: same command and sender context, options 0."""
        return EncapPacket(self.command, data, self.session if session is None else session,
                           status, self.context, 0)


@dataclass(frozen=True)
class RegisterSessionData:
    version: int = PROTOCOL_VERSION
    options: int = 0

    def encode(self) -> bytes:
        return _REGISTER.pack(self.version, self.options)

    @classmethod
    def decode(cls, raw: bytes) -> RegisterSessionData:
        if len(raw) != _REGISTER.size:
            raise FramingError(f"RegisterSession data is 4 bytes, got {len(raw)}")
        return cls(*_REGISTER.unpack(raw))


@dataclass(frozen=True)
class EncapReject:
    """A header the framer could not take: its data (``length`` bytes) is skipped."""

    header: EncapHeader
    status: EncapStatus


class EncapFramer:
    """TCP stream -> packets, bounded: at most one header + ``max_data`` bytes buffered."""

    def __init__(self, max_data: int = MAX_DATA) -> None:
        self.max_data = max_data
        self._buf = bytearray()
        self._skip = 0

    @property
    def buffered(self) -> int:
        return len(self._buf)

    def feed(self, chunk: bytes) -> list[EncapPacket | EncapReject]:
        if not self._buf and not self._skip and len(chunk) >= HEADER_SIZE:
            # the common case, one whole packet in one read: no buffering
            command, length, session, status, context, options = HEADER.unpack_from(chunk)
            if len(chunk) == HEADER_SIZE + length and length <= self.max_data:
                return [EncapPacket(command, bytes(chunk[HEADER_SIZE:]), session, status,
                                    context, options)]
        out: list[EncapPacket | EncapReject] = []
        view = memoryview(chunk)
        if self._skip:
            n = min(self._skip, len(view))
            self._skip -= n
            view = view[n:]
        self._buf += view
        buf = self._buf
        pos = 0
        while len(buf) - pos >= HEADER_SIZE:
            head = EncapHeader(*HEADER.unpack_from(buf, pos))
            if head.length > self.max_data:
                out.append(EncapReject(head, EncapStatus.INVALID_LENGTH))
                pos += HEADER_SIZE
                available = len(buf) - pos
                if available >= head.length:
                    pos += head.length
                else:
                    self._skip = head.length - available
                    pos = len(buf)
                continue
            end = pos + HEADER_SIZE + head.length
            if end > len(buf):
                break
            out.append(EncapPacket(head.command, bytes(buf[pos + HEADER_SIZE:end]),
                                   head.session, head.status, head.context, head.options))
            pos = end
        if pos:
            del buf[:pos]
        return out
