"""CIP padded EPATH segments (CIP Vol. 1 appendix C): bytes <-> frozen dataclasses. Pure.

Segments understood: logical (class, instance, member, connection point, attribute in 8,
16 and 32 bits; the electronic key), port (with extended port id and link address), simple
data, and the one-byte network segments (e.g. 0x43 production inhibit time). Padded form:
16/32-bit logical values and odd-sized port link addresses are followed by a pad byte so
every segment is a whole number of 16-bit words.

Anything else raises :class:`~servobus.errors.FramingError` (a typed ProtocolError); the
decoder never raises anything else, whatever the input.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from servobus.errors import FramingError


class LogicalType(IntEnum):
    CLASS = 0
    INSTANCE = 1
    MEMBER = 2
    CONNECTION_POINT = 3
    ATTRIBUTE = 4


_LOGICAL = 0x20  # segment type 001 in bits 7-5
_KEY = 0x34  # logical type 5 (special), format 0: electronic key
_KEY_FORMAT = 4
_DATA_SIMPLE = 0x80
_PORT_MAX = 0x0F  # port id 15 means: an extended (16-bit) port id follows
_EXT_LINK = 0x10
_WIDTH_FORMAT = {8: 0, 16: 1, 32: 2}
_FORMAT_WIDTH = {v: k for k, v in _WIDTH_FORMAT.items()}


@dataclass(frozen=True)
class LogicalSegment:
    kind: LogicalType
    value: int
    width: int = 0  # 8, 16 or 32 bits; 0 = the smallest that holds the value

    def encoded_width(self) -> int:
        if self.width:
            return self.width
        return 8 if self.value <= 0xFF else 16 if self.value <= 0xFFFF else 32


@dataclass(frozen=True)
class PortSegment:
    port: int
    link: bytes  # link address (one byte for a backplane slot)


@dataclass(frozen=True)
class KeySegment:
    """Electronic key (format 4); zeros mean "do not check" for that field."""

    vendor_id: int
    device_type: int
    product_code: int
    major_revision: int
    minor_revision: int
    compatibility: bool = False


@dataclass(frozen=True)
class DataSegment:
    data: bytes  # an even number of bytes (16-bit words)


@dataclass(frozen=True)
class NetworkSegment:
    subtype: int  # 0x40..0x4F (0x43: production inhibit time in ms)
    value: int  # one byte


Segment = LogicalSegment | PortSegment | KeySegment | DataSegment | NetworkSegment


def logical(kind: LogicalType, value: int, width: int = 0) -> LogicalSegment:
    return LogicalSegment(kind, value, width)


def request_path(class_id: int, instance: int, attribute: int | None = None
                 ) -> tuple[LogicalSegment, ...]:
    """class / instance [/ attribute], each in the smallest width."""
    segs = [LogicalSegment(LogicalType.CLASS, class_id),
            LogicalSegment(LogicalType.INSTANCE, instance)]
    if attribute is not None:
        segs.append(LogicalSegment(LogicalType.ATTRIBUTE, attribute))
    return tuple(segs)


# ---------------------------------------------------------------- encode
def _encode_logical(seg: LogicalSegment) -> bytes:
    width = seg.encoded_width()
    if width not in _WIDTH_FORMAT:
        raise FramingError(f"logical segment width {width} is not 8, 16 or 32")
    if not 0 <= seg.value < (1 << width):
        raise FramingError(f"{seg.kind.name.lower()} {seg.value} does not fit {width} bits")
    head = _LOGICAL | (int(seg.kind) << 2) | _WIDTH_FORMAT[width]
    if width == 8:
        return bytes((head, seg.value))
    fmt = "<BxH" if width == 16 else "<BxI"
    return struct.pack(fmt, head, seg.value)


def _encode_port(seg: PortSegment) -> bytes:
    if not 0 < seg.port <= 0xFFFF or not seg.link or len(seg.link) > 0xFF:
        raise FramingError(f"invalid port segment {seg!r}")
    extended_port = seg.port >= _PORT_MAX
    head = _PORT_MAX if extended_port else seg.port
    out = bytearray()
    if len(seg.link) == 1:
        out.append(head)
        if extended_port:
            out += struct.pack("<H", seg.port)
        out += seg.link
    else:
        out += bytes((head | _EXT_LINK, len(seg.link)))
        if extended_port:
            out += struct.pack("<H", seg.port)
        out += seg.link
    if len(out) % 2:
        out.append(0)
    return bytes(out)


def _encode_segment(seg: Segment) -> bytes:
    if isinstance(seg, LogicalSegment):
        return _encode_logical(seg)
    if isinstance(seg, PortSegment):
        return _encode_port(seg)
    if isinstance(seg, KeySegment):
        major = (seg.major_revision & 0x7F) | (0x80 if seg.compatibility else 0)
        return struct.pack("<BBHHHBB", _KEY, _KEY_FORMAT, seg.vendor_id, seg.device_type,
                           seg.product_code, major, seg.minor_revision)
    if isinstance(seg, DataSegment):
        if len(seg.data) % 2 or len(seg.data) > 0x1FE:
            raise FramingError("a data segment holds up to 255 whole 16-bit words")
        return bytes((_DATA_SIMPLE, len(seg.data) // 2)) + seg.data
    if not 0x40 <= seg.subtype <= 0x4F or not 0 <= seg.value <= 0xFF:
        raise FramingError(f"invalid network segment {seg!r}")
    return bytes((seg.subtype, seg.value))


def encode_path(segments: tuple[Segment, ...] | list[Segment]) -> bytes:
    """Padded EPATH bytes (always a whole number of words)."""
    return b"".join(_encode_segment(s) for s in segments)


def encode_sized_path(segments: tuple[Segment, ...] | list[Segment]) -> bytes:
    """Path size in words (one byte), then the padded EPATH."""
    raw = encode_path(segments)
    if len(raw) // 2 > 0xFF:
        raise FramingError("path longer than 255 words")
    return bytes((len(raw) // 2,)) + raw


# ---------------------------------------------------------------- decode
def _need(raw: bytes, pos: int, n: int) -> None:
    if pos + n > len(raw):
        raise FramingError(f"EPATH truncated at byte {pos} (needs {n} more)")


def _decode_logical(raw: bytes, pos: int, head: int) -> tuple[LogicalSegment, int]:
    fmt = head & 0x03
    if fmt not in _FORMAT_WIDTH:
        raise FramingError(f"reserved logical format in segment 0x{head:02X}")
    width = _FORMAT_WIDTH[fmt]
    kind = LogicalType((head >> 2) & 0x07)
    if width == 8:
        _need(raw, pos, 2)
        return LogicalSegment(kind, raw[pos + 1], 8), pos + 2
    size = 4 if width == 16 else 6
    _need(raw, pos, size)
    value = int.from_bytes(raw[pos + 2:pos + size], "little")
    return LogicalSegment(kind, value, width), pos + size


def _decode_port(raw: bytes, pos: int, head: int) -> tuple[PortSegment, int]:
    start = pos
    pos += 1
    link_size = 1
    if head & _EXT_LINK:
        _need(raw, pos, 1)
        link_size = raw[pos]
        pos += 1
        if link_size == 0:
            raise FramingError("port segment with an empty link address")
    port = head & _PORT_MAX
    if port == _PORT_MAX:
        _need(raw, pos, 2)
        port = int.from_bytes(raw[pos:pos + 2], "little")
        pos += 2
    if port == 0:
        raise FramingError("port segment with port 0 (reserved)")
    _need(raw, pos, link_size)
    link = bytes(raw[pos:pos + link_size])
    pos += link_size
    if (pos - start) % 2:
        _need(raw, pos, 1)
        pos += 1
    return PortSegment(port, link), pos


def _decode_one(raw: bytes, pos: int) -> tuple[Segment, int]:
    head = raw[pos]
    kind = head >> 5
    if kind == 0:
        return _decode_port(raw, pos, head)
    if head == _KEY:
        _need(raw, pos, 10)
        if raw[pos + 1] != _KEY_FORMAT:
            raise FramingError(f"electronic key format {raw[pos + 1]} is not 4")
        vendor, dev, prod, major, minor = struct.unpack_from("<HHHBB", raw, pos + 2)
        return KeySegment(vendor, dev, prod, major & 0x7F, minor, bool(major & 0x80)), pos + 10
    if kind == 1 and ((head >> 2) & 0x07) <= LogicalType.ATTRIBUTE:
        return _decode_logical(raw, pos, head)
    if head == _DATA_SIMPLE:
        _need(raw, pos, 2)
        n = raw[pos + 1] * 2
        _need(raw, pos + 2, n)
        return DataSegment(bytes(raw[pos + 2:pos + 2 + n])), pos + 2 + n
    if 0x40 <= head <= 0x4F:
        _need(raw, pos, 2)
        return NetworkSegment(head, raw[pos + 1]), pos + 2
    raise FramingError(f"unsupported EPATH segment type 0x{head:02X} at byte {pos}")


def decode_path(raw: bytes) -> tuple[Segment, ...]:
    """All segments of a padded EPATH (the bytes must end exactly at a segment end)."""
    segs: list[Segment] = []
    pos = 0
    while pos < len(raw):
        seg, pos = _decode_one(raw, pos)
        segs.append(seg)
    return tuple(segs)
