"""Pure EasyCan commands for the host: a request plus what the client must know about it.

Every builder checks its arguments against the YZ-AIM family table (range, access, 32-bit
pairs) and raises ArgumentRangeError before anything exists to be sent. No I/O.

Retry rule (servobus decision, docs/easycan.md): reads are re-sent after a timeout; a write
of a setting (the same value again is harmless) too; a write that moves the motor, saves,
or signals synchronisation (positions, save flag, sync_control, the position cache) and the
emergency stop are never re-sent: a second copy could move twice or restart a cycle.

EEPROM rule (servobus decision, docs/easycan.md): parameters are RAM until the save flag
(0x14) is written (5.2); that write stores every saved register in the EEPROM, so it is the
one write the client's EEPROM guard counts (item "save_flag"; writing 0 saves nothing).

Each command carries what the client needs on its hot path, computed once when it is
built: its frame, whether a reply comes, and the key and lane of that reply (matching.py).
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass, field

from servobus.errors import ArgumentRangeError
from servobus.families.yzaim import registers as yzaim
from servobus.families.yzaim.family import PARAM_NAMES
from servobus.protocols.easycan import codec
from servobus.protocols.easycan.functions import MAX_MULTI_READ
from servobus.protocols.easycan.matching import Key, request_key, request_lane
from servobus.protocols.easycan.messages import (
    ClearPosition,
    EmergencyStop,
    PositionCacheWrite,
    ReadMultipleRequest,
    ReadRequest,
    Request,
    WriteRequest,
)

MIN_ADDRESS = yzaim.BY_NAME["device_address"].minimum  # 1
MAX_ADDRESS = yzaim.BY_NAME["device_address"].maximum  # 254
#: What ``params``/``set`` reach over EasyCan: every parameter of the family.
REACHABLE_PARAMS: tuple[str, ...] = PARAM_NAMES
#: Registers whose write is never re-sent (module docstring).
_ONCE = frozenset({"sync_control"})
#: Registers whose (non-zero) write stores to EEPROM: counted by the EEPROM guard.
_EEPROM = frozenset({"save_flag"})


@dataclass(frozen=True)
class EasyCanCommand:
    request: Request
    what: str  # "read target_speed", "write absolute_position = 100": errors and logs
    retry_safe: bool
    #: Words a write reply must echo (None: not checked - reads, position writes).
    echo: tuple[int, ...] | None = None
    #: The parameter a read returns (decoded with the family table), if any.
    name: str | None = None
    #: The EEPROM guard's item for a write that stores to EEPROM (None: RAM only).
    eeprom_item: str | None = None
    # computed once (module docstring): (arbitration id, data), reply expected, its key/lane
    frame: tuple[int, bytes] = field(init=False, repr=False, compare=False)
    expects_reply: bool = field(init=False, repr=False, compare=False)
    key: Key = field(init=False, repr=False, compare=False)
    lane: Hashable = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        request = self.request
        object.__setattr__(self, "frame", codec.encode(request))
        object.__setattr__(self, "expects_reply", codec.expects_reply(request))
        object.__setattr__(self, "key", request_key(request))
        object.__setattr__(self, "lane", request_lane(request))

    @property
    def slave(self) -> int:
        return self.request.slave


def check_address(address: object) -> int:
    """A motor's EasyCan address 1..254 (register 0x15; 0xFF is the host's)."""
    if isinstance(address, bool) or not isinstance(address, int):
        raise ArgumentRangeError(f"motor address must be an integer, got {address!r}")
    if not MIN_ADDRESS <= address <= MAX_ADDRESS:
        raise ArgumentRangeError(
            f"motor address {address} is outside {MIN_ADDRESS}..{MAX_ADDRESS} "
            "(0xFF is the host's own address)")
    return address


def _span(name: str) -> tuple[int, int]:
    p = yzaim.parameter(name)
    if isinstance(p, yzaim.Pair):
        return p.low, 2
    return p.address, 1


def make_read(slave: int, name: str) -> EasyCanCommand:
    """0x03: one register, or a 32-bit pair as two words."""
    address, count = _span(name)
    return EasyCanCommand(ReadRequest(check_address(slave), address, count),
                          f"read {name}", retry_safe=True, name=name)


def make_read_registers(slave: int, names: tuple[str, ...]) -> EasyCanCommand:
    """0x12: two or three single registers in one frame (one would be ambiguous, see codec)."""
    if not 2 <= len(names) <= MAX_MULTI_READ:
        raise ArgumentRangeError(f"0x12 reads 2..{MAX_MULTI_READ} registers here, got "
                                 f"{len(names)}")
    addresses = tuple(yzaim.register(n).address for n in names)
    return EasyCanCommand(ReadMultipleRequest(check_address(slave), addresses),
                          f"read {', '.join(names)}", retry_safe=True)


def make_write(slave: int, name: str, value: int) -> EasyCanCommand:
    """0x06: a register or a 32-bit pair, range- and access-checked."""
    address, words = yzaim.encode_parameter(name, value)
    p = yzaim.parameter(name)
    action = isinstance(p, yzaim.Pair) or p.access is yzaim.Access.ACTION
    return EasyCanCommand(WriteRequest(check_address(slave), address, words),
                          f"write {name} = {value}", retry_safe=not (action or name in _ONCE),
                          echo=None if action else words,
                          eeprom_item=name if name in _EEPROM and value else None)


def make_move_absolute(slave: int, position: int) -> EasyCanCommand:
    return make_write(slave, "absolute_position", position)


def make_move_relative(slave: int, distance: int) -> EasyCanCommand:
    return make_write(slave, "incremental_position", distance)


def make_emergency_stop(slave: int) -> EasyCanCommand:
    return EasyCanCommand(EmergencyStop(check_address(slave)), "emergency stop",
                          retry_safe=False)


def make_clear_position(slave: int) -> EasyCanCommand:
    """0x11: no reply."""
    return EasyCanCommand(ClearPosition(check_address(slave)), "clear absolute position",
                          retry_safe=False)


def make_cache(slave: int, position: int, *, reply: bool = False) -> EasyCanCommand:
    """Position-cache frame 0x100|slave (silent) or 0x300|slave (answers the position)."""
    yzaim.PAIR_BY_NAME["position_cache"].check(position)
    return EasyCanCommand(PositionCacheWrite(check_address(slave), position, reply),
                          f"position cache = {position}", retry_safe=False)
