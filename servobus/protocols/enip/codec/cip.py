"""CIP Message Router request/response (CIP Vol. 1 2-4): bytes <-> frozen dataclasses. Pure.

Request: service, path size (words), padded EPATH, service data.
Response: service | 0x80, reserved 0, general status, additional status size (words),
additional status words, response data.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum

from servobus.errors import FramingError
from servobus.protocols.enip.codec import epath
from servobus.protocols.enip.codec.epath import LogicalSegment, LogicalType, Segment

REPLY_FLAG = 0x80


class Service(IntEnum):
    GET_ATTRIBUTES_ALL = 0x01
    RESET = 0x05
    GET_ATTRIBUTE_SINGLE = 0x0E
    SET_ATTRIBUTE_SINGLE = 0x10
    FORWARD_CLOSE = 0x4E
    UNCONNECTED_SEND = 0x52
    FORWARD_OPEN = 0x54
    LARGE_FORWARD_OPEN = 0x5B


class ClassCode(IntEnum):
    IDENTITY = 0x01
    MESSAGE_ROUTER = 0x02
    ASSEMBLY = 0x04
    CONNECTION_MANAGER = 0x06
    PARAMETER = 0x0F


class GeneralStatus(IntEnum):
    SUCCESS = 0x00
    CONNECTION_FAILURE = 0x01  # Connection Manager: extended status follows
    RESOURCE_UNAVAILABLE = 0x02
    PATH_SEGMENT_ERROR = 0x04
    PATH_DESTINATION_UNKNOWN = 0x05  # the DYN5's "05 error" for everything it refuses
    SERVICE_NOT_SUPPORTED = 0x08
    NOT_ENOUGH_DATA = 0x13
    ATTRIBUTE_NOT_SUPPORTED = 0x14
    TOO_MUCH_DATA = 0x15
    OBJECT_DOES_NOT_EXIST = 0x16


@dataclass(frozen=True)
class MessageRouterRequest:
    service: int
    path: tuple[Segment, ...]
    data: bytes = b""

    def encode(self) -> bytes:
        if not 0 <= self.service < REPLY_FLAG:
            raise FramingError(f"service 0x{self.service:02X} is not a request service")
        return bytes((self.service,)) + epath.encode_sized_path(self.path) + self.data

    @classmethod
    def decode(cls, raw: bytes) -> MessageRouterRequest:
        if len(raw) < 2:
            raise FramingError(f"a Message Router request needs 2 bytes, got {len(raw)}")
        service, words = raw[0], raw[1]
        if service & REPLY_FLAG:
            raise FramingError(f"0x{service:02X} is a reply service code")
        end = 2 + 2 * words
        if end > len(raw):
            raise FramingError(f"request path of {words} word(s) exceeds the {len(raw)} bytes")
        return cls(service, epath.decode_path(raw[2:end]), bytes(raw[end:]))


@dataclass(frozen=True)
class MessageRouterResponse:
    service: int  # the request's service code (the wire carries service | 0x80)
    general_status: int = GeneralStatus.SUCCESS
    additional_status: tuple[int, ...] = field(default=())
    data: bytes = b""

    @property
    def ok(self) -> bool:
        return self.general_status == GeneralStatus.SUCCESS

    def encode(self) -> bytes:
        if not 0 <= self.service < REPLY_FLAG or not 0 <= self.general_status <= 0xFF:
            raise FramingError("service or general status out of range")
        if len(self.additional_status) > 0xFF:
            raise FramingError("too many additional status words")
        head = bytes((self.service | REPLY_FLAG, 0, self.general_status,
                      len(self.additional_status)))
        extra = struct.pack(f"<{len(self.additional_status)}H", *self.additional_status)
        return head + extra + self.data

    @classmethod
    def decode(cls, raw: bytes) -> MessageRouterResponse:
        if len(raw) < 4:
            raise FramingError(f"a Message Router response needs 4 bytes, got {len(raw)}")
        if not raw[0] & REPLY_FLAG:
            raise FramingError(f"0x{raw[0]:02X} is not a reply service code")
        n = raw[3]
        end = 4 + 2 * n
        if end > len(raw):
            raise FramingError("additional status exceeds the response")
        extra = struct.unpack_from(f"<{n}H", raw, 4)
        return cls(raw[0] & ~REPLY_FLAG & 0xFF, raw[2], tuple(extra), bytes(raw[end:]))


@dataclass(frozen=True)
class RequestTarget:
    """class / instance / optional attribute of a Message Router request path."""

    class_id: int
    instance: int
    attribute: int | None = None


def request_target(path: tuple[Segment, ...]) -> RequestTarget:
    """Interpret a request path as class, instance[, attribute].

    Decision: any other shape (no instance, port or key segments, repeated kinds) is a
    path syntax error (general status 0x04) rather than an unknown object (0x05)."""
    kinds = [s.kind for s in path if isinstance(s, LogicalSegment)]
    if len(kinds) != len(path) or kinds[:2] != [LogicalType.CLASS, LogicalType.INSTANCE]:
        raise FramingError("request path is not class / instance [/ attribute]")
    segs = [s for s in path if isinstance(s, LogicalSegment)]
    if len(segs) == 2:
        return RequestTarget(segs[0].value, segs[1].value)
    if len(segs) == 3 and segs[2].kind is LogicalType.ATTRIBUTE:
        return RequestTarget(segs[0].value, segs[1].value, segs[2].value)
    raise FramingError("request path is not class / instance [/ attribute]")


def error_response(request_service: int, status: int, *extra: int) -> MessageRouterResponse:
    return MessageRouterResponse(request_service & 0x7F, status, tuple(extra))
