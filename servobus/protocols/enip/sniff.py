"""EtherNet/IP packets for people: ``servobus decode --protocol enip HEX`` (docs/enip.md).

The bytes are a TCP stream of encapsulation packets (24-byte header + data, CIP Vol. 2 2-3),
as a capture of port 44818 holds them; the framer keeps alignment by the length field. Each
packet becomes one line: the command, session, status and, for SendRRData, the Message
Router request or reply inside, with the DYN5 meaning of Parameter instances (the instance
table, ``servobus.families.dyn5.params``). Direction: a Message Router reply has bit 7 of its
service set (CIP Vol. 1 2-4); other packets are shown without one. A packet that does not
parse is an error line; a length above the framer's bound is reported and skipped.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from servobus.errors import FramingError
from servobus.families.dyn5 import params as dyn5
from servobus.protocols.enip.client import describe, status_text
from servobus.protocols.enip.codec.cip import (
    REPLY_FLAG,
    ClassCode,
    MessageRouterRequest,
    MessageRouterResponse,
    RequestTarget,
    Service,
    request_target,
)
from servobus.protocols.enip.codec.cpf import unconnected_message
from servobus.protocols.enip.codec.encap import (
    Command,
    EncapFramer,
    EncapPacket,
    EncapReject,
    EncapStatus,
)
from servobus.sniff import ByteDecoder, ErrorEvent

MAX_REMEMBERED = 64  # outstanding requests whose replies can be named


@dataclass(frozen=True)
class EnipEvent:
    """One encapsulation packet and what it means."""

    raw: bytes
    packet: EncapPacket
    text: str

    is_error = False

    def lines(self, prefix: str = "", width: int = 21) -> list[str]:
        head = self.raw[:4].hex(" ") + (" .." if len(self.raw) > 4 else "")
        return [f"{prefix}{head:<{max(width, len(head) + 2)}}{self.text}"]

    def as_dict(self) -> dict[str, object]:
        p = self.packet
        return {"raw": self.raw.hex(" "), "command": _name(Command, p.command),
                "session": p.session, "status": p.status, "context": p.context.hex(),
                "text": self.text}


def _name(kind: type[Service] | type[Command] | type[EncapStatus], value: int) -> str:
    try:
        return kind(value).name
    except ValueError:
        return f"0x{value:04X}"


def _instance(class_id: int, instance: int) -> str:
    if class_id == ClassCode.PARAMETER:
        inst = dyn5.BY_NUMBER.get(instance)
        return f"0x{instance:02X} {inst.name}" if inst is not None else f"0x{instance:02X}"
    return f"0x{instance:02X}"


def _value(class_id: int, instance: int, data: bytes) -> str:
    if class_id == ClassCode.PARAMETER and len(data) == 4:
        inst = dyn5.BY_NUMBER.get(instance)
        value = inst.decode(data) if inst is not None else dyn5.decode_udint(data)
        return f" = {value}" + (" (unreadable)" if value == dyn5.UNREADABLE else "")
    return f" data {data.hex(' ')}" if data else ""


def message_text(message: bytes, asked: RequestTarget | None = None) -> str:
    """A Message Router request or reply in one phrase; ``asked``: what the request of a
    reply addressed (a reply does not carry its path), to show the value in its units."""
    if message and message[0] & REPLY_FLAG:
        reply = MessageRouterResponse.decode(message)
        what = _name(Service, reply.service)
        if not reply.ok:
            return f"reply {what}: {status_text(reply.general_status)}"
        if asked is not None and reply.service == Service.GET_ATTRIBUTE_SINGLE:
            where = _instance(asked.class_id, asked.instance)
            return f"reply {what} {where}:{_value(asked.class_id, asked.instance, reply.data)}"
        return f"reply {what}: ok" + (f", data {reply.data.hex(' ')}" if reply.data else "")
    request = MessageRouterRequest.decode(message)
    try:
        target = request_target(request.path)
    except FramingError:
        return describe(message)
    name = _name(Service, request.service)
    where = f"class 0x{target.class_id:02X} instance {_instance(target.class_id, target.instance)}"
    if target.attribute is not None:
        where += f" attribute {target.attribute}"
    value = _value(target.class_id, target.instance, request.data) if (
        request.service == Service.SET_ATTRIBUTE_SINGLE) else (
        f" data {request.data.hex(' ')}" if request.data else "")
    return f"{name} {where}{value}"


def packet_text(pkt: EncapPacket, asked: RequestTarget | None = None) -> str:
    head = f"{_name(Command, pkt.command)} session 0x{pkt.session:08X}"
    if pkt.status:
        head += f" status {_name(EncapStatus, pkt.status)}"
    if pkt.command in (Command.SEND_RR_DATA, Command.SEND_UNIT_DATA) and pkt.data:
        items, _ = unconnected_message(pkt.data)
        head += ": " + message_text(items.message, asked)
        for label, sock in (("O->T", items.sockaddr_o_t), ("T->O", items.sockaddr_t_o)):
            if sock is not None:
                head += f" [{label} to {sock.address}:{sock.port}]"
    return head


class EnipStreamDecoder:
    """Encapsulation packets from a byte stream in any chunking; never raises."""

    def __init__(self) -> None:
        self.framer = EncapFramer()
        self._asked: dict[bytes, RequestTarget] = {}  # sender context -> request target

    def _remember(self, pkt: EncapPacket) -> RequestTarget | None:
        """The target of a request (remembered by its sender context), or for a reply the
        target its request named."""
        if pkt.command != Command.SEND_RR_DATA or not pkt.data:
            return None
        message = unconnected_message(pkt.data)[0].message
        if message and message[0] & REPLY_FLAG:
            return self._asked.pop(pkt.context, None)
        try:
            target = request_target(MessageRouterRequest.decode(message).path)
        except FramingError:
            return None
        if len(self._asked) >= MAX_REMEMBERED:
            self._asked.pop(next(iter(self._asked)))
        self._asked[pkt.context] = target
        return None

    def iter_feed(self, data: bytes | bytearray) -> Iterator[EnipEvent | ErrorEvent]:
        for item in self.framer.feed(bytes(data)):
            if isinstance(item, EncapReject):
                h = item.header
                yield ErrorEvent("framing", f"{_name(Command, h.command)} with a length of "
                                 f"{h.length} bytes (above {self.framer.max_data}): skipped")
                continue
            raw = item.encode()
            try:
                yield EnipEvent(raw, item, packet_text(item, self._remember(item)))
            except (FramingError, ValueError) as exc:
                yield ErrorEvent("framing", f"{_name(Command, item.command)}: {exc}", raw)

    def finish(self) -> list[EnipEvent | ErrorEvent]:
        left = self.framer.buffered
        self.framer = EncapFramer()
        if left:
            return [ErrorEvent("framing", f"{left} byte(s) of an incomplete packet at the end")]
        return []


DECODER = ByteDecoder("enip", "EtherNet/IP", EnipStreamDecoder)  # a TCP capture
