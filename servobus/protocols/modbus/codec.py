"""Modbus RTU frames (generic; no device registers here). Pure: bytes <-> frozen dataclasses.

Frame on the wire (Modbus over Serial Line v1.02 section 2.5.1; Application Protocol v1.1b3
sections 6.3, 6.6, 6.12, 7)::

    address  function  data ...  crc-lo crc-hi
    1 byte   1 byte    0..252    CRC-16/MODBUS of everything before it, low byte first

    0x03 read holding registers   request  start(2) count(2)               8 bytes
                                  reply    byte-count(1) values(2 x count)  5 + 2 x count
    0x06 write single register    request  register(2) value(2)             8 bytes
                                  reply    the same four bytes (an echo)    8 bytes
    0x10 write multiple registers request  start(2) count(2) byte-count(1) values  9 + 2 x count
                                  reply    start(2) count(2)                8 bytes
    exception reply               function | 0x80, exception code(1)       5 bytes

Register addresses, counts and values are big-endian 16-bit words on this wire. How a device
combines two registers into a 32-bit value (YZ-AIM: low word at the lower address) is the
device family's business, not the codec's.

Decisions where the Modbus standard and spec 004 leave room (docs/modbus.md for users):

* Addresses 0..255 are encoded and decoded; 0 is broadcast (no reply). The standard reserves
  248..255, but the YZ-AIM address register (0x15) allows 0..255, so the codec does not refuse
  them.
* The decoders check structure (lengths, byte counts, CRC) and nothing else: a request whose
  count is out of the standard's range still decodes, so a server can answer it with exception
  3 (:func:`request_exception`). The encoders refuse anything out of range
  (:class:`ArgumentRangeError`, nothing is sent).
* A write-single reply is an echo in the standard; :func:`decode_reply` checks that it names
  the written register but returns the value as received and does not require it to equal the
  written one (the YZ-AIM EasyCan twin of this write returns the current position for
  registers 0x0C and 0x16, spec 004 section V.3.b; the serial side is undocumented).
* A request frame with a function other than 0x03/0x06/0x10 and a good CRC decodes to
  :class:`UnsupportedRequest` (answered with exception 1); the frame is whatever the silence
  delimited, so only the gap framer can deliver one.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar

from servobus.errors import ArgumentRangeError, ChecksumError, FramingError, ProtocolError
from servobus.protocols.modbus.crc import crc16, crc_ok, with_crc

BROADCAST = 0
MAX_ADDRESS = 0xFF
WORD_MAX = 0xFFFF
MAX_READ_COUNT = 125  # Application Protocol 6.3: 1..0x7D registers per read
MAX_WRITE_COUNT = 123  # Application Protocol 6.12: 1..0x7B registers per write
MAX_FRAME = 256  # Serial Line 2.5.1: the RTU ADU holds at most 256 bytes
EXCEPTION_FLAG = 0x80
EXCEPTION_FRAME_LENGTH = 5
FIXED_FRAME_LENGTH = 8  # read request, write-single request and reply, write-multiple reply
MIN_FRAME = 4  # address, function, CRC


class Function(IntEnum):
    """The function codes servobus speaks."""

    READ_HOLDING_REGISTERS = 0x03
    WRITE_SINGLE_REGISTER = 0x06
    WRITE_MULTIPLE_REGISTERS = 0x10


class ExceptionCode(IntEnum):
    """Exception codes of the Modbus Application Protocol, section 7."""

    ILLEGAL_FUNCTION = 0x01
    ILLEGAL_DATA_ADDRESS = 0x02
    ILLEGAL_DATA_VALUE = 0x03
    SERVER_DEVICE_FAILURE = 0x04
    ACKNOWLEDGE = 0x05
    SERVER_DEVICE_BUSY = 0x06
    MEMORY_PARITY_ERROR = 0x08
    GATEWAY_PATH_UNAVAILABLE = 0x0A
    GATEWAY_TARGET_FAILED = 0x0B


#: One line per exception code: what the standard says it means.
EXCEPTION_TEXT: dict[int, str] = {
    ExceptionCode.ILLEGAL_FUNCTION: "function code not supported by the device",
    ExceptionCode.ILLEGAL_DATA_ADDRESS: "register address (or address + count) not allowed",
    ExceptionCode.ILLEGAL_DATA_VALUE: "value in the request not allowed (count, byte count)",
    ExceptionCode.SERVER_DEVICE_FAILURE: "unrecoverable error while performing the action",
    ExceptionCode.ACKNOWLEDGE: "accepted, still processing a long action",
    ExceptionCode.SERVER_DEVICE_BUSY: "busy with a long action; retry later",
    ExceptionCode.MEMORY_PARITY_ERROR: "parity error in extended memory",
    ExceptionCode.GATEWAY_PATH_UNAVAILABLE: "gateway has no path to the target",
    ExceptionCode.GATEWAY_TARGET_FAILED: "gateway target did not respond",
}

FUNCTION_TEXT: dict[int, str] = {
    Function.READ_HOLDING_REGISTERS: "read holding registers",
    Function.WRITE_SINGLE_REGISTER: "write single register",
    Function.WRITE_MULTIPLE_REGISTERS: "write multiple registers",
}


def exception_name(code: int) -> str:
    """``ILLEGAL_DATA_ADDRESS`` for 2; ``code 0x..`` for codes the standard does not name."""
    try:
        return ExceptionCode(code).name
    except ValueError:
        return f"code 0x{code:02X}"


def function_name(function: int) -> str:
    return FUNCTION_TEXT.get(function, f"function 0x{function:02X}")


# ---------------------------------------------------------------- requests (host -> device)


@dataclass(frozen=True)
class ReadHoldingRequest:
    address: int
    start: int
    count: int
    function: ClassVar[Function] = Function.READ_HOLDING_REGISTERS


@dataclass(frozen=True)
class WriteSingleRequest:
    address: int
    register: int
    value: int
    function: ClassVar[Function] = Function.WRITE_SINGLE_REGISTER


@dataclass(frozen=True)
class WriteMultipleRequest:
    address: int
    start: int
    values: tuple[int, ...]
    function: ClassVar[Function] = Function.WRITE_MULTIPLE_REGISTERS

    @property
    def count(self) -> int:
        return len(self.values)


@dataclass(frozen=True)
class UnsupportedRequest:
    """A well-formed frame (good CRC) with a function code servobus does not implement."""

    address: int
    function: int
    data: bytes


Request = ReadHoldingRequest | WriteSingleRequest | WriteMultipleRequest


# ------------------------------------------------------------------ replies (device -> host)


@dataclass(frozen=True)
class ReadHoldingReply:
    address: int
    values: tuple[int, ...]
    function: ClassVar[Function] = Function.READ_HOLDING_REGISTERS


@dataclass(frozen=True)
class WriteSingleReply:
    address: int
    register: int
    value: int
    function: ClassVar[Function] = Function.WRITE_SINGLE_REGISTER


@dataclass(frozen=True)
class WriteMultipleReply:
    address: int
    start: int
    count: int
    function: ClassVar[Function] = Function.WRITE_MULTIPLE_REGISTERS


@dataclass(frozen=True)
class ExceptionReply:
    """``function`` is the request's function code (without the 0x80 flag)."""

    address: int
    function: int
    code: int

    @property
    def name(self) -> str:
        return exception_name(self.code)


