"""Common Packet Format (CIP Vol. 2 2-6): item count, then typed items. Pure.

SendRRData / SendUnitData carry an interface handle (UDINT, 0 for CIP), a timeout (UINT)
and a CPF list; Class 1 UDP datagrams are a bare CPF list. Sockaddr Info items are the one
big-endian structure inside the little-endian stream: sin_family INT, sin_port UINT,
sin_addr UDINT (all network byte order), then 8 zero bytes.
"""

from __future__ import annotations

import ipaddress
import struct
from dataclasses import dataclass
from enum import IntEnum

from servobus.errors import FramingError

_ITEM = struct.Struct("<HH")
_RR = struct.Struct("<IH")
_SOCKADDR = struct.Struct(">hHI8s")
_SEQUENCED = struct.Struct("<II")
AF_INET = 2


class ItemType(IntEnum):
    NULL_ADDRESS = 0x0000
    LIST_IDENTITY = 0x000C
    CONNECTED_ADDRESS = 0x00A1
    CONNECTED_DATA = 0x00B1
    UNCONNECTED_DATA = 0x00B2
    LIST_SERVICES = 0x0100
    SOCKADDR_O_T = 0x8000  # where the sender receives O->T data
    SOCKADDR_T_O = 0x8001  # where the sender receives T->O data
    SEQUENCED_ADDRESS = 0x8002


@dataclass(frozen=True)
class CpfItem:
    type_id: int
    data: bytes = b""


def encode_items(items: tuple[CpfItem, ...] | list[CpfItem]) -> bytes:
    out = bytearray(struct.pack("<H", len(items)))
    for item in items:
        if len(item.data) > 0xFFFF or not 0 <= item.type_id <= 0xFFFF:
            raise FramingError(f"CPF item 0x{item.type_id:04X} too long or out of range")
        out += _ITEM.pack(item.type_id, len(item.data)) + item.data
    return bytes(out)


def decode_items(raw: bytes) -> tuple[CpfItem, ...]:
    """The whole of ``raw`` must be the list: truncation and trailing bytes are errors."""
    if len(raw) < 2:
        raise FramingError("CPF list needs an item count")
    (count,) = struct.unpack_from("<H", raw)
    pos = 2
    items: list[CpfItem] = []
    for _ in range(count):
        if pos + _ITEM.size > len(raw):
            raise FramingError(f"CPF item {len(items)} header truncated")
        type_id, length = _ITEM.unpack_from(raw, pos)
        pos += _ITEM.size
        if pos + length > len(raw):
            raise FramingError(f"CPF item 0x{type_id:04X} data truncated")
        items.append(CpfItem(type_id, bytes(raw[pos:pos + length])))
        pos += length
    if pos != len(raw):
        raise FramingError(f"{len(raw) - pos} byte(s) after the last CPF item")
    return tuple(items)


@dataclass(frozen=True)
class RRData:
    """Data part of SendRRData / SendUnitData."""

    items: tuple[CpfItem, ...]
    interface_handle: int = 0
    timeout: int = 0

    def encode(self) -> bytes:
        return _RR.pack(self.interface_handle, self.timeout) + encode_items(self.items)

    @classmethod
    def decode(cls, raw: bytes) -> RRData:
        if len(raw) < _RR.size:
            raise FramingError(f"SendRRData data needs 6 bytes before the CPF, got {len(raw)}")
        handle, timeout = _RR.unpack_from(raw)
        return cls(decode_items(raw[_RR.size:]), handle, timeout)


@dataclass(frozen=True)
class SockaddrInfo:
    port: int
    address: str  # dotted IPv4
    family: int = AF_INET

    def encode(self) -> bytes:
        try:
            addr = int(ipaddress.IPv4Address(self.address))
            return _SOCKADDR.pack(self.family, self.port, addr, bytes(8))
        except (ValueError, struct.error) as exc:
            raise FramingError(f"invalid sockaddr {self.address}:{self.port}: {exc}") from None

    @classmethod
    def decode(cls, raw: bytes) -> SockaddrInfo:
        if len(raw) != _SOCKADDR.size:
            raise FramingError(f"sockaddr info is 16 bytes, got {len(raw)}")
        family, port, addr, _ = _SOCKADDR.unpack(raw)
        return cls(port, str(ipaddress.IPv4Address(addr)), family)

    def item(self, type_id: ItemType) -> CpfItem:
        return CpfItem(type_id, self.encode())


