"""EasyCan messages as frozen dataclasses, one per frame shape (manual 5.3).

Construction checks structure only (bytes fit, word counts the frame can carry), raising
ArgumentRangeError; register ranges and access are the family table's business
(servobus.families.yzaim.registers), so a virtual drive can still be sent out-of-range values.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from servobus.errors import ArgumentRangeError
from servobus.families.yzaim.registers import INT32_MAX, INT32_MIN, WORD_MAX, join32
from servobus.protocols.easycan.functions import (
    ERROR_FLAG,
    HOST_ADDRESS,
    MAX_MULTI_READ,
    MAX_SLAVE_ADDRESS,
    MAX_WRITE_WORDS,
    POSITION_ECHO_ADDRESSES,
    Function,
)


def _check(name: str, value: int, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ArgumentRangeError(f"{name} {value!r} is outside {lo}..{hi}")


def _check_words(name: str, words: tuple[int, ...], most: int) -> None:
    if not 1 <= len(words) <= most:
        raise ArgumentRangeError(f"{name}: {len(words)} values, the frame carries 1..{most}")
    for w in words:
        _check(f"{name} word", w, 0, WORD_MAX)


def _check_ends(slave: int, host: int) -> None:
    _check("slave address", slave, 0, MAX_SLAVE_ADDRESS)
    _check("host address", host, 0, 0xFF)


# ------------------------------------------------------------------ requests (host -> drive)
@dataclass(frozen=True)
class ReadRequest:
    """0x03: read ``count`` consecutive registers from ``address`` (the drive allows 1..2)."""

    slave: int
    address: int
    count: int = 1
    host: int = HOST_ADDRESS
    function: ClassVar[Function] = Function.READ

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)
        _check("register address", self.address, 0, 0xFF)
        _check("register count", self.count, 0, 0xFF)


@dataclass(frozen=True)
class WriteRequest:
    """0x06: write 1 or 2 consecutive registers from ``address`` (16-bit wire words)."""

    slave: int
    address: int
    values: tuple[int, ...]
    host: int = HOST_ADDRESS
    function: ClassVar[Function] = Function.WRITE

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)
        _check("register address", self.address, 0, 0xFF)
        _check_words("write", self.values, MAX_WRITE_WORDS)


@dataclass(frozen=True)
class EmergencyStop:
    """0x10: stop immediately; the drive answers."""

    slave: int
    host: int = HOST_ADDRESS
    function: ClassVar[Function] = Function.EMERGENCY_STOP

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)


@dataclass(frozen=True)
class ClearPosition:
    """0x11: clear the absolute position to 0; the drive does not answer."""

    slave: int
    host: int = HOST_ADDRESS
    function: ClassVar[Function] = Function.CLEAR_POSITION

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)


@dataclass(frozen=True)
class ReadMultipleRequest:
    """0x12: read 1..3 arbitrary registers in one frame."""

    slave: int
    addresses: tuple[int, ...]
    host: int = HOST_ADDRESS
    function: ClassVar[Function] = Function.READ_MULTIPLE

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)
        if not 1 <= len(self.addresses) <= MAX_MULTI_READ:
            raise ArgumentRangeError(
                f"0x12 reads 1..{MAX_MULTI_READ} registers, got {len(self.addresses)}")
        for a in self.addresses:
            _check("register address", a, 0, 0xFF)


@dataclass(frozen=True)
class PositionCacheWrite:
    """Identifier 0x100|slave (silent) or 0x300|slave (``reply``): absolute position cache."""

    slave: int
    position: int  # signed 32-bit encoder counts
    reply: bool = False

    def __post_init__(self) -> None:
        _check("slave address", self.slave, 0, MAX_SLAVE_ADDRESS)
        _check("cache position", self.position, INT32_MIN, INT32_MAX)


Request = (ReadRequest | WriteRequest | EmergencyStop | ClearPosition | ReadMultipleRequest
           | PositionCacheWrite)


# ------------------------------------------------------------------ replies (drive -> host)
@dataclass(frozen=True)
class ReadReply:
    """0x03 reply: the registers' words from ``address`` on."""

    slave: int
    address: int
    values: tuple[int, ...]
    host: int = HOST_ADDRESS
    function: ClassVar[Function] = Function.READ

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)
        _check("register address", self.address, 0, 0xFF)
        _check_words("read reply", self.values, MAX_WRITE_WORDS)


@dataclass(frozen=True)
class WriteReply:
    """0x06 reply: the written words, or for 0x0C/0x16 the current absolute position."""

    slave: int
    address: int
    values: tuple[int, ...]
    host: int = HOST_ADDRESS
    function: ClassVar[Function] = Function.WRITE

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)
        _check("register address", self.address, 0, 0xFF)
        _check_words("write reply", self.values, MAX_WRITE_WORDS)

    @property
    def position(self) -> int | None:
        """The current absolute position a position write returns (None for other writes)."""
        if self.address not in POSITION_ECHO_ADDRESSES or len(self.values) != 2:
            return None
        return join32(self.values[0], self.values[1])


@dataclass(frozen=True)
class EmergencyStopReply:
    slave: int
    host: int = HOST_ADDRESS
    function: ClassVar[Function] = Function.EMERGENCY_STOP

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)


@dataclass(frozen=True)
class ReadMultipleReply:
    """0x12 reply: one word per requested register, in request order (no addresses)."""

    slave: int
    values: tuple[int, ...]
    host: int = HOST_ADDRESS
    function: ClassVar[Function] = Function.READ_MULTIPLE

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)
        _check_words("0x12 reply", self.values, MAX_MULTI_READ)


@dataclass(frozen=True)
class PositionReply:
    """Reply to a 0x300|slave cache write: the current absolute position (no slave address)."""

    position: int
    host: int = HOST_ADDRESS

    def __post_init__(self) -> None:
        _check("position", self.position, INT32_MIN, INT32_MAX)
        _check("host address", self.host, 0, 0xFF)


@dataclass(frozen=True)
class ErrorReply:
    """Function | 0x80 and an error code (5.5)."""

    slave: int
    function: int  # the function code the error is about (without 0x80)
    code: int
    host: int = HOST_ADDRESS

    def __post_init__(self) -> None:
        _check_ends(self.slave, self.host)
        _check("function code", self.function, 0, ERROR_FLAG - 1)
        _check("error code", self.code, 0, 0xFF)


Reply = (ReadReply | WriteReply | EmergencyStopReply | ReadMultipleReply | PositionReply
         | ErrorReply)
Message = Request | Reply