Reply = ReadHoldingReply | WriteSingleReply | WriteMultipleReply | ExceptionReply
Frame = Request | UnsupportedRequest | Reply


# ------------------------------------------------------------------------------- encoding


def _check(what: str, value: int, low: int, high: int) -> None:
    if not low <= value <= high:
        raise ArgumentRangeError(f"{what} {value} is outside {low}..{high}")


def _words(values: tuple[int, ...] | list[int]) -> bytes:
    for v in values:
        _check("register value", v, 0, WORD_MAX)
    return b"".join(v.to_bytes(2, "big") for v in values)


def _frame(address: int, function: int, body: bytes) -> bytes:
    _check("device address", address, 0, MAX_ADDRESS)
    return with_crc(bytes((address, function)) + body)


def _span(start: int, count: int, maximum: int) -> None:
    _check("register address", start, 0, WORD_MAX)
    _check("register count", count, 1, maximum)
    _check("last register address", start + count - 1, 0, WORD_MAX)


def encode_request(request: Request | UnsupportedRequest) -> bytes:
    """The RTU frame of ``request``; ArgumentRangeError for anything out of range."""
    match request:
        case ReadHoldingRequest(address, start, count):
            _span(start, count, MAX_READ_COUNT)
            body = start.to_bytes(2, "big") + count.to_bytes(2, "big")
        case WriteSingleRequest(address, register, value):
            _check("register address", register, 0, WORD_MAX)
            body = register.to_bytes(2, "big") + _words([value])
        case WriteMultipleRequest(address, start, values):
            _span(start, len(values), MAX_WRITE_COUNT)
            body = (start.to_bytes(2, "big") + len(values).to_bytes(2, "big")
                    + bytes((2 * len(values),)) + _words(values))
        case UnsupportedRequest(address, function, data):
            _check("function code", function, 0, 0xFF)
            _check("frame length", len(data) + MIN_FRAME, MIN_FRAME, MAX_FRAME)
            body = bytes(data)
        case _:
            raise ArgumentRangeError(f"not a Modbus request: {request!r}")
    return _frame(address, request.function, body)