@dataclass(frozen=True)
class SequencedAddress:
    connection_id: int
    sequence: int

    def encode(self) -> bytes:
        try:
            return _SEQUENCED.pack(self.connection_id, self.sequence)
        except struct.error as exc:
            raise FramingError(f"sequenced address out of range: {exc}") from None

    @classmethod
    def decode(cls, raw: bytes) -> SequencedAddress:
        if len(raw) != _SEQUENCED.size:
            raise FramingError(f"sequenced address item is 8 bytes, got {len(raw)}")
        return cls(*_SEQUENCED.unpack(raw))


#: SendRRData data of the common shape: interface handle, timeout, item count 2, null address
#: item (type 0, length 0), unconnected data item header; the message follows.
_PLAIN_RR = struct.Struct("<IHHHHHH")


def plain_rr_data(message: bytes, timeout: int = 0) -> bytes:
    """SendRRData data: null address + unconnected data ``message`` (interface handle 0)."""
    return _PLAIN_RR.pack(0, timeout, 2, ItemType.NULL_ADDRESS, 0, ItemType.UNCONNECTED_DATA,
                          len(message)) + message


def unconnected_message(raw: bytes) -> tuple[UnconnectedMessage, int]:
    """SendRRData data -> (the message and its sockaddr items, interface handle).

    The plain shape (null address + unconnected data, nothing else) is read with one struct
    (the hot path of every explicit request and reply); any other shape goes through
    :meth:`RRData.decode` and :meth:`UnconnectedMessage.from_items`, with their checks."""
    if len(raw) >= _PLAIN_RR.size:
        handle, _, count, null, null_len, kind, length = _PLAIN_RR.unpack_from(raw)
        if (count == 2 and null == ItemType.NULL_ADDRESS and null_len == 0
                and kind == ItemType.UNCONNECTED_DATA
                and length == len(raw) - _PLAIN_RR.size):
            return UnconnectedMessage(raw[_PLAIN_RR.size:]), handle
    rr = RRData.decode(raw)
    return UnconnectedMessage.from_items(rr.items), rr.interface_handle


def unconnected(message: bytes, *extra: CpfItem) -> tuple[CpfItem, ...]:
    """Null address + unconnected data (+ e.g. sockaddr items): an unconnected message."""
    return (CpfItem(ItemType.NULL_ADDRESS), CpfItem(ItemType.UNCONNECTED_DATA, message), *extra)


@dataclass(frozen=True)
class UnconnectedMessage:
    """The items of a SendRRData request or reply, split by role."""

    message: bytes
    sockaddr_o_t: SockaddrInfo | None = None
    sockaddr_t_o: SockaddrInfo | None = None

    @classmethod
    def from_items(cls, items: tuple[CpfItem, ...]) -> UnconnectedMessage:
        """Null address, unconnected data, then optional sockaddr items (any order)."""
        if len(items) < 2 or items[0].type_id != ItemType.NULL_ADDRESS or items[0].data:
            raise FramingError("unconnected message must start with a null address item")
        if items[1].type_id != ItemType.UNCONNECTED_DATA:
            raise FramingError("unconnected message needs an unconnected data item")
        found: dict[int, SockaddrInfo] = {}
        for item in items[2:]:
            if item.type_id not in (ItemType.SOCKADDR_O_T, ItemType.SOCKADDR_T_O):
                raise FramingError(f"unexpected CPF item 0x{item.type_id:04X}")
            if item.type_id in found:
                raise FramingError(f"duplicate CPF item 0x{item.type_id:04X}")
            found[item.type_id] = SockaddrInfo.decode(item.data)
        return cls(items[1].data, found.get(ItemType.SOCKADDR_O_T),
                   found.get(ItemType.SOCKADDR_T_O))

    def items(self) -> tuple[CpfItem, ...]:
        extra = [s.item(t) for s, t in ((self.sockaddr_o_t, ItemType.SOCKADDR_O_T),
                                        (self.sockaddr_t_o, ItemType.SOCKADDR_T_O))
                 if s is not None]
        return unconnected(self.message, *extra)
