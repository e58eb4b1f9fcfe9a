"""EasyCan function codes, frame lengths and error codes: the one table of the protocol.

YZ-AIM manual 5.3 (frame formats) and 5.5 (error codes). CAN 2.0A data frames at
1 Mbit/s. Identifier = the receiver's address: a request goes to the slave's address
(0x000|address), a reply to the host's (0xFF). Request data starts with the host's
address and the function code, reply data with the slave's address and the function code;
register values are 16-bit little-endian words. Position-cache frames carry no function
code: identifier 0x100|address writes the cache silently, 0x300|address writes it and the
slave answers, on the host's identifier, with the current absolute position (4 bytes).

Decisions where the manual is silent or contradicts itself (see docs/easycan.md):

* The host's address is 0xFF (every example); slave addresses are 0x00..0xFE on the wire
  (the register 0x15 range 1..254 is enforced by the family table, not the codec).
* Read (0x03) asks for 1 or 2 registers, write (0x06) carries 1 or 2 (5.5 error 0x04
  "only two 16-bit numbers at a time"); 0x12 names 1 to 3 registers (the manual shows 3).
* Absolute position clear (0x11): the example gives DLC 4 but shows only the host address
  and the function code; servobus sends FF 11 00 00 and accepts 2 to 4 data bytes.
* The error example ``01 90 00`` carries code 0x00, which the code table (0x02-0x05) does
  not list: any code byte decodes; unknown codes are shown as such.
* A 4-byte frame on the host's identifier is a position-cache reply unless the receiver
  knows it waits for a one-register 0x12 reply (the frame itself cannot tell).
* Errors about position-cache frames (0x05 interpolation too fast) are sent as an error
  reply of the write function (0x86): the cache frame has no function code of its own and
  it writes registers 0x1A/0x1B.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from servobus.families.yzaim import registers as yzaim

BITRATE = 1_000_000
HOST_ADDRESS = 0xFF
MAX_SLAVE_ADDRESS = 0xFE
MAX_ARBITRATION_ID = 0x7FF  # CAN 2.0A base identifier
ADDRESS_MASK = 0x0FF
MAX_DATA = 8
HEADER = 2  # address byte + function code
ERROR_FLAG = 0x80
ERROR_LENGTH = 3  # slave address, function | 0x80, code
MAX_READ_WORDS = 2
MAX_WRITE_WORDS = 2
MAX_MULTI_READ = 3
POSITION_BYTES = 4  # position-cache frames and their reply: signed 32-bit little-endian
CLEAR_POSITION_SENT = 4  # DLC servobus sends for 0x11 (5.3e)

#: Writes whose reply carries the current absolute position instead of the echo (5.3b note).
POSITION_ECHO_ADDRESSES: frozenset[int] = frozenset(
    {yzaim.PAIR_BY_NAME["incremental_position"].low,
     yzaim.PAIR_BY_NAME["absolute_position"].low}
)


class Function(IntEnum):
    READ = 0x03
    WRITE = 0x06
    EMERGENCY_STOP = 0x10
    CLEAR_POSITION = 0x11
    READ_MULTIPLE = 0x12


class CacheKind(IntEnum):
    """Identifier bits 8..10 of a position-cache frame (5.3c)."""

    SILENT = 0x100  # write the cache, no reply
    REPLY = 0x300  # write the cache, the slave answers with its absolute position


class ErrorCode(IntEnum):
    """Error reply codes (5.5)."""

    ILLEGAL_ADDRESS = 0x02
    ILLEGAL_FUNCTION = 0x03
    ILLEGAL_DATA_LENGTH = 0x04
    INTERPOLATION_TOO_FAST = 0x05


ERROR_TEXTS: dict[ErrorCode, str] = {
    ErrorCode.ILLEGAL_ADDRESS: "illegal register address (beyond the last register)",
    ErrorCode.ILLEGAL_FUNCTION: "illegal function code",
    ErrorCode.ILLEGAL_DATA_LENGTH: "illegal data length (at most two 16-bit registers)",
    ErrorCode.INTERPOLATION_TOO_FAST: "position-cache frames faster than one per 2 ms",
}

CACHE_ERROR_FUNCTION = Function.WRITE  # function an error about a cache frame names


def error_text(code: int) -> str:
    try:
        return ERROR_TEXTS[ErrorCode(code)]
    except ValueError:
        return f"unknown error code 0x{code:02X}"


@dataclass(frozen=True)
class FunctionSpec:
    function: Function
    request_lengths: tuple[int, ...]  # data lengths the drive accepts
    reply_lengths: tuple[int, ...]  # data lengths of its reply; () = no reply
    doc: str

    @property
    def expects_reply(self) -> bool:
        return bool(self.reply_lengths)


def _words(header: int, most: int) -> tuple[int, ...]:
    return tuple(header + 2 * n for n in range(1, most + 1))


_F = Function

#: THE EasyCan function table (5.3): data lengths both ways.
SPECS: dict[Function, FunctionSpec] = {
    s.function: s
    for s in (
        FunctionSpec(_F.READ, (HEADER + 2,), _words(HEADER + 2, MAX_READ_WORDS),
                     "read 1-2 consecutive registers: address, count"),
        FunctionSpec(_F.WRITE, _words(HEADER + 2, MAX_WRITE_WORDS),
                     _words(HEADER + 2, MAX_WRITE_WORDS),
                     "write 1-2 consecutive registers: address, count, words; the reply "
                     "echoes them (0x0C/0x16: the current absolute position)"),
        FunctionSpec(_F.EMERGENCY_STOP, (HEADER,), (HEADER,), "stop immediately"),
        FunctionSpec(_F.CLEAR_POSITION, tuple(range(HEADER, CLEAR_POSITION_SENT + 1)), (),
                     "clear the absolute position, no reply"),
        FunctionSpec(_F.READ_MULTIPLE, tuple(range(HEADER + 1, HEADER + MAX_MULTI_READ + 1)),
                     _words(HEADER, MAX_MULTI_READ),
                     "read 1-3 arbitrary registers: their addresses; reply: their words"),
    )
}