def encode_reply(reply: Reply) -> bytes:
    """The RTU frame of ``reply``; ArgumentRangeError for anything out of range."""
    match reply:
        case ReadHoldingReply(address, values):
            _check("register count", len(values), 1, MAX_READ_COUNT)
            body = bytes((2 * len(values),)) + _words(values)
        case WriteSingleReply(address, register, value):
            _check("register address", register, 0, WORD_MAX)
            body = register.to_bytes(2, "big") + _words([value])
        case WriteMultipleReply(address, start, count):
            _span(start, count, MAX_WRITE_COUNT)
            body = start.to_bytes(2, "big") + count.to_bytes(2, "big")
        case ExceptionReply(address, function, code):
            _check("function code", function, 0, 0x7F)
            _check("exception code", code, 0, 0xFF)
            return _frame(address, function | EXCEPTION_FLAG, bytes((code,)))
        case _:
            raise ArgumentRangeError(f"not a Modbus reply: {reply!r}")
    return _frame(address, reply.function, body)


# ------------------------------------------------------------------------------- decoding


def _bytes(frame: bytes | bytearray | memoryview) -> bytes:
    raw = frame if type(frame) is bytes else bytes(frame)
    if not MIN_FRAME <= len(raw) <= MAX_FRAME:
        raise FramingError(f"frame length {len(raw)} is outside {MIN_FRAME}..{MAX_FRAME}: "
                           f"{raw.hex(' ')}")
    if not crc_ok(raw):
        got = int.from_bytes(raw[-2:], "little")
        raise ChecksumError(f"CRC 0x{got:04X} != 0x{crc16(raw[:-2]):04X} in {raw.hex(' ')}", raw)
    return raw


def _length(raw: bytes, expected: int, what: str) -> None:
    if len(raw) != expected:
        raise FramingError(f"{what} is {expected} bytes long, got {len(raw)}: {raw.hex(' ')}")


def _u16(raw: bytes, at: int) -> int:
    return (raw[at] << 8) | raw[at + 1]


def _values(raw: bytes, at: int, count: int) -> tuple[int, ...]:
    return tuple(_u16(raw, at + 2 * i) for i in range(count))


