"""Connection Manager services (CIP Vol. 1 3-5.4): Forward_Open 0x54, Forward_Close 0x4E,
Unconnected_Send 0x52. Service data only (the Message Router wraps it). Pure.

Forward_Open request: priority/tick, timeout ticks, O->T and T->O network connection ids,
connection serial number, originator vendor id, originator serial number (the three
together: the connection triad), timeout multiplier, 3 reserved bytes, O->T RPI (us),
O->T network parameters (WORD), T->O RPI, T->O parameters, transport type/trigger,
connection path (size in words, padded EPATH).

A failed Forward_Open / Forward_Close answers general status 0x01 with the extended
status as the first additional status word (a size mismatch adds the size the target
expects, in bytes, as a second word) and the data: triad, remaining path size, reserved.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from servobus.errors import FramingError
from servobus.protocols.enip.codec import epath
from servobus.protocols.enip.codec.epath import Segment

CONNECTION_MANAGER_PATH = epath.request_path(0x06, 1)
_OPEN = struct.Struct("<BBIIHHIB3xIHIHB")
_OPEN_REPLY = struct.Struct("<IIHHIIIBx")
_CLOSE = struct.Struct("<BBHHI")
_TRIAD = struct.Struct("<HHI")
_FAILURE = struct.Struct("<HHIBx")
_CLOSE_REPLY = struct.Struct("<HHIBx")
TIMEOUT_MULTIPLIER_MAX = 7  # the watchdog is RPI x (4 << multiplier)


class ExtendedStatus(IntEnum):
    DUPLICATE_FORWARD_OPEN = 0x0100
    TRANSPORT_NOT_SUPPORTED = 0x0103  # transport class / trigger combination
    OWNERSHIP_CONFLICT = 0x0106
    CONNECTION_NOT_FOUND = 0x0107
    INVALID_NETWORK_PARAMETER = 0x0108
    INVALID_CONNECTION_SIZE = 0x0109
    RPI_NOT_SUPPORTED = 0x0111
    OUT_OF_CONNECTIONS = 0x0113
    VENDOR_OR_PRODUCT_MISMATCH = 0x0114
    DEVICE_TYPE_MISMATCH = 0x0115
    REVISION_MISMATCH = 0x0116
    INVALID_O_T_FIXED_VARIABLE = 0x011F
    INVALID_T_O_FIXED_VARIABLE = 0x0120
    INVALID_O_T_CONNECTION_TYPE = 0x0123
    INVALID_T_O_CONNECTION_TYPE = 0x0124
    INVALID_CONFIGURATION_SIZE = 0x0126
    INVALID_O_T_SIZE = 0x0127
    INVALID_T_O_SIZE = 0x0128
    INVALID_CONFIGURATION_PATH = 0x0129
    INVALID_CONSUMING_PATH = 0x012A
    INVALID_PRODUCING_PATH = 0x012B
    NULL_FORWARD_OPEN_NOT_SUPPORTED = 0x0132
    TIMEOUT_MULTIPLIER_NOT_ACCEPTABLE = 0x0133
    CONNECTION_TIMED_OUT = 0x0203
    PARAMETER_ERROR_IN_UNCONNECTED_SEND = 0x0205
    PORT_NOT_AVAILABLE = 0x0311
    LINK_ADDRESS_NOT_VALID = 0x0312
    INVALID_SEGMENT_IN_PATH = 0x0315
    FORWARD_CLOSE_PATH_MISMATCH = 0x0316


class ConnectionType(IntEnum):
    NULL = 0
    MULTICAST = 1
    POINT_TO_POINT = 2


class Priority(IntEnum):
    LOW = 0
    HIGH = 1
    SCHEDULED = 2
    URGENT = 3


@dataclass(frozen=True)
class NetworkParameters:
    """16-bit network connection parameters; ``size`` in bytes. ``connection_type`` is the
    raw 2-bit field (3 is reserved, so it is not forced into :class:`ConnectionType`)."""

    size: int
    connection_type: int = ConnectionType.POINT_TO_POINT
    priority: Priority = Priority.SCHEDULED
    variable: bool = False
    redundant_owner: bool = False

    def to_word(self) -> int:
        if not 0 <= self.size <= 0x1FF or not 0 <= self.connection_type <= 3:
            raise FramingError(f"connection size {self.size} or type out of range")
        return (self.size | (0x200 if self.variable else 0) | (int(self.priority) << 10)
                | (int(self.connection_type) << 13) | (0x8000 if self.redundant_owner else 0))

    @classmethod
    def from_word(cls, word: int) -> NetworkParameters:
        return cls(word & 0x1FF, (word >> 13) & 0x03, Priority((word >> 10) & 0x03),
                   bool(word & 0x200), bool(word & 0x8000))


@dataclass(frozen=True)
class TransportTrigger:
    transport_class: int = 1
    trigger: int = 0  # 0 cyclic, 1 change of state, 2 application object
    server: bool = False

    def to_byte(self) -> int:
        if not 0 <= self.transport_class <= 0x0F or not 0 <= self.trigger <= 0x07:
            raise FramingError("transport class or trigger out of range")
        return self.transport_class | (self.trigger << 4) | (0x80 if self.server else 0)

    @classmethod
    def from_byte(cls, value: int) -> TransportTrigger:
        return cls(value & 0x0F, (value >> 4) & 0x07, bool(value & 0x80))


@dataclass(frozen=True)
class Triad:
    """Connection serial number, originator vendor id, originator serial number."""

    connection_serial: int
    vendor_id: int
    originator_serial: int

    def encode(self) -> bytes:
        return _pack(_TRIAD, self.connection_serial, self.vendor_id, self.originator_serial)


def _pack(st: struct.Struct, *values: int) -> bytes:
    try:
        return st.pack(*values)
    except struct.error as exc:
        raise FramingError(f"field out of range: {exc}") from None


@dataclass(frozen=True)
class ForwardOpenRequest:
    o_t_connection_id: int
    t_o_connection_id: int
    triad: Triad
    o_t_rpi_us: int
    o_t_params: int  # 16-bit network parameters word (see NetworkParameters)
    t_o_rpi_us: int
    t_o_params: int
    transport: int  # transport type/trigger byte (see TransportTrigger)
    path: tuple[Segment, ...]
    timeout_multiplier: int = 0
    priority_tick: int = 0x0A
    timeout_ticks: int = 0x0E

    def encode(self) -> bytes:
        t = self.triad
        return _pack(_OPEN, self.priority_tick, self.timeout_ticks, self.o_t_connection_id,
                     self.t_o_connection_id, t.connection_serial, t.vendor_id,
                     t.originator_serial, self.timeout_multiplier, self.o_t_rpi_us,
                     self.o_t_params, self.t_o_rpi_us, self.t_o_params,
                     self.transport) + epath.encode_sized_path(self.path)

    @classmethod
    def decode(cls, raw: bytes) -> ForwardOpenRequest:
        if len(raw) < _OPEN.size + 1:
            raise FramingError(f"Forward_Open data needs {_OPEN.size + 1} bytes, got {len(raw)}")
        (tick, ticks, ot_id, to_id, serial, vendor, oserial, mult, ot_rpi, ot_p, to_rpi,
         to_p, transport) = _OPEN.unpack_from(raw)
        words = raw[_OPEN.size]
        end = _OPEN.size + 1 + 2 * words
        if end != len(raw):
            raise FramingError(f"Forward_Open path of {words} word(s) does not match the "
                               f"{len(raw) - _OPEN.size - 1} bytes after it")
        path = epath.decode_path(raw[_OPEN.size + 1:end])
        return cls(ot_id, to_id, Triad(serial, vendor, oserial), ot_rpi, ot_p, to_rpi, to_p,
                   transport, path, mult, tick, ticks)


@dataclass(frozen=True)
class ForwardOpenReply:
    o_t_connection_id: int
    t_o_connection_id: int
    triad: Triad
    o_t_api_us: int
    t_o_api_us: int
    application_reply: bytes = b""

    def encode(self) -> bytes:
        if len(self.application_reply) % 2:
            raise FramingError("application reply must be whole 16-bit words")
        t = self.triad
        return _pack(_OPEN_REPLY, self.o_t_connection_id, self.t_o_connection_id,
                     t.connection_serial, t.vendor_id, t.originator_serial, self.o_t_api_us,
                     self.t_o_api_us, len(self.application_reply) // 2) + self.application_reply

    @classmethod
    def decode(cls, raw: bytes) -> ForwardOpenReply:
        if len(raw) < _OPEN_REPLY.size:
            raise FramingError(f"Forward_Open reply needs {_OPEN_REPLY.size} bytes")
        ot_id, to_id, serial, vendor, oserial, ot_api, to_api, words = _OPEN_REPLY.unpack_from(raw)
        app = bytes(raw[_OPEN_REPLY.size:])
        if len(app) != 2 * words:
            raise FramingError("Forward_Open reply: application reply size mismatch")
        return cls(ot_id, to_id, Triad(serial, vendor, oserial), ot_api, to_api, app)


@dataclass(frozen=True)
class ConnectionFailure:
    """Data of a failed Forward_Open / Forward_Close (general status 0x01)."""

    triad: Triad
    remaining_path_size: int = 0

    def encode(self) -> bytes:
        t = self.triad
        return _pack(_FAILURE, t.connection_serial, t.vendor_id, t.originator_serial,
                     self.remaining_path_size)

    @classmethod
    def decode(cls, raw: bytes) -> ConnectionFailure:
        if len(raw) < _FAILURE.size:
            raise FramingError(f"connection failure data needs {_FAILURE.size} bytes")
        serial, vendor, oserial, remaining = _FAILURE.unpack_from(raw)
        return cls(Triad(serial, vendor, oserial), remaining)


@dataclass(frozen=True)
class ForwardCloseRequest:
    triad: Triad
    path: tuple[Segment, ...]
    priority_tick: int = 0x0A
    timeout_ticks: int = 0x0E

    def encode(self) -> bytes:
        raw = epath.encode_path(self.path)
        t = self.triad
        return (_pack(_CLOSE, self.priority_tick, self.timeout_ticks, t.connection_serial,
                      t.vendor_id, t.originator_serial)
                + bytes((len(raw) // 2, 0)) + raw)

    @classmethod
    def decode(cls, raw: bytes) -> ForwardCloseRequest:
        if len(raw) < _CLOSE.size + 2:
            raise FramingError(f"Forward_Close data needs {_CLOSE.size + 2} bytes")
        tick, ticks, serial, vendor, oserial = _CLOSE.unpack_from(raw)
        words = raw[_CLOSE.size]
        start = _CLOSE.size + 2  # path size, reserved
        if start + 2 * words != len(raw):
            raise FramingError("Forward_Close path size does not match the data")
        return cls(Triad(serial, vendor, oserial), epath.decode_path(raw[start:]), tick, ticks)


@dataclass(frozen=True)
class ForwardCloseReply:
    triad: Triad
    application_reply: bytes = b""

    def encode(self) -> bytes:
        if len(self.application_reply) % 2:
            raise FramingError("application reply must be whole 16-bit words")
        t = self.triad
        return _pack(_CLOSE_REPLY, t.connection_serial, t.vendor_id, t.originator_serial,
                     len(self.application_reply) // 2) + self.application_reply

    @classmethod
    def decode(cls, raw: bytes) -> ForwardCloseReply:
        if len(raw) < _CLOSE_REPLY.size:
            raise FramingError(f"Forward_Close reply needs {_CLOSE_REPLY.size} bytes")
        serial, vendor, oserial, words = _CLOSE_REPLY.unpack_from(raw)
        app = bytes(raw[_CLOSE_REPLY.size:])
        if len(app) != 2 * words:
            raise FramingError("Forward_Close reply: application reply size mismatch")
        return cls(Triad(serial, vendor, oserial), app)


@dataclass(frozen=True)
class UnconnectedSendRequest:
    """Unconnected_Send: an embedded Message Router request and the route to its target."""

    message: bytes
    route: tuple[Segment, ...]
    priority_tick: int = 0x0A
    timeout_ticks: int = 0x0E

    def encode(self) -> bytes:
        if len(self.message) > 0xFFFF:
            raise FramingError("embedded message too long")
        pad = b"\0" if len(self.message) % 2 else b""
        route = epath.encode_path(self.route)
        return (bytes((self.priority_tick, self.timeout_ticks))
                + struct.pack("<H", len(self.message)) + self.message + pad
                + bytes((len(route) // 2, 0)) + route)

    @classmethod
    def decode(cls, raw: bytes) -> UnconnectedSendRequest:
        if len(raw) < 4:
            raise FramingError("Unconnected_Send data needs 4 bytes")
        (size,) = struct.unpack_from("<H", raw, 2)
        pos = 4 + size + (size % 2)
        if pos + 2 > len(raw):
            raise FramingError("Unconnected_Send embedded message truncated")
        words = raw[pos]
        end = pos + 2 + 2 * words
        if end != len(raw):
            raise FramingError("Unconnected_Send route path size does not match the data")
        return cls(bytes(raw[4:4 + size]), epath.decode_path(raw[pos + 2:end]), raw[0], raw[1])


def peek_triad(raw: bytes, offset: int) -> Triad | None:
    """The triad of a request too malformed to decode (Forward_Open: offset 10, Forward_Close:
    offset 2), so a failure reply can still name it; None when the bytes are missing."""
    if len(raw) < offset + _TRIAD.size:
        return None
    return Triad(*_TRIAD.unpack_from(raw, offset))


@dataclass(frozen=True)
class Layout:
    """Where a connection request keeps its triad and its path size (for error replies)."""

    triad_offset: int
    size_offset: int  # the path size byte (words)
    path_offset: int


FORWARD_OPEN_LAYOUT = Layout(10, _OPEN.size, _OPEN.size + 1)
FORWARD_CLOSE_LAYOUT = Layout(2, _CLOSE.size, _CLOSE.size + 2)


def watchdog_s(rpi_us: int, multiplier: int) -> float:
    """Connection timeout: RPI x 4 x 2^multiplier (CIP Vol. 1 3-4.4.x)."""
    return rpi_us * (4 << multiplier) / 1e6
