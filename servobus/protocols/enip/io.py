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
from servobus.families import dyn5
from servobus.protocols.enip import cpf
from servobus.protocols.enip.cpf import CpfItem, ItemType, SequencedAddress

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


def seq32_newer(new: int, last: int) -> bool:
    """Serial-number order of 32-bit sequence numbers (wraps)."""
    diff = (new - last) & 0xFFFF_FFFF
    return 0 < diff < 0x8000_0000


def seq16_newer(new: int, last: int) -> bool:
    diff = (new - last) & 0xFFFF
    return 0 < diff < 0x8000