def decode_request(frame: bytes | bytearray | memoryview) -> Request | UnsupportedRequest:
    """Decode one request frame (device side); FramingError or ChecksumError if malformed."""
    raw = _bytes(frame)
    address, function = raw[0], raw[1]
    if function == Function.READ_HOLDING_REGISTERS:
        _length(raw, FIXED_FRAME_LENGTH, "a read request")
        return ReadHoldingRequest(address, _u16(raw, 2), _u16(raw, 4))
    if function == Function.WRITE_SINGLE_REGISTER:
        _length(raw, FIXED_FRAME_LENGTH, "a write-single request")
        return WriteSingleRequest(address, _u16(raw, 2), _u16(raw, 4))
    if function == Function.WRITE_MULTIPLE_REGISTERS:
        if len(raw) < 9:
            raise FramingError(f"write-multiple request too short: {raw.hex(' ')}")
        count, byte_count = _u16(raw, 4), raw[6]
        _length(raw, 9 + byte_count, "a write-multiple request with this byte count")
        if byte_count != 2 * count:
            raise FramingError(f"byte count {byte_count} != 2 x {count} registers: "
                               f"{raw.hex(' ')}")
        return WriteMultipleRequest(address, _u16(raw, 2), _values(raw, 7, count))
    if function & EXCEPTION_FLAG:
        raise FramingError(f"an exception reply is not a request: {raw.hex(' ')}")
    return UnsupportedRequest(address, function, raw[2:-2])


