"""Identity object (class 0x01) attributes (DYN5 manual 4.2; CIP Vol. 1 5A-2). Pure.

Instance 1, attributes 1-7: vendor UINT, device type UINT, product code UINT, revision
(major USINT, minor USINT), status WORD, serial UDINT, product name SHORT_STRING (decision
in ``servobus.families.dyn5.params``). Get_Attributes_All returns the seven in order, and
the ListIdentity item (``discovery``) carries the same bytes: this module owns their layout
(:data:`FIXED`, :class:`IdentityAttributes`, the SHORT_STRING codec) for both.

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

#: Wire formats of instance attributes 1-6 in order (4: revision major, minor); attribute 7,
#: the product name, follows them as a SHORT_STRING.
_FORMATS = ("H", "H", "H", "BB", "H", "I")
FIXED = struct.Struct("<" + "".join(_FORMATS))
NAME_ATTRIBUTE = len(_FORMATS) + 1
INSTANCE_ATTRIBUTES = tuple(range(1, NAME_ATTRIBUTE + 1))
CLASS_ATTRIBUTES = {1: 1, 2: 1, 3: 1, 6: 7, 7: 7}
#: The seven attribute values in order, as :class:`IdentityAttributes` takes them.
Values = tuple[int, int, int, tuple[int, int], int, int, str]


@dataclass(frozen=True)
class IdentityAttributes:
    """Instance attributes 1-7 in wire order: what a Get_Attributes_All reply and a
    ListIdentity item share (both derive from this class)."""

    vendor_id: int
    device_type: int
    product_code: int
    revision: tuple[int, int]
    status: int
    serial_number: int
    product_name: str


def encode_short_string(text: str) -> bytes:
    try:
        raw = text.encode("ascii")
    except UnicodeEncodeError:
        raise FramingError(f"{text!r} is not ASCII") from None
    if len(raw) > 0xFF:
        raise FramingError(f"{text!r} is longer than 255 characters")
    return bytes((len(raw),)) + raw


def decode_short_string(raw: bytes, pos: int) -> tuple[str, int]:
    if pos >= len(raw):
        raise FramingError("SHORT_STRING length byte missing")
    n = raw[pos]
    if pos + 1 + n > len(raw):
        raise FramingError("SHORT_STRING truncated")
    return raw[pos + 1:pos + 1 + n].decode("ascii", errors="replace"), pos + 1 + n


def _spans() -> dict[int, tuple[int, int]]:
    """Attribute id -> (start, end) of its bytes within FIXED."""
    spans, start = {}, 0
    for attribute, fmt in enumerate(_FORMATS, start=1):
        end = start + struct.calcsize("<" + fmt)
        spans[attribute] = (start, end)
        start = end
    return spans


_SPANS = _spans()


def _fixed(identity: Identity | IdentityAttributes) -> bytes:
    """Attributes 1-6 packed; FramingError when a value does not fit its field."""
    try:
        return FIXED.pack(identity.vendor_id, identity.device_type, identity.product_code,
                          identity.revision[0], identity.revision[1], identity.status,
                          identity.serial_number)
    except struct.error as exc:
        raise FramingError(f"identity field out of range: {exc}") from None


def all_attributes(identity: Identity | IdentityAttributes) -> bytes:
    """Attributes 1-7 as Get_Attributes_All and the ListIdentity item lay them out."""
    return _fixed(identity) + encode_short_string(identity.product_name)


def decode_attributes(raw: bytes, pos: int) -> tuple[Values, int]:
    """Attributes 1-7 from ``raw[pos:]``, and the offset after the product name."""
    if len(raw) < pos + FIXED.size:
        raise FramingError(f"Identity attributes need {FIXED.size + 1} bytes")
    vendor, dev, prod, major, minor, status, serial = FIXED.unpack_from(raw, pos)
    name, end = decode_short_string(raw, pos + FIXED.size)
    return (vendor, dev, prod, (major, minor), status, serial, name), end


def instance_attribute(identity: Identity | IdentityAttributes, attribute: int) -> bytes | None:
    """Bytes of one instance attribute; None when the attribute does not exist."""
    if attribute == NAME_ATTRIBUTE:
        return encode_short_string(identity.product_name)
    span = _SPANS.get(attribute)
    return None if span is None else _fixed(identity)[span[0]:span[1]]


def class_attribute(attribute: int) -> bytes | None:
    value = CLASS_ATTRIBUTES.get(attribute)
    return None if value is None else struct.pack("<H", value)


def class_all_attributes() -> bytes:
    return b"".join(struct.pack("<H", v) for v in CLASS_ATTRIBUTES.values())


@dataclass(frozen=True)
class IdentityReply(IdentityAttributes):
    """Decoded Get_Attributes_All reply of instance 1 (for clients and tests)."""

    @classmethod
    def decode(cls, raw: bytes) -> IdentityReply:
        if len(raw) < FIXED.size + 1:
            raise FramingError(f"Identity attributes need {FIXED.size + 1} bytes")
        values, end = decode_attributes(raw, 0)
        if end != len(raw):
            raise FramingError("trailing bytes after the Identity product name")
        return cls(*values)
