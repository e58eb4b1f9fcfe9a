"""One line of text per EasyCan frame, for ``servobus decode`` and ``sniff``.

Register names, units and scales come from the YZ-AIM family table; a frame that does not
decode is shown with the reason instead of raising.
"""

from __future__ import annotations

from servobus.errors import FramingError
from servobus.families.yzaim import registers as yzaim
from servobus.protocols.easycan.codec import decode
from servobus.protocols.easycan.functions import HOST_ADDRESS, Function, error_text
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
    Request,
    WriteReply,
    WriteRequest,
)


def register_name(address: int) -> str:
    reg = yzaim.BY_ADDRESS.get(address)
    return reg.name if reg is not None else f"register 0x{address:02X}"


def _one(address: int, word: int) -> str:
    reg = yzaim.BY_ADDRESS.get(address)
    if reg is None:
        return f"register 0x{address:02X} = {word}"
    raw = reg.from_word(word)
    if reg.per_unit == 1:
        unit = "" if reg.unit == "-" else f" {reg.unit}"
        return f"{reg.name} = {raw}{unit}"
    return f"{reg.name} = {raw} ({reg.to_engineering(raw):g} {reg.unit})"


def show_registers(address: int, words: tuple[int, ...]) -> str:
    """``name = value unit`` for consecutive registers; a 32-bit pair as one value."""
    pair = yzaim.PAIR_BY_LOW.get(address)
    if pair is not None and len(words) == 2:
        return f"{pair.name} = {yzaim.join32(words[0], words[1])} {pair.unit}"
    return ", ".join(_one(address + i, w) for i, w in enumerate(words))


def _span(address: int, count: int) -> str:
    pair = yzaim.PAIR_BY_LOW.get(address)
    if pair is not None and count == 2:
        return pair.name
    names = ", ".join(register_name(a) for a in range(address, address + min(count, 2)))
    return names if 1 <= count <= 2 else f"{names} x{count}"


def _host(host: int) -> str:
    return "host" if host == HOST_ADDRESS else f"host 0x{host:02X}"


def describe(message: Message, after: Request | None = None) -> str:
    """One line; ``after`` (the request being answered) lets a 0x12 reply name registers."""
    match message:
        case ReadRequest():
            span = _span(message.address, message.count)
            return f"{_host(message.host)} -> {message.slave}: READ {span}"
        case WriteRequest():
            shown = show_registers(message.address, message.values)
            return f"{_host(message.host)} -> {message.slave}: WRITE {shown}"
        case EmergencyStop():
            return f"{_host(message.host)} -> {message.slave}: EMERGENCY_STOP"
        case ClearPosition():
            return f"{_host(message.host)} -> {message.slave}: CLEAR_POSITION (no reply)"
        case ReadMultipleRequest():
            names = ", ".join(register_name(a) for a in message.addresses)
            return f"{_host(message.host)} -> {message.slave}: READ_MULTIPLE {names}"
        case PositionCacheWrite():
            how = "reply with position" if message.reply else "no reply"
            return f"host -> {message.slave}: POSITION_CACHE {message.position} ({how})"
        case ReadReply():
            shown = show_registers(message.address, message.values)
            return f"{message.slave} -> {_host(message.host)}: READ {shown}"
        case WriteReply():
            head = f"{message.slave} -> {_host(message.host)}: WRITE"
            if message.position is not None:
                return (f"{head} {_span(message.address, 2)} accepted, absolute position "
                        f"{message.position}")
            return f"{head} {show_registers(message.address, message.values)}"
        case EmergencyStopReply():
            return f"{message.slave} -> {_host(message.host)}: EMERGENCY_STOP done"
        case ReadMultipleReply():
            if isinstance(after, ReadMultipleRequest) and len(after.addresses) == len(
                    message.values):
                shown = ", ".join(_one(a, w) for a, w in zip(after.addresses, message.values,
                                                              strict=True))
            else:
                shown = ", ".join(str(w) for w in message.values)
            return f"{message.slave} -> {_host(message.host)}: READ_MULTIPLE {shown}"
        case PositionReply():
            return f"drive -> {_host(message.host)}: absolute position {message.position}"
        case ErrorReply():
            return (f"{message.slave} -> {_host(message.host)}: ERROR on "
                    f"{_function_name(message.function)}: 0x{message.code:02X} "
                    f"{error_text(message.code)}")
    return repr(message)  # pragma: no cover


def _function_name(code: int) -> str:
    try:
        return Function(code).name
    except ValueError:
        return f"function 0x{code:02X}"


def describe_frame(arbitration_id: int, data: bytes | bytearray,
                   after: Request | None = None) -> str:
    """Decode and describe; ``after`` resolves the 4-byte reply ambiguity (see codec)."""
    position = None if after is None else isinstance(after, PositionCacheWrite)
    try:
        return describe(decode(arbitration_id, data, position), after)
    except FramingError as exc:
        return f"id 0x{arbitration_id:03X} [{bytes(data).hex(' ')}]: malformed ({exc})"
