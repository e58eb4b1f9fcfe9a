"""The device side of a Modbus RTU line: virtual YZ-AIM motors answering request frames.

Pure-ish: no I/O and no clock. :meth:`ModbusLine.handle` takes one request frame whose CRC
checked (the runner's framer cut it from the byte stream) and returns the reply bytes,
possibly none; pacing is :mod:`servobus.protocols.modbus.pacing`, sockets
:mod:`servobus.protocols.modbus.server`. The registers, ranges and behaviour are the
motor's (:class:`servobus.sim.yzaim.motor.YzaimMotor`); this module only maps frames.

Decisions where spec 004 is silent about its serial side (docs/modbus.md; Modbus
Application Protocol v1.1b3 sections 6.3, 6.6, 6.12, 7; Serial Line v1.02 2.1):

* **Addressing.** A motor answers requests for its device address (0x15, effective since its
  last power-on). Frames for addresses nobody has get silence. Broadcast (address 0)
  writes are executed by every motor and answered by none; broadcast reads are ignored.
  Two motors sharing an address both execute the request; their replies would collide on
  the wire, which the line models as silence (the host's deadline passes).
* **Bad CRC** frames never reach this module (the framer drops them: silence), as the
  standard requires; the runner reports them in :attr:`ModbusLine.crc_errors`.
* **Exceptions.** Function other than 0x03/0x06/0x10: 1 ILLEGAL_FUNCTION. A count outside
  1..125 (read) or 1..123 (write): 3 ILLEGAL_DATA_VALUE. Any register of the span outside
  0x00..0x1D, or a write to a read-only register: 2 ILLEGAL_DATA_ADDRESS. A value outside
  the register's range (the family table): 3 ILLEGAL_DATA_VALUE, and nothing of that
  write is applied. A write while modbus_enable (0x00) is 0, other than switching it on:
  4 SERVER_DEVICE_FAILURE (the motor ignores it, spec 004 section 6: "you must first enable
  the modbus"). A position-cache write within one 2 ms cycle (the EasyCan error 0x05 of
  section 5.5): 6 SERVER_DEVICE_BUSY. EasyCan has no error for a bad value (its write reply
  shows what the register holds); Modbus has, so the serial side reports it.
* **Write replies** follow the standard: 0x06 echoes the request (also for 0x0C/0x16,
  whose EasyCan twin returns the current position - read 0x16 for it), 0x10 returns the
  start address and count.
"""

from __future__ import annotations

from collections.abc import Sequence

from servobus.errors import ProtocolError
from servobus.families.yzaim import registers as Y
from servobus.protocols.modbus import codec as C
from servobus.sim.yzaim.motor import MotorRefused, Refusal, YzaimMotor

E = C.ExceptionCode
#: Motor refusals -> Modbus exception codes.
REFUSAL_CODES: dict[Refusal, C.ExceptionCode] = {
    Refusal.ILLEGAL_ADDRESS: E.ILLEGAL_DATA_ADDRESS,
    Refusal.TOO_FAST: E.SERVER_DEVICE_BUSY,
}
_PAIR_WORDS = frozenset(a for p in Y.PAIRS for a in (p.low, p.high))
_ENABLE = Y.BY_NAME["modbus_enable"]


class ModbusLine:
    """Several virtual YZ-AIM motors sharing one Modbus RTU line."""

    def __init__(self, motors: Sequence[YzaimMotor]) -> None:
        self.motors: list[YzaimMotor] = list(motors)
        self.frames = 0  # request frames with a good CRC (any address)
        self.replies = 0
        self.exceptions = 0
        self.broadcasts = 0
        self.unaddressed = 0  # frames for an address nobody has (silence)
        self.collisions = 0  # replies suppressed because several motors share an address
        self.crc_errors = 0  # runs shaped like a frame that failed the CRC (silence)
        self.discarded = 0  # bytes the framers dropped

    @property
    def drives(self) -> list[YzaimMotor]:
        """What the real-time clock advances."""
        return self.motors

    def addressed(self, address: int) -> list[YzaimMotor]:
        return [m for m in self.motors if m.address == address]

    def note_dropped(self, crc_errors: int, discarded: int) -> None:
        self.crc_errors += crc_errors
        self.discarded += discarded

    # ------------------------------------------------------------------ frames
    def handle(self, raw: bytes) -> bytes:
        """Execute one request frame (good CRC); return the reply bytes (maybe none)."""
        try:
            request = C.decode_request(raw)
        except ProtocolError:
            self.discarded += len(raw)
            return b""
        self.frames += 1
        if request.address == C.BROADCAST:
            self.broadcasts += 1
            if not isinstance(request, C.ReadHoldingRequest | C.UnsupportedRequest):
                for motor in self.motors:
                    self.execute(motor, request)
            return b""
        motors = self.addressed(request.address)
        if not motors:
            self.unaddressed += 1
            return b""
        replies = [self.execute(motor, request) for motor in motors]
        if len(replies) > 1:
            self.collisions += 1
            return b""
        reply = replies[0]
        if isinstance(reply, C.ExceptionReply):
            self.exceptions += 1
        self.replies += 1
        return C.encode_reply(reply)

    def execute(self, motor: YzaimMotor, request: C.Request | C.UnsupportedRequest) -> C.Reply:
        """What ``motor`` does with ``request``: its normal reply or an exception reply."""
        code = C.request_exception(request)
        if code is not None:
            return C.ExceptionReply(request.address, request.function, code)
        try:
            match request:
                case C.ReadHoldingRequest(address, start, count):
                    return C.ReadHoldingReply(address, motor.read_words(start, count))
                case C.WriteSingleRequest(address, register, value):
                    refused = _write_refusal(motor, register, (value,))
                    if refused is None:
                        motor.write_words(register, (value,))
                        return C.WriteSingleReply(address, register, value)
                case C.WriteMultipleRequest(address, start, values):
                    refused = _write_refusal(motor, start, values)
                    if refused is None:
                        motor.write_words(start, values)
                        return C.WriteMultipleReply(address, start, len(values))
        except MotorRefused as exc:
            refused = REFUSAL_CODES.get(exc.reason, E.SERVER_DEVICE_FAILURE)
        assert refused is not None  # every request type returned above or refused
        return C.ExceptionReply(request.address, request.function, refused)


def _write_refusal(motor: YzaimMotor, start: int, words: Sequence[int]) -> C.ExceptionCode | None:
    """Why the motor would not apply this write (module doc), checked before any of it is."""
    end = start + len(words)
    if start < 0 or end > Y.REGISTER_COUNT:
        return E.ILLEGAL_DATA_ADDRESS
    for address, word in zip(range(start, end), words, strict=True):
        reg = Y.BY_ADDRESS[address]
        if not reg.writable:
            return E.ILLEGAL_DATA_ADDRESS
        if address not in _PAIR_WORDS and not reg.valid(reg.from_word(word)):
            return E.ILLEGAL_DATA_VALUE
    switching_on = start == _ENABLE.address and words[0] == 1
    if not motor.read_word(_ENABLE.address) and not switching_on and (
            start != _ENABLE.address or len(words) > 1):
        return E.SERVER_DEVICE_FAILURE
    return None
