"""EasyCan frames <-> messages (YZ-AIM manual 5.3). Pure: (arbitration id, data) both ways.

Host side: :func:`encode` requests, :func:`decode_reply` replies. Drive side (the virtual
motor): :func:`decode_request`, then :func:`encode` its reply. :func:`decode` infers the
direction from the identifier for sniffing. Malformed frames raise FramingError;
:class:`MalformedRequest` (a FramingError) also names the error reply the drive sends.
Lengths come from the one table, ``functions.SPECS``.
"""

from __future__ import annotations

import struct

from servobus.errors import ArgumentRangeError, FramingError
from servobus.protocols.easycan.functions import (
    ADDRESS_MASK,
    CLEAR_POSITION_SENT,
    ERROR_FLAG,
    ERROR_LENGTH,
    HEADER,
    HOST_ADDRESS,
    MAX_ARBITRATION_ID,
    MAX_DATA,
    MAX_SLAVE_ADDRESS,
    POSITION_BYTES,
    SPECS,
    CacheKind,
    ErrorCode,
    Function,
)
from servobus.protocols.easycan.messages import (
    ClearPosition,
    EmergencyStop,
    EmergencyStopReply,
    ErrorReply,
    Message,
    PositionCacheWrite,
    PositionReply,
    ReadMultipleReply,
    ReadMultipleRequest,
    ReadReply,
    ReadRequest,
    Reply,
    Request,
    WriteReply,
    WriteRequest,
)

_POSITION = struct.Struct("<i")


class MalformedRequest(FramingError):
    """A request frame for a slave that names host and function but cannot be executed.

    The drive answers it with :meth:`error_reply` (illegal function or data length).
    """

    def __init__(self, message: str, slave: int, host: int, function: int,
                 code: ErrorCode) -> None:
        super().__init__(message)
        self.slave = slave
        self.host = host
        self.function = function
        self.code = code

    def error_reply(self) -> ErrorReply:
        return ErrorReply(self.slave, self.function & (ERROR_FLAG - 1), self.code, self.host)


# ------------------------------------------------------------------ words
def pack_words(words: tuple[int, ...]) -> bytes:
    """16-bit words little-endian, as this wire carries registers."""
    return b"".join(w.to_bytes(2, "little") for w in words)


def unpack_words(data: bytes) -> tuple[int, ...]:
    if len(data) % 2:
        raise FramingError(f"{len(data)} register bytes are not whole 16-bit words")
    return tuple(int.from_bytes(data[i:i + 2], "little") for i in range(0, len(data), 2))


# ------------------------------------------------------------------ encode
def arbitration_id(message: Message) -> int:
    """The identifier a message travels on: the receiver's address (cache: kind | slave)."""
    if isinstance(message, PositionCacheWrite):
        kind = CacheKind.REPLY if message.reply else CacheKind.SILENT
        return int(kind) | message.slave
    if isinstance(message, Request):
        return message.slave
    return message.host


def encode(message: Message) -> tuple[int, bytes]:
    """(arbitration id, data) ready for any CAN library."""
    return arbitration_id(message), _data(message)


def _data(m: Message) -> bytes:
    match m:
        case ReadRequest():
            return bytes((m.host, m.function, m.address, m.count))
        case WriteRequest():
            return bytes((m.host, m.function, m.address, len(m.values))) + pack_words(m.values)
        case EmergencyStop():
            return bytes((m.host, m.function))
        case ClearPosition():
            return bytes((m.host, m.function)).ljust(CLEAR_POSITION_SENT, b"\x00")
        case ReadMultipleRequest():
            return bytes((m.host, m.function, *m.addresses))
        case PositionCacheWrite() | PositionReply():
            return _POSITION.pack(m.position)
        case ReadReply() | WriteReply():
            return bytes((m.slave, m.function, m.address, len(m.values))) + pack_words(m.values)
        case EmergencyStopReply():
            return bytes((m.slave, m.function))
        case ReadMultipleReply():
            return bytes((m.slave, m.function)) + pack_words(m.values)
        case ErrorReply():
            return bytes((m.slave, m.function | ERROR_FLAG, m.code))
    raise ArgumentRangeError(f"not an EasyCan message: {m!r}")  # pragma: no cover


# ------------------------------------------------------------------ decode
def _frame(arbitration_id: int, data: bytes | bytearray) -> bytes:
    if not 0 <= arbitration_id <= MAX_ARBITRATION_ID:
        raise FramingError(f"identifier 0x{arbitration_id:x} is not an 11-bit base id")
    if len(data) > MAX_DATA:
        raise FramingError(f"{len(data)} data bytes exceed a CAN frame's {MAX_DATA}")
    return bytes(data)


def _cache_kind(arbitration_id: int) -> CacheKind | None:
    """The cache kind of an identifier, None for a plain address; FramingError otherwise."""
    high = arbitration_id & ~ADDRESS_MASK
    if high == 0:
        return None
    try:
        return CacheKind(high)
    except ValueError:
        raise FramingError(
            f"identifier 0x{arbitration_id:03x} is not EasyCan (0x0xx, 0x1xx or 0x3xx)"
        ) from None