def _decode_reply_any(raw: bytes, function: int) -> Reply:
    address = raw[0]
    if raw[1] == function | EXCEPTION_FLAG:
        _length(raw, EXCEPTION_FRAME_LENGTH, "an exception reply")
        return ExceptionReply(address, function, raw[2])
    if raw[1] != function:
        raise ProtocolError(f"reply function 0x{raw[1]:02X} answers neither 0x{function:02X} "
                            f"nor its exception: {raw.hex(' ')}")
    if function == Function.READ_HOLDING_REGISTERS:
        byte_count = raw[2]
        _length(raw, 5 + byte_count, "a read reply with this byte count")
        if byte_count % 2:
            raise FramingError(f"odd byte count {byte_count} in a read reply: {raw.hex(' ')}")
        return ReadHoldingReply(address, _values(raw, 3, byte_count // 2))
    if function == Function.WRITE_SINGLE_REGISTER:
        _length(raw, FIXED_FRAME_LENGTH, "a write-single reply")
        return WriteSingleReply(address, _u16(raw, 2), _u16(raw, 4))
    if function == Function.WRITE_MULTIPLE_REGISTERS:
        _length(raw, FIXED_FRAME_LENGTH, "a write-multiple reply")
        return WriteMultipleReply(address, _u16(raw, 2), _u16(raw, 4))
    raise ProtocolError(f"function 0x{function:02X} is not one servobus speaks")


def decode_reply(frame: bytes | bytearray | memoryview, request: Request) -> Reply:
    """Decode the reply to ``request`` (host side, one request outstanding).

    FramingError/ChecksumError for a malformed frame; ProtocolError for a well-formed frame
    that does not answer ``request`` (another address, function, register or count). An
    exception reply decodes to :class:`ExceptionReply` (the caller raises on it).
    """
    raw = _bytes(frame)
    if raw[0] != request.address:
        raise ProtocolError(f"reply from address {raw[0]} to a request for {request.address}: "
                            f"{raw.hex(' ')}")
    reply = _decode_reply_any(raw, request.function)
    mismatch = ""
    match request, reply:
        case ReadHoldingRequest(count=count), ReadHoldingReply(values=values):
            if len(values) != count:
                mismatch = f"{len(values)} registers for a read of {count}"
        case WriteSingleRequest(register=register), WriteSingleReply(register=echo):
            if echo != register:
                mismatch = f"register 0x{echo:04X} echoed for a write to 0x{register:04X}"
        case WriteMultipleRequest(start=start), WriteMultipleReply(start=got, count=n):
            if (got, n) != (start, request.count):
                mismatch = f"{n} registers at 0x{got:04X} for a write of {request.count} " \
                           f"at 0x{start:04X}"
    if mismatch:
        raise ProtocolError(f"reply does not answer the request: {mismatch}: {raw.hex(' ')}")
    return reply


def decode_frame(frame: bytes | bytearray | memoryview) -> Frame:
    """Decode a frame of unknown direction (sniffer). The lengths tell requests from replies
    (a read request is 8 bytes, its reply 5 + 2n; a write-multiple request 9 + 2n, its reply
    8), except for write-single, whose echo equals the request: it decodes as the request."""
    raw = _bytes(frame)
    function = raw[1]
    if function & EXCEPTION_FLAG:
        return _decode_reply_any(raw, function & ~EXCEPTION_FLAG)
    if function == Function.READ_HOLDING_REGISTERS and len(raw) != FIXED_FRAME_LENGTH:
        return _decode_reply_any(raw, function)
    if function == Function.WRITE_MULTIPLE_REGISTERS and len(raw) == FIXED_FRAME_LENGTH:
        return _decode_reply_any(raw, function)
    return decode_request(raw)


# ------------------------------------------------------------------------ request helpers


def expects_reply(request: Request | UnsupportedRequest) -> bool:
    """A broadcast (address 0) is executed by every device and answered by none."""
    return request.address != BROADCAST


def reply_length(request: Request) -> int:
    """Length of the normal reply to ``request`` (an exception reply is 5 bytes)."""
    if isinstance(request, ReadHoldingRequest):
        return 5 + 2 * request.count
    return FIXED_FRAME_LENGTH


def request_exception(request: Request | UnsupportedRequest) -> ExceptionCode | None:
    """The exception the standard prescribes before any register is looked at (function,
    count and address-range checks of Application Protocol 6.3, 6.6, 6.12), or None.
    Whether the registers exist is the device's decision (exception 2)."""
    match request:
        case UnsupportedRequest():
            return ExceptionCode.ILLEGAL_FUNCTION
        case ReadHoldingRequest(start=start, count=count):
            if not 1 <= count <= MAX_READ_COUNT:
                return ExceptionCode.ILLEGAL_DATA_VALUE
            if start + count - 1 > WORD_MAX:
                return ExceptionCode.ILLEGAL_DATA_ADDRESS
        case WriteMultipleRequest(start=start, values=values):
            if not 1 <= len(values) <= MAX_WRITE_COUNT:
                return ExceptionCode.ILLEGAL_DATA_VALUE
            if start + len(values) - 1 > WORD_MAX:
                return ExceptionCode.ILLEGAL_DATA_ADDRESS
    return None


# ------------------------------------------------------------------------------- describe


def _reg(register: int, names: Mapping[int, str] | None) -> str:
    name = names.get(register) if names else None
    return f"0x{register:04X} {name}" if name else f"0x{register:04X}"


def _assignments(start: int, values: tuple[int, ...], names: Mapping[int, str] | None) -> str:
    return ", ".join(f"{_reg(start + i, names)}={v}" for i, v in enumerate(values))


def describe(frame: bytes | bytearray | memoryview,
             names: Mapping[int, str] | None = None) -> str:
    """One line for a sniffer, e.g. ``id 1 read 0x0000 x10``. ``names`` maps register
    addresses to names (the device family's). Raises FramingError/ChecksumError."""
    decoded = decode_frame(frame)
    head = "broadcast" if decoded.address == BROADCAST else f"id {decoded.address}"
    match decoded:
        case ReadHoldingRequest(start=start, count=count):
            span = f"x{count}" if count != 1 else ""
            return f"{head} read {_reg(start, names)} {span}".rstrip()
        case ReadHoldingReply(values=values):
            return f"{head} read reply [{', '.join(str(v) for v in values)}]"
        case WriteSingleRequest(register=register, value=value):
            return f"{head} write {_reg(register, names)}={value} (request or echo)"
        case WriteMultipleRequest(start=start, values=values):
            return f"{head} write {_assignments(start, values, names)}"
        case WriteMultipleReply(start=start, count=count):
            return f"{head} wrote {count} registers from {_reg(start, names)}"
        case ExceptionReply(function=function, code=code):
            why = f": {EXCEPTION_TEXT[code]}" if code in EXCEPTION_TEXT else ""
            return f"{head} exception {exception_name(code)} to {function_name(function)}{why}"
        case UnsupportedRequest(function=function, data=data):
            return f"{head} {function_name(function)} data {data.hex(' ') or '-'}"
    raise ProtocolError(f"cannot describe {decoded!r}")  # pragma: no cover - exhaustive

