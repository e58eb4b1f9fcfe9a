"""EasyCan front end: virtual YZ-AIM motors as nodes on one CAN bus (manual 5.3, 5.5).

``EasyCanNetwork.handle_raw(id, data)`` executes one host frame on the motor it addresses
and returns the frames to send back; the caller advances the motors' time first.
:func:`serve` runs a network on any FramePort (a python-can bus, the socketcand hub) in
wall-clock time. The motors' behaviour is :mod:`servobus.sim.yzaim.motor`'s; this module only
maps frames. Decisions where the manual is silent:

* A frame that does not decode as a request (a reply on the host's identifier, an identifier
  outside 0x0xx/0x1xx/0x3xx, a cache frame of the wrong length) is ignored and counted; a
  request naming a function or length the table does not have is answered with error 0x03
  or 0x04 by the motor it addresses (the codec's MalformedRequest).
* Reads of 0 or more than 2 registers (0x03) answer 0x04; addresses past 0x1D answer 0x02.
* A write reply carries what the registers hold after the write (the motor's rule; an
  accepted save-flag write shows the value written, as 5.4a does), except writes to 0x0C or
  0x16, which answer the current absolute position (5.3b note: "When the written register
  address is 0xC (incremental position), the returned data is the current absolute
  position", the same for 0x16). A one-word write answers its low word: the reply keeps
  the request's length, as every 5.3b reply does.
* A cache write that comes too fast (the motor's TOO_FAST) answers 0x86 code 0x05 when the
  frame asked for a reply (0x3xx) and is dropped silently otherwise (0x1xx), counted.
* Motors answer on their power-on address (register 0x15 takes effect after a power cycle).
* Timing: a frame is executed as of the instant it reached the bus (its receive timestamp),
  not when this process got round to it, so the 2 ms cycle a cache frame belongs to does not
  depend on the simulator's own scheduling delays. Frames that reached the simulator
  together (``batch``: the socketcand hub's stamp of one TCP read) carry no such instant
  each; the motor queues their cache values one per cycle instead of refusing them (the
  motor's module doc).
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from dataclasses import dataclass

from servobus.errors import FramingError
from servobus.families.yzaim import registers as yzaim
from servobus.protocols.easycan import codec
from servobus.protocols.easycan.functions import (
    CACHE_ERROR_FUNCTION,
    MAX_READ_WORDS,
    POSITION_ECHO_ADDRESSES,
    ErrorCode,
)
from servobus.protocols.easycan.messages import (
    ClearPosition,
    EmergencyStop,
    EmergencyStopReply,
    ErrorReply,
    PositionCacheWrite,
    PositionReply,
    ReadMultipleReply,
    ReadMultipleRequest,
    ReadReply,
    ReadRequest,
    Reply,
    Request,
    WriteReply,
    WriteRequest,
)
from servobus.sim.yzaim.motor import MotorRefused, Refusal, YzaimMotor

_ABS_LOW = yzaim.PAIR_BY_NAME["absolute_position"].low
_CODES: dict[Refusal, ErrorCode] = {
    Refusal.ILLEGAL_ADDRESS: ErrorCode.ILLEGAL_ADDRESS,
    Refusal.TOO_FAST: ErrorCode.INTERPOLATION_TOO_FAST,
}


@dataclass
class NodeStats:
    frames: int = 0
    replies: int = 0
    errors: int = 0
    ignored: int = 0  # not a request (or for no motor here)
    cache_dropped: int = 0  # silent cache frames refused as too fast


class EasyCanNetwork:
    """Several YzaimMotors as EasyCan nodes on one bus."""

    def __init__(self, motors: Sequence[YzaimMotor]) -> None:
        self.motors = list(motors)
        self.stats = NodeStats()

    @property
    def drives(self) -> list[YzaimMotor]:
        return self.motors

    def motor(self, address: int) -> YzaimMotor | None:
        for m in self.motors:
            if m.address == address:
                return m
        return None

    def handle_raw(self, arbitration_id: int, data: bytes, now: float | None = None,
                   batch: Hashable | None = None) -> list[tuple[int, bytes]]:
        """Execute one frame that reached the bus at simulated time ``now``: it first
        advances the motor it addresses (only that one: O(1) per frame however many motors
        share the bus); a motor already past ``now`` executes it as of ``now``. ``batch``:
        a key shared by frames received together (module doc)."""
        self.stats.frames += 1
        try:
            request = codec.decode_request(arbitration_id, data)
        except codec.MalformedRequest as bad:
            if self.motor(bad.slave) is None:
                self.stats.ignored += 1
                return []
            return self._out(bad.error_reply())
        except FramingError:
            self.stats.ignored += 1
            return []
        motor = self.motor(request.slave)
        if motor is None:
            self.stats.ignored += 1
            return []
        if now is not None and now > motor.time:
            motor.advance_to(now)
        return self._out(self.execute(motor, request, now, batch))

    def _out(self, reply: Reply | None) -> list[tuple[int, bytes]]:
        if reply is None:
            return []
        self.stats.replies += 1
        if isinstance(reply, ErrorReply):
            self.stats.errors += 1
        return [codec.encode(reply)]

    def execute(self, motor: YzaimMotor, request: Request, at: float | None = None,
                batch: Hashable | None = None) -> Reply | None:
        try:
            return _execute(motor, request, at, batch)
        except MotorRefused as exc:
            code = _CODES[exc.reason]
            if not isinstance(request, PositionCacheWrite):
                return ErrorReply(request.slave, int(request.function), code, request.host)
            if not request.reply:
                self.stats.cache_dropped += 1
                return None
            return ErrorReply(request.slave, int(CACHE_ERROR_FUNCTION), code)


def _execute(motor: YzaimMotor, request: Request, at: float | None,
             batch: Hashable | None) -> Reply | None:
    match request:
        case ReadRequest():
            if not 1 <= request.count <= MAX_READ_WORDS:
                return ErrorReply(request.slave, request.function,
                                  ErrorCode.ILLEGAL_DATA_LENGTH, request.host)
            words = motor.read_words(request.address, request.count)
            return ReadReply(request.slave, request.address, words, request.host)
        case WriteRequest():
            words = motor.write_words(request.address, request.values, at=at)
            if request.address in POSITION_ECHO_ADDRESSES:  # 5.3b: the current position
                words = motor.read_words(_ABS_LOW, 2)[:len(words)]
            return WriteReply(request.slave, request.address, words, request.host)
        case EmergencyStop():
            motor.emergency_stop()
            return EmergencyStopReply(request.slave, request.host)
        case ClearPosition():
            motor.clear_position()
            return None
        case ReadMultipleRequest():
            for a in request.addresses:
                motor.read_words(a, 1)  # MotorRefused before any value is read
            words = tuple(motor.read_word(a) for a in request.addresses)
            return ReadMultipleReply(request.slave, words, request.host)
        case PositionCacheWrite():
            position = motor.write_position_cache(request.position, at=at, batch=batch)
            return PositionReply(position) if request.reply else None
    return None  # pragma: no cover
