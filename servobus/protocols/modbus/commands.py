"""Pure Modbus RTU commands for the host: the request a register read or write becomes.

No I/O: the client (:mod:`servobus.protocols.modbus.client`) sends what these build, and the
codec checks every field's range when it encodes. A read cannot be broadcast (address 0 gets
no reply); a write of one word is function 0x06, of more words 0x10 (a 32-bit pair in one
frame, so the device takes both words together).
"""

from __future__ import annotations

from collections.abc import Sequence

from servobus.errors import ArgumentRangeError
from servobus.protocols.modbus import codec as C


def make_read(address: int, start: int, count: int = 1) -> C.ReadHoldingRequest:
    """Read ``count`` holding registers (function 0x03) from device ``address``."""
    if isinstance(address, bool) or not isinstance(address, int):
        raise ArgumentRangeError(f"device address must be an integer, got {address!r}")
    if address == C.BROADCAST:
        raise ArgumentRangeError("a read cannot be broadcast (address 0 gets no reply)")
    return C.ReadHoldingRequest(address, start, count)


def make_write(address: int, start: int,
               values: Sequence[int]) -> C.WriteSingleRequest | C.WriteMultipleRequest:
    """Write registers from ``start``: 0x06 for one word, 0x10 for more. Address 0
    broadcasts (no reply)."""
    words = tuple(values)
    if len(words) == 1:
        return C.WriteSingleRequest(address, start, words[0])
    return C.WriteMultipleRequest(address, start, words)