def decode_request(arbitration_id: int, data: bytes | bytearray) -> Request:
    """A frame sent to a slave (drive side)."""
    raw = _frame(arbitration_id, data)
    kind = _cache_kind(arbitration_id)
    slave = arbitration_id & ADDRESS_MASK
    if kind is not None:
        if len(raw) != POSITION_BYTES:
            raise FramingError(f"position-cache frame needs {POSITION_BYTES} bytes, got "
                               f"{len(raw)}")
        if slave > MAX_SLAVE_ADDRESS:
            raise FramingError(f"position-cache frame to 0x{slave:02x}, the host address")
        return PositionCacheWrite(slave, _POSITION.unpack(raw)[0], kind is CacheKind.REPLY)
    if slave > MAX_SLAVE_ADDRESS:
        raise FramingError(f"identifier 0x{slave:02x} is the host's: not a request")
    if len(raw) < HEADER:
        raise FramingError(f"request with {len(raw)} data bytes has no host address and "
                           "function code")
    host, code = raw[0], raw[1]
    try:
        fn = Function(code)
    except ValueError:
        raise MalformedRequest(f"unknown function code 0x{code:02x}", slave, host, code,
                               ErrorCode.ILLEGAL_FUNCTION) from None
    if len(raw) not in SPECS[fn].request_lengths:
        raise MalformedRequest(f"{fn.name} request with {len(raw)} data bytes", slave, host,
                               fn, ErrorCode.ILLEGAL_DATA_LENGTH)
    match fn:
        case Function.READ:
            return ReadRequest(slave, raw[2], raw[3], host)
        case Function.WRITE:
            if raw[3] != (len(raw) - 4) // 2:
                raise MalformedRequest(f"WRITE counts {raw[3]} registers but carries "
                                       f"{(len(raw) - 4) // 2}", slave, host, fn,
                                       ErrorCode.ILLEGAL_DATA_LENGTH)
            return WriteRequest(slave, raw[2], unpack_words(raw[4:]), host)
        case Function.EMERGENCY_STOP:
            return EmergencyStop(slave, host)
        case Function.CLEAR_POSITION:
            return ClearPosition(slave, host)
        case Function.READ_MULTIPLE:
            return ReadMultipleRequest(slave, tuple(raw[2:]), host)
    raise FramingError(f"function {fn.name} has no decoder")  # pragma: no cover


def decode_reply(arbitration_id: int, data: bytes | bytearray,
                 position: bool | None = None) -> Reply:
    """A frame sent to the host (host side); ``arbitration_id`` is the host's address.

    ``position`` says whether a 4-byte frame is the position-cache reply (True) or a
    one-register 0x12 reply (False); None: a 4-byte frame is a position reply.
    """
    raw = _frame(arbitration_id, data)
    if _cache_kind(arbitration_id) is not None:
        raise FramingError(f"identifier 0x{arbitration_id:03x} is a position-cache request")
    host = arbitration_id
    if position or (position is None and len(raw) == POSITION_BYTES):
        if len(raw) != POSITION_BYTES:
            raise FramingError(f"position reply needs {POSITION_BYTES} bytes, got {len(raw)}")
        return PositionReply(_POSITION.unpack(raw)[0], host)
    if len(raw) < HEADER:
        raise FramingError(f"reply with {len(raw)} data bytes has no slave address and "
                           "function code")
    slave, code = raw[0], raw[1]
    if slave > MAX_SLAVE_ADDRESS:
        raise FramingError(f"reply from 0x{slave:02x}, the host address")
    if code & ERROR_FLAG:
        if len(raw) != ERROR_LENGTH:
            raise FramingError(f"error reply needs {ERROR_LENGTH} bytes, got {len(raw)}")
        return ErrorReply(slave, code & (ERROR_FLAG - 1), raw[2], host)
    try:
        fn = Function(code)
    except ValueError:
        raise FramingError(f"reply with unknown function code 0x{code:02x}") from None
    if len(raw) not in SPECS[fn].reply_lengths:
        raise FramingError(f"{fn.name} reply with {len(raw)} data bytes")
    match fn:
        case Function.READ | Function.WRITE:
            words = unpack_words(raw[4:])
            if raw[3] != len(words):
                raise FramingError(f"{fn.name} reply counts {raw[3]} registers but carries "
                                   f"{len(words)}")
            cls = ReadReply if fn is Function.READ else WriteReply
            return cls(slave, raw[2], words, host)
        case Function.EMERGENCY_STOP:
            return EmergencyStopReply(slave, host)
        case Function.READ_MULTIPLE:
            return ReadMultipleReply(slave, unpack_words(raw[2:]), host)
    raise FramingError(f"function {fn.name} has no reply decoder")  # pragma: no cover


def decode(arbitration_id: int, data: bytes | bytearray, position: bool | None = None,
           host: int = HOST_ADDRESS) -> Message:
    """Either direction, told apart by the identifier (sniffing): ``host``'s id = reply."""
    if arbitration_id == host:
        return decode_reply(arbitration_id, data, position)
    return decode_request(arbitration_id, data)


# ------------------------------------------------------------------ transaction helpers
def expects_reply(request: Request) -> bool:
    if isinstance(request, PositionCacheWrite):
        return request.reply
    return SPECS[request.function].expects_reply


def answers(request: Request, reply: Reply) -> bool:
    """Is ``reply`` (a normal or an error reply) the answer to ``request``?"""
    if isinstance(request, PositionCacheWrite):
        return request.reply and isinstance(reply, PositionReply)
    if isinstance(reply, PositionReply) or reply.host != request.host:
        return False
    if reply.slave != request.slave:
        return False
    if isinstance(reply, ErrorReply):
        return reply.function == request.function
    match request, reply:
        case ReadRequest(), ReadReply():
            return (reply.address, len(reply.values)) == (request.address, request.count)
        case WriteRequest(), WriteReply():
            return (reply.address, len(reply.values)) == (request.address,
                                                          len(request.values))
        case EmergencyStop(), EmergencyStopReply():
            return True
        case ReadMultipleRequest(), ReadMultipleReply():
            return len(reply.values) == len(request.addresses)
    return False


def reply_is_position(request: Request) -> bool:
    """The ``position`` argument of :func:`decode_reply` for this request's answer."""
    return isinstance(request, PositionCacheWrite)
