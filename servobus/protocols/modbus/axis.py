"""ModbusAxis: one YZ-AIM motor on a Modbus RTU line, in the Axis units (docs/modbus.md).

Positions are encoder counts (32,768 per revolution), speeds rpm, currents A. The mapping
of the Axis calls onto the YZ-AIM registers is :mod:`servobus.families.yzaim.axis`'s (shared
with EasyCan); what the serial port does its own way (manual sections in brackets):

* Registers are read with 0x03 (a span: the status read takes output_enable 0x01 ..
  motor_speed 0x10, on to the position 0x17 when the axis commanded a target); 32-bit
  values go in one write-multiple (0x10) frame, low word first, so the motor takes both
  words together. A write is sent exactly once: a lost reply raises DriveTimeout.
* ``move_by`` with no target known reads the position first (the write reply has none).
* ``emergency_stop()``: 0 to 0x0C with gear numerator 0 (4.7; the gear numerator is set to
  0 for it and back). ``set_origin()`` clears the absolute position the manual's way (4.7):
  gear numerator 0, 0 to 0x16, then the gear numerator back.
* ``enable()`` takes communication control and energises in one frame (0x00 = 1, 0x01 = 1).
* ``save_parameters()`` asks the client's EEPROM guard first.
* An exception 4 from the virtual motor on a write means modbus_enable is 0: the error says
  so (docs/modbus.md).
"""

from __future__ import annotations

from servobus.axis.base import check_int
from servobus.errors import ArgumentRangeError, DriveError
from servobus.families.yzaim import registers as Y
from servobus.families.yzaim.axis import ABS, ADDRESS, INC, R, YzaimAxis
from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus.client import AsyncModbusClient
from servobus.protocols.modbus.params import REACHABLE_PARAMS

#: One status read: output_enable 0x01 .. motor_speed 0x10 (and on to the position 0x17
#: when the axis commanded a target).
STATUS_FIRST = R["output_enable"].address
STATUS_LAST = R["motor_speed"].address
DEVICE_FAILURE = int(C.ExceptionCode.SERVER_DEVICE_FAILURE)


def check_address(address: object) -> int:
    """A YZ-AIM device address 1..254 (register 0x15), or ArgumentRangeError."""
    value = check_int("drive id", address)
    if not ADDRESS.minimum <= value <= ADDRESS.maximum:
        raise ArgumentRangeError(f"drive id {value} is outside the YZ-AIM addresses "
                                 f"{ADDRESS.minimum}..{ADDRESS.maximum} (register 0x15)")
    return value


class ModbusAxis(YzaimAxis[AsyncModbusClient]):
    """One YZ-AIM motor on a Modbus RTU line."""

    protocol_name = "modbus"
    reachable_params = REACHABLE_PARAMS

    def _check_id(self, drive_id: int) -> int:
        return check_address(drive_id)

    # ------------------------------------------------------------- register access
    async def read_words(self, start: int, count: int = 1, *, retries: int | None = None,
                         timeout: float | None = None) -> tuple[int, ...]:
        """Raw 16-bit words of registers ``start..start+count-1`` (retried, bounded)."""
        return await self.client.read(self._id, start, count, retries=retries, timeout=timeout)

    async def write_words(self, start: int, words: tuple[int, ...]) -> None:
        """Write raw words once (never re-sent); an exception 4 is explained (module doc)."""
        try:
            await self.client.write(self._id, start, words)
        except DriveError as exc:
            if exc.code == DEVICE_FAILURE:
                raise DriveError(f"{exc}; the motor takes no writes while modbus_enable "
                                 "(0x00) is 0: enable() switches it on", code=exc.code,
                                 drive_id=exc.drive_id) from None
            raise

    async def _write(self, name: str, value: int) -> None:
        start, words = Y.encode_parameter(name, int(value))
        await self.write_words(start, words)

    async def _read(self, name: str) -> int:
        p = Y.parameter(name)
        start, count = (p.low, 2) if isinstance(p, Y.Pair) else (p.address, 1)
        return Y.decode_parameter(name, await self.read_words(start, count))

    async def _read_words(self, names: tuple[str, ...]) -> tuple[int, ...]:
        """One read of the span the registers cover, picked out in the order named."""
        addresses = [R[name].address for name in names]
        first = min(addresses)
        words = await self.read_words(first, max(addresses) - first + 1)
        return tuple(words[a - first] for a in addresses)

    def ping_deadline(self) -> float:
        """The RTU deadline of the one-register read a ping sends: request + t3.5 + reply on
        the wire at the line's baud rate + ``turnaround_s`` (policy.py)."""
        return self.client.policy.deadline_s(
            C.ReadHoldingRequest(self._id, R["alarm_code"].address, 1))

    async def _probe(self, timeout: float) -> None:
        await self.read_words(R["alarm_code"].address, retries=0, timeout=timeout)

    async def _read_status(self, *, with_position: bool) -> tuple[int, int, int, int | None]:
        """One frame: the status registers and, when asked, on to the position."""
        last = ABS.high if with_position else STATUS_LAST
        words = await self.read_words(STATUS_FIRST, last - STATUS_FIRST + 1)

        def word(name: str) -> int:
            return words[R[name].address - STATUS_FIRST]

        position = Y.join32(words[ABS.low - STATUS_FIRST],
                            words[ABS.high - STATUS_FIRST]) if with_position else None
        return word("output_enable"), word("alarm_code"), word("motor_speed"), position

    # ------------------------------------------------------------- the serial port's means
    async def _with_gear_zero(self, start: int, words: tuple[int, int]) -> None:
        """Write ``words`` with gear numerator 0 (4.7's special functions), then restore it."""
        gear = await self.read_param("gear_numerator")
        if gear:
            await self._write("gear_numerator", 0)
        try:
            await self.write_words(start, words)
        finally:
            self._target = None
            if gear:
                await self._write("gear_numerator", gear)

    async def emergency_stop(self) -> None:
        """0 to the increment with gear numerator 0 (4.7): the motor stops at once, braked by
        its position loop; speed mode ends."""
        await self._with_gear_zero(INC.low, Y.split32(0))
        self._speed_mode = None

    async def set_origin(self) -> None:
        """0 to the absolute position with gear numerator 0 (4.7): here becomes 0."""
        await self._with_gear_zero(ABS.low, Y.split32(0))

    async def enable(self) -> None:
        """Communication control and output on: 0x00 = 1, 0x01 = 1 in one frame."""
        await self.write_words(R["modbus_enable"].address, (1, 1))

    async def save_parameters(self) -> None:
        """The EEPROM guard first, then the save flag (module docstring)."""
        self.client.guard.check(self._id, "save_flag")
        await super().save_parameters()
