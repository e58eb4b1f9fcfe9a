"""Identity object (class 0x01) attribute encoding (DYN5 manual 4.2; CIP Vol. 1 5A-2). Pure.

Instance 1, attributes 1-7: vendor UINT, device type UINT, product code UINT, revision
(major USINT, minor USINT), status WORD, serial UDINT, product name SHORT_STRING (decision
in ``servobus.families.dyn5.params``). Get_Attributes_All returns the seven in order.

Class level (instance 0; the manual says both services are implemented for the class but
gives no attributes). Decision: the CIP common class attributes 1 revision (1), 2 max
instance (1), 3 number of instances (1), 6 max class attribute id (7), 7 max instance
attribute id (7), each UINT; Get_Attributes_All returns them in that order.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from servobus.errors import FramingError
from servobus.families.dyn5.params import Identity
from servobus.protocols.enip.codec.discovery import decode_short_string, encode_short_string

INSTANCE_ATTRIBUTES = (1, 2, 3, 4, 5, 6, 7)
CLASS_ATTRIBUTES = {1: 1, 2: 1, 3: 1, 6: 7, 7: 7}
_FIXED = struct.Struct("<HHHBBHI")


def instance_attribute(identity: Identity, attribute: int) -> bytes | None:
    """Bytes of one instance attribute; None when the attribute does not exist."""
    values: dict[int, bytes] = {
        1: struct.pack("<H", identity.vendor_id),
        2: struct.pack("<H", identity.device_type),
        3: struct.pack("<H", identity.product_code),
        4: bytes(identity.revision),
        5: struct.pack("<H", identity.status),
        6: struct.pack("<I", identity.serial_number),
        7: encode_short_string(identity.product_name),
    }
    return values.get(attribute)


def all_attributes(identity: Identity) -> bytes:
    return b"".join(instance_attribute(identity, a) or b"" for a in INSTANCE_ATTRIBUTES)


def class_attribute(attribute: int) -> bytes | None:
    value = CLASS_ATTRIBUTES.get(attribute)
    return None if value is None else struct.pack("<H", value)


def class_all_attributes() -> bytes:
    return b"".join(struct.pack("<H", v) for v in CLASS_ATTRIBUTES.values())


@dataclass(frozen=True)
class IdentityReply:
    """Decoded Get_Attributes_All reply of instance 1 (for clients and tests)."""

    vendor_id: int
    device_type: int
    product_code: int
    revision: tuple[int, int]
    status: int
    serial_number: int
    product_name: str

    @classmethod
    def decode(cls, raw: bytes) -> IdentityReply:
        if len(raw) < _FIXED.size + 1:
            raise FramingError(f"Identity attributes need {_FIXED.size + 1} bytes")
        vendor, dev, prod, major, minor, status, serial = _FIXED.unpack_from(raw)
        name, end = decode_short_string(raw, _FIXED.size)
        if end != len(raw):
            raise FramingError("trailing bytes after the Identity product name")
        return cls(vendor, dev, prod, (major, minor), status, serial, name)
