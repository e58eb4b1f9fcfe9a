"""ListIdentity / ListServices / ListInterfaces reply items (CIP Vol. 2 2-4). Pure.

ListIdentity item 0x000C: encapsulation version UINT, socket address (sockaddr, big-endian),
the Identity object's attributes 1-7 as Get_Attributes_All lays them out (vendor, device
type, product code, revision, status, serial, product name: ``identity`` owns that layout),
state USINT.
ListServices item 0x0100: version UINT, capability flags UINT, name (16 bytes, NUL padded).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from servobus.errors import FramingError
from servobus.protocols.enip.codec import cpf, identity
from servobus.protocols.enip.codec.cpf import CpfItem, ItemType, SockaddrInfo
from servobus.protocols.enip.codec.encap import PROTOCOL_VERSION
from servobus.protocols.enip.codec.identity import IdentityAttributes

#: Encapsulation version UINT and socket address before the Identity attributes.
_HEAD = 2 + 16
_SERVICE = struct.Struct("<HH16s")
#: ListServices capability flags: bit 5 CIP encapsulation over TCP, bit 8 Class 0/1 over UDP.
CAPABILITY_TCP = 0x0020
CAPABILITY_UDP_IO = 0x0100
SERVICE_NAME = "Communications"


@dataclass(frozen=True)
class _Socket:
    socket: SockaddrInfo


@dataclass(frozen=True)
class IdentityItem(IdentityAttributes, _Socket):
    """Fields: socket (from _Socket: a dataclass takes its bases' fields in reverse MRO
    order), the Identity attributes 1-7 (``identity.IdentityAttributes``), state, version."""

    state: int
    version: int = PROTOCOL_VERSION

    def encode(self) -> bytes:
        try:
            head = struct.pack("<H", self.version)
            tail = bytes((self.state,))
        except (struct.error, ValueError) as exc:
            raise FramingError(f"identity field out of range: {exc}") from None
        return head + self.socket.encode() + identity.all_attributes(self) + tail

    @classmethod
    def decode(cls, raw: bytes) -> IdentityItem:
        if len(raw) < _HEAD + identity.FIXED.size + 2:
            raise FramingError(f"ListIdentity item too short ({len(raw)} bytes)")
        (version,) = struct.unpack_from("<H", raw)
        sock = SockaddrInfo.decode(raw[2:_HEAD])
        values, pos = identity.decode_attributes(raw, _HEAD)
        if pos + 1 != len(raw):
            raise FramingError("ListIdentity item: state byte missing or trailing bytes")
        return cls(sock, *values, raw[pos], version)

    def item(self) -> CpfItem:
        return CpfItem(ItemType.LIST_IDENTITY, self.encode())


@dataclass(frozen=True)
class ServiceItem:
    capabilities: int = CAPABILITY_TCP | CAPABILITY_UDP_IO
    name: str = SERVICE_NAME
    version: int = PROTOCOL_VERSION

    def encode(self) -> bytes:
        try:
            raw = self.name.encode("ascii")
        except UnicodeEncodeError:
            raise FramingError(f"service name {self.name!r} is not ASCII") from None
        if len(raw) > 15:
            raise FramingError("service name longer than 15 characters")
        try:
            return _SERVICE.pack(self.version, self.capabilities, raw)
        except struct.error as exc:
            raise FramingError(f"ListServices field out of range: {exc}") from None

    @classmethod
    def decode(cls, raw: bytes) -> ServiceItem:
        if len(raw) != _SERVICE.size:
            raise FramingError(f"ListServices item is 20 bytes, got {len(raw)}")
        version, caps, name = _SERVICE.unpack(raw)
        return cls(caps, name.split(b"\0", 1)[0].decode("ascii", errors="replace"), version)

    def item(self) -> CpfItem:
        return CpfItem(ItemType.LIST_SERVICES, self.encode())


def list_identity_reply(item: IdentityItem) -> bytes:
    return cpf.encode_items((item.item(),))


def list_services_reply(item: ServiceItem | None = None) -> bytes:
    return cpf.encode_items(((item or ServiceItem()).item(),))


def list_interfaces_reply() -> bytes:
    """Decision: no non-CIP interfaces to list (item count 0)."""
    return cpf.encode_items(())


def decode_identity_reply(raw: bytes) -> IdentityItem:
    items = cpf.decode_items(raw)
    found = [i for i in items if i.type_id == ItemType.LIST_IDENTITY]
    if len(found) != 1:
        raise FramingError("ListIdentity reply must hold one identity item")
    return IdentityItem.decode(found[0].data)
