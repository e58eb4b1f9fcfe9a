"""DYN5 Class 1 implicit I/O (DYN5 manual section 5; CIP Vol. 2 3-2): images and frames. Pure.

A Class 1 UDP datagram is a bare CPF list: a sequenced address item (connection id, 32-bit
encapsulation sequence number) and a connected data item whose data starts with the 16-bit
CIP sequence count.

* T->O (assembly 100, produced): sequence count + 4 UDINT = 18 bytes: absolute position,
  speed, torque (signed, two's complement) and the status word. No run/idle header.
* O->T (assembly 101, consumed): sequence count + 32-bit run/idle header (bit 0 = run) +
  1 UDINT = 10 bytes: 0xAAAA enable, 0xDEDE disable.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from servobus.errors import FramingError
from servobus.families.dyn5 import params as dyn5
from servobus.protocols.enip.codec import cpf
from servobus.protocols.enip.codec.cpf import CpfItem, ItemType, SequencedAddress

_INPUT = struct.Struct("<iiiI")
_OUTPUT = struct.Struct("<II")  # run/idle header, command word
_COUNT = struct.Struct("<H")
INPUT_SIZE = _INPUT.size  # 16
OUTPUT_SIZE = 4
RUN_BIT = 0x0001
#: Connection sizes in the Forward_Open network parameters (NOTES: sequence count included).
T_O_CONNECTION_SIZE = _COUNT.size + INPUT_SIZE  # 18
O_T_CONNECTION_SIZE = _COUNT.size + _OUTPUT.size  # 10
UDP_PORT = 2222


@dataclass(frozen=True)
class InputImage:
    """T->O data: position (counts), speed (rpm), torque (2000 = peak), status word."""

    position: int
    speed: int
    torque: int
    status: int

    def encode(self) -> bytes:
        try:
            return _INPUT.pack(self.position, self.speed, self.torque, self.status)
        except struct.error as exc:
            raise FramingError(f"input image field out of range: {exc}") from None

    @classmethod
    def decode(cls, raw: bytes) -> InputImage:
        if len(raw) != INPUT_SIZE:
            raise FramingError(f"input image is {INPUT_SIZE} bytes, got {len(raw)}")
        return cls(*_INPUT.unpack(raw))


@dataclass(frozen=True)
class OutputImage:
    """O->T data behind the run/idle header: the enable/disable command word."""

    command: int
    run: bool = True

    @property
    def enable(self) -> bool | None:
        """True for 0xAAAA, False for 0xDEDE, None for any other word (no command)."""
        return {dyn5.ENABLE: True, dyn5.DISABLE: False}.get(self.command)

    def encode(self) -> bytes:
        """Run/idle header + command word (the consumed connection's payload)."""
        try:
            return _OUTPUT.pack(RUN_BIT if self.run else 0, self.command)
        except struct.error as exc:
            raise FramingError(f"output command out of range: {exc}") from None

    @classmethod
    def decode(cls, raw: bytes) -> OutputImage:
        if len(raw) != _OUTPUT.size:
            raise FramingError(f"run/idle header + output image is 8 bytes, got {len(raw)}")
        header, command = _OUTPUT.unpack(raw)
        return cls(command, bool(header & RUN_BIT))


@dataclass(frozen=True)
class IoFrame:
    """One Class 1 datagram: connection id, 32-bit sequence, 16-bit count, payload."""

    connection_id: int
    sequence: int
    count: int
    payload: bytes

    def encode(self) -> bytes:
        try:
            data = _COUNT.pack(self.count) + self.payload
        except struct.error as exc:
            raise FramingError(f"sequence count out of range: {exc}") from None
        return cpf.encode_items((
            CpfItem(ItemType.SEQUENCED_ADDRESS,
                    SequencedAddress(self.connection_id, self.sequence).encode()),
            CpfItem(ItemType.CONNECTED_DATA, data)))

    @classmethod
    def decode(cls, raw: bytes) -> IoFrame:
        items = cpf.decode_items(raw)
        if (len(items) != 2 or items[0].type_id != ItemType.SEQUENCED_ADDRESS
                or items[1].type_id != ItemType.CONNECTED_DATA):
            raise FramingError("Class 1 frame must be a sequenced address + connected data")
        addr = SequencedAddress.decode(items[0].data)
        data = items[1].data
        if len(data) < _COUNT.size:
            raise FramingError("connected data item lacks the sequence count")
        (count,) = _COUNT.unpack_from(data)
        return cls(addr.connection_id, addr.sequence, count, bytes(data[_COUNT.size:]))


def input_frame(connection_id: int, sequence: int, count: int, image: InputImage) -> bytes:
    return IoFrame(connection_id, sequence, count, image.encode()).encode()


def output_frame(connection_id: int, sequence: int, count: int, image: OutputImage) -> bytes:
    return IoFrame(connection_id, sequence, count, image.encode()).encode()


#: A whole Class 1 datagram up to the sequence count: item count (2), sequenced address item
#: (type, length 8, connection id, sequence number), connected data item (type, length),
#: the 16-bit sequence count. The payload follows. Same bytes as :meth:`IoFrame.encode`.
_DATAGRAM = struct.Struct("<HHHIIHHH")
_SEQUENCED_LENGTH = 8


class FramePacker:
    """The datagrams of one connection, re-packed in one buffer (cyclic production: no
    dataclasses per frame). The returned buffer is reused by the next :meth:`pack`."""

    def __init__(self, connection_id: int, payload: struct.Struct) -> None:
        self.connection_id = connection_id
        self._payload = payload
        self._data_len = _COUNT.size + payload.size
        self._buf = bytearray(_DATAGRAM.size + payload.size)

    def pack(self, sequence: int, count: int, *values: int) -> bytearray:
        try:
            _DATAGRAM.pack_into(self._buf, 0, 2, ItemType.SEQUENCED_ADDRESS, _SEQUENCED_LENGTH,
                                self.connection_id, sequence, ItemType.CONNECTED_DATA,
                                self._data_len, count)
            self._payload.pack_into(self._buf, _DATAGRAM.size, *values)
        except struct.error as exc:
            raise FramingError(f"Class 1 frame field out of range: {exc}") from None
        return self._buf


def input_packer(connection_id: int) -> FramePacker:
    """T->O: ``pack(sequence, count, position, speed, torque, status)``."""
    return FramePacker(connection_id, _INPUT)


def output_packer(connection_id: int) -> FramePacker:
    """O->T: ``pack(sequence, count, run_idle_header, command)``."""
    return FramePacker(connection_id, _OUTPUT)


_INPUT_DATAGRAM_SIZE = _DATAGRAM.size + _INPUT.size
_INPUT_DATA_LEN = _COUNT.size + _INPUT.size


def unpack_input(raw: bytes) -> tuple[int, int, int, InputImage]:
    """A T->O datagram of the DYN5's exact layout: connection id, sequence number, sequence
    count and image. Anything else (other sizes, item types) is a FramingError."""
    if len(raw) != _INPUT_DATAGRAM_SIZE:
        raise FramingError(f"T->O datagram is {_INPUT_DATAGRAM_SIZE} bytes, got {len(raw)}")
    items, addr_type, addr_len, conn, seq, data_type, data_len, count = _DATAGRAM.unpack_from(raw)
    if (items, addr_type, addr_len, data_type, data_len) != (
            2, ItemType.SEQUENCED_ADDRESS, _SEQUENCED_LENGTH, ItemType.CONNECTED_DATA,
            _INPUT_DATA_LEN):
        raise FramingError("T->O datagram is not a sequenced address + connected data")
    return conn, seq, count, InputImage(*_INPUT.unpack_from(raw, _DATAGRAM.size))


_OUTPUT_DATA_LEN = _COUNT.size + _OUTPUT.size
_OUTPUT_DATAGRAM_SIZE = _DATAGRAM.size + _OUTPUT.size


def decode_frame(raw: bytes) -> IoFrame:
    """:meth:`IoFrame.decode` with a one-struct path for the DYN5's O->T datagram (the
    adapter reads one per connection every RPI); any other shape takes the full decoder."""
    if len(raw) == _OUTPUT_DATAGRAM_SIZE:
        items, addr_type, addr_len, conn, seq, data_type, data_len, count = (
            _DATAGRAM.unpack_from(raw))
        if (items, addr_type, addr_len, data_type, data_len) == (
                2, ItemType.SEQUENCED_ADDRESS, _SEQUENCED_LENGTH, ItemType.CONNECTED_DATA,
                _OUTPUT_DATA_LEN):
            return IoFrame(conn, seq, count, raw[_DATAGRAM.size:])
    return IoFrame.decode(raw)


def seq32_newer(new: int, last: int) -> bool:
    """Serial-number order of 32-bit sequence numbers (wraps)."""
    diff = (new - last) & 0xFFFF_FFFF
    return 0 < diff < 0x8000_0000


def seq16_newer(new: int, last: int) -> bool:
    diff = (new - last) & 0xFFFF
    return 0 < diff < 0x8000
