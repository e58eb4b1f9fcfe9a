"""What an EasyCan reply answers, and which requests wait one at a time (docs/easycan.md).

The EasyCan rules the client hands to the shared
:class:`~servobus.link.transaction.TransactionManager`; pure, no I/O. Decisions (servobus;
the manual gives none):

* **Keys.** A reply carries no sequence number, only the answering motor and the function
  (5.3), so requests and replies are matched on ``(motor, function)``. The position-cache
  reply (0x300|address, 5.3c) is a bare 4-byte position without a motor address: every
  replied cache write shares :data:`POSITION_KEY`. Late replies are owed under the same keys.
* **Lanes.** Requests to one motor run one at a time (lane = the motor's address); different
  motors are served concurrently. Replied cache writes run one at a time on the whole bus
  (:data:`POSITION_LANE`): their replies cannot tell the motors apart. The client reads a
  single register with 0x03, never a one-register 0x12, so a 4-byte reply on the host's
  identifier is always a position reply (the codec's ambiguity never arises).
* **Fit.** Within its key a reply answers the waiting request only when the codec says it
  fits (register and count, :func:`servobus.protocols.easycan.codec.answers`); another
  host's reply of the same kind is not taken for ours.
* **Errors about cache writes.** The motor reports them as an error reply of the write
  function (0x86, see functions.py), so such an error may answer a replied cache write of
  its motor as well as a register write to it. Code 0x05 (interpolation too fast, 5.5) is
  only ever about a cache frame and goes to the cache write first; any other code goes to
  the register write first.
"""

from __future__ import annotations

from collections.abc import Hashable

from servobus.protocols.easycan import codec
from servobus.protocols.easycan.functions import (
    CACHE_ERROR_FUNCTION,
    CacheKind,
    ErrorCode,
    Function,
)
from servobus.protocols.easycan.messages import (
    ErrorReply,
    PositionCacheWrite,
    PositionReply,
    Reply,
    Request,
)

#: What a reply is matched on: (motor address, function code).
Key = tuple[int, int]
#: The key of every position-cache reply (it names no motor).
POSITION_KEY: Key = (-1, int(CacheKind.REPLY))
#: The lane of replied cache writes: the whole bus.
POSITION_LANE = "position-cache"


def request_key(request: Request) -> Key:
    """The key the reply of ``request`` will have."""
    if isinstance(request, PositionCacheWrite):
        return POSITION_KEY
    return request.slave, int(request.function)


def request_lane(request: Request) -> Hashable:
    """Requests of one lane wait for their replies one at a time."""
    if isinstance(request, PositionCacheWrite):
        return POSITION_LANE
    return request.slave


def reply_keys(reply: Reply) -> tuple[Key, ...]:
    """The keys ``reply`` may answer, the likeliest first (module docstring)."""
    if isinstance(reply, PositionReply):
        return (POSITION_KEY,)
    own = (reply.slave, int(reply.function))
    if isinstance(reply, ErrorReply) and reply.function == CACHE_ERROR_FUNCTION:
        if reply.code == ErrorCode.INTERPOLATION_TOO_FAST:
            return POSITION_KEY, own
        return own, POSITION_KEY
    return (own,)


def fits(request: Request, reply: Reply) -> bool:
    """``reply`` answers ``request`` (a normal reply, or an error reply about it)."""
    if isinstance(request, PositionCacheWrite) and isinstance(reply, ErrorReply):
        return reply.slave == request.slave and reply.function == CACHE_ERROR_FUNCTION
    return codec.answers(request, reply)


def describe_key(key: Key) -> str:
    """A reply as logs name it: "READ reply from motor 3"."""
    if key == POSITION_KEY:
        return "position-cache reply"
    motor, function = key
    name = Function(function).name if function in _FUNCTIONS else f"function 0x{function:02X}"
    return f"{name} reply from motor {motor}"


_FUNCTIONS = frozenset(int(f) for f in Function)
