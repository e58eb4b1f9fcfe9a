"""CRC-16/MODBUS: polynomial 0x8005 reflected (0xA001), initial value 0xFFFF, no final XOR.

The frame carries the CRC low byte first, so the CRC of a whole frame including its CRC
is 0 (the check used by :func:`crc_ok`). Check value: CRC of b"123456789" is 0x4B37.

A zero register stays zero over a 0x00 byte (no final XOR): a frame with a good CRC is still
"good" with a 0x00 appended, and a good frame whose CRC high byte is 0x00 is also good one
byte shorter. A framer must not take a CRC match alone as the end of a frame.
"""

from __future__ import annotations

POLYNOMIAL = 0xA001
INITIAL = 0xFFFF


def _table() -> tuple[int, ...]:
    rows = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ POLYNOMIAL if crc & 1 else crc >> 1
        rows.append(crc)
    return tuple(rows)


_TABLE = _table()


def crc16(data: bytes | bytearray | memoryview, crc: int = INITIAL) -> int:
    """The CRC register after ``data`` (low byte goes first on the wire); pass a previous
    result as ``crc`` to continue over more bytes."""
    table = _TABLE
    for b in data:
        crc = (crc >> 8) ^ table[(crc ^ b) & 0xFF]
    return crc


def crc_bytes(data: bytes | bytearray | memoryview) -> bytes:
    """The two CRC bytes as sent after ``data``: low byte, then high byte."""
    return crc16(data).to_bytes(2, "little")


def with_crc(data: bytes | bytearray) -> bytes:
    """``data`` followed by its CRC."""
    return bytes(data) + crc_bytes(data)


def good_lengths(data: bytes | bytearray, start: int, low: int, high: int) -> list[int]:
    """Every length ``low <= n <= high`` for which ``data[start:start + n]`` ends in its own
    CRC, found in one pass (the CRC of a whole frame including its CRC is 0)."""
    found = []
    crc = INITIAL
    table = _TABLE
    end = min(len(data), start + high)
    for n, b in enumerate(data[start:end], 1):
        crc = (crc >> 8) ^ table[(crc ^ b) & 0xFF]
        if crc == 0 and n >= low:
            found.append(n)
    return found


def crc_ok(frame: bytes | bytearray | memoryview) -> bool:
    """True when the last two bytes of ``frame`` are the CRC of the bytes before them."""
    return len(frame) >= 3 and crc16(frame) == 0
