"""ModbusAxis: one YZ-AIM motor on a Modbus RTU line, in the Axis units (docs/modbus.md).

Positions are encoder counts (32,768 per revolution), speeds rpm, currents A. Registers,
parameters and the status decoding are the YZ-AIM family's (servobus.families.yzaim and
yzaim_family); 32-bit values go in one write-multiple (0x10) frame, low word first, so the
motor takes both words together. The calls behave as on EasyCan (docs/easycan.md), with
the serial port's means (manual sections in brackets):

* ``move_to(p)`` writes the absolute position 0x16/0x17, ``move_by(d)`` the increment
  0x0C/0x0D (5.4a), after 0x19 = 0 when the motor may be in speed mode. With gear numerator
  0 (communication control, 4.7/4.8) writing 0 there is special (0 to 0x16 clears the
  position, 0 to 0x0C stops), so a target of 0 is sent as 1, as 5.4a goes "back to the
  origin" (one count, inside its +-10), and ``move_by(0)`` sends nothing.
* A write is sent exactly once: a lost reply raises DriveTimeout and is never re-sent.
* In position (5.4a): the motor reports none; the axis remembers the target it sent (a
  relative move adds to it; with none known it starts from a position read) and the
  family's ``axis_status`` compares the position with it (+-10 counts).
* ``turn(rpm)``: speed mode (0x19 = 3) at |rpm| on 0x02, the sign on 0x09 dir_polarity
  (0 = increasing position). 0x02 is also the speed of position moves: the axis keeps the
  value it replaced and writes it back when it returns to position mode. ``stop()`` =
  ``turn(0)``: ramps down at 0x03 and holds. ``emergency_stop()``: 0 to 0x0C with gear
  numerator 0 (4.7; the gear numerator is set to 0 for it and back).
* ``set_origin()`` clears the absolute position the manual's way (4.7): gear numerator 0,
  0 to 0x16, then the gear numerator back.
* ``enable()`` takes communication control and energises (0x00 = 1, 0x01 = 1 in one frame);
  ``disable()`` frees the motor; ``reset()`` writes 0x01 = 0 then 1, which clears a latched
  alarm (the manual has no reset command; 2.3 says only "downtime").
* ``current()`` is 0x0F (x / 2000 A) with the sign of the output PWM 0x13.
* ``assign_id(new)`` writes 0x15 and the save flag; the motor answers on the new address
  after its next power cycle (5.2), and this axis addresses it from now on.
* An exception 4 from the virtual motor on a write means modbus_enable is 0: the error says
  so (docs/modbus.md).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable

from servobus.axis import checks
from servobus.axis.base import AsyncAxis, AxisTraceHook, check_int
from servobus.errors import (
    ArgumentRangeError,
    DriveError,
    DriveTimeout,
    ProtocolError,
)
from servobus.families import yzaim as Y
from servobus.families.base import AxisStatus, Family, ParamInfo
from servobus.families.yzaim_family import YZAIM, axis_status
from servobus.protocols.modbus import codec as C
from servobus.protocols.modbus.client import ModbusClient
from servobus.protocols.modbus.params import REACHABLE_PARAMS

R = Y.BY_NAME
_ABS = Y.PAIR_BY_NAME["absolute_position"]
_INC = Y.PAIR_BY_NAME["incremental_position"]
_ADDRESS = R["device_address"]
_SPEED = R["target_speed"]
_ORIGIN_TARGET = 1  # 5.4a: "going back to the origin, send 1" (module docstring)
#: One status read: output_enable 0x01 .. motor_speed 0x10 (and on to the position 0x17
#: when the axis commanded a target).
STATUS_FIRST = R["output_enable"].address
STATUS_LAST = R["motor_speed"].address
DEVICE_FAILURE = int(C.ExceptionCode.SERVER_DEVICE_FAILURE)


def check_address(address: object) -> int:
    """A YZ-AIM device address 1..254 (register 0x15), or ArgumentRangeError."""
    value = check_int("drive id", address)
    if not _ADDRESS.minimum <= value <= _ADDRESS.maximum:
        raise ArgumentRangeError(f"drive id {value} is outside the YZ-AIM addresses "
                                 f"{_ADDRESS.minimum}..{_ADDRESS.maximum} (register 0x15)")
    return value


class ModbusAxis(AsyncAxis):
    """One YZ-AIM motor on a Modbus RTU line."""

    protocol_name = "modbus"

    def __init__(self, client: ModbusClient, drive_id: int, *, owns_client: bool = True) -> None:
        self.client = client
        self._id = check_address(drive_id)
        self._owns_client = owns_client
        self._closers: list[Callable[[], Awaitable[None]]] = []
        self._target: int | None = None  # last commanded absolute target, counts
        self._speed_mode: bool | None = None  # None: unknown (another host may have set it)
        self._cruise_rpm: int | None = None  # target_speed replaced by turn()

    def on_close(self, closer: Callable[[], Awaitable[None]]) -> None:
        """Run ``closer`` after the client closes (e.g. an in-process line's task)."""
        self._closers.append(closer)

    # ------------------------------------------------------------- identity
    @property
    def drive_id(self) -> int:
        return self._id

    @property
    def protocol(self) -> str:
        return self.protocol_name

    @property
    def family(self) -> Family:
        return YZAIM

    @property
    def drive_ids(self) -> range:
        return range(_ADDRESS.minimum, _ADDRESS.maximum + 1)

    async def position_window(self) -> int:
        return Y.POSITION_TOLERANCE_COUNTS

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
        reg = R[name]
        (word,) = await self.read_words(reg.address)
        return reg.from_word(word)

    # ------------------------------------------------------------- motion
    def _check_move(self, value: object, *, relative: bool) -> int:
        counts = super()._check_move(value, relative=relative)
        return (_INC if relative else _ABS).check(counts)

    async def _position_mode(self) -> None:
        if self._speed_mode is False:
            return
        await self._write("special_function", Y.SpecialFunction.PULSE_DIRECTION)
        if self._cruise_rpm is not None:
            await self._write("target_speed", self._cruise_rpm)
            self._cruise_rpm = None
        self._speed_mode = False

    async def _send_move_to(self, position: int) -> None:
        self._check_move(position, relative=False)
        await self._position_mode()
        wire = _ORIGIN_TARGET if position == 0 else position
        self._target = None
        await self.write_words(_ABS.low, Y.split32(wire))
        self._target = position

    async def _send_move_by(self, distance: int) -> None:
        self._check_move(distance, relative=True)
        if distance == 0:
            return  # 0 would be the emergency stop at gear numerator 0 (4.7)
        await self._position_mode()
        base = self._target if self._target is not None else await self.position()
        self._target = None
        await self.write_words(_INC.low, Y.split32(distance))
        self._target = base + distance

    async def turn(self, rpm: int) -> None:
        rpm = check_int("rpm", rpm)
        if abs(rpm) > _SPEED.maximum:
            raise ArgumentRangeError(f"rpm={rpm} is outside -{_SPEED.maximum}.."
                                     f"{_SPEED.maximum} (target_speed 0x02)")
        if self._speed_mode is not True and self._cruise_rpm is None:
            self._cruise_rpm = await self.read_param("target_speed")
        self._target = None
        if rpm:
            await self._write("dir_polarity", 1 if rpm < 0 else 0)
        await self._write("target_speed", abs(rpm))
        if self._speed_mode is not True:
            await self._write("special_function", Y.SpecialFunction.SPEED_MODE)
            self._speed_mode = True

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
        await self._with_gear_zero(_INC.low, Y.split32(0))
        self._speed_mode = None

    async def set_origin(self) -> None:
        """0 to the absolute position with gear numerator 0 (4.7): here becomes 0."""
        await self._with_gear_zero(_ABS.low, Y.split32(0))

    async def enable(self) -> None:
        """Communication control and output on: 0x00 = 1, 0x01 = 1 in one frame."""
        await self.write_words(R["modbus_enable"].address, (1, 1))

    async def disable(self) -> None:
        self._target = None
        await self._write("output_enable", 0)

    async def reset(self) -> None:
        """output_enable 0 then 1: clears a latched alarm (module docstring)."""
        self._target = None
        await self._write("output_enable", 0)
        await self._write("output_enable", 1)

    async def save_parameters(self) -> None:
        """Save flag 0x14 = 1: every saved register goes to EEPROM (5.2, 5.4a)."""
        self.client.guard.check(self._id, "save_flag")
        await self._write("save_flag", Y.SaveFlag.SAVE)

    # ------------------------------------------------------------- readouts
    async def status(self) -> AxisStatus:
        last = _ABS.high if self._target is not None else STATUS_LAST
        words = await self.read_words(STATUS_FIRST, last - STATUS_FIRST + 1)

        def word(name: str) -> int:
            return words[R[name].address - STATUS_FIRST]

        error = None
        if self._target is not None:
            error = Y.join32(words[_ABS.low - STATUS_FIRST],
                             words[_ABS.high - STATUS_FIRST]) - self._target
        return axis_status(word("output_enable"), word("alarm_code"), word("motor_speed"),
                           error)

    async def position(self) -> int:
        low, high = await self.read_words(_ABS.low, 2)
        return Y.join32(low, high)

    async def speed(self) -> float:
        return R["motor_speed"].to_engineering(await self._read("motor_speed"))

    async def current(self) -> float:
        first, last = R["system_current"], R["output_pwm"]
        words = await self.read_words(first.address, last.address - first.address + 1)
        amps = first.to_engineering(first.from_word(words[0]))
        return -amps if last.from_word(words[-1]) < 0 else amps

    # ------------------------------------------------------------- parameters and id
    def parameters(self) -> tuple[ParamInfo, ...]:
        reach = set(REACHABLE_PARAMS)
        return tuple(p for p in YZAIM.params if p.name in reach)

    def _check_param(self, name: str, value: object) -> int:
        checked = super()._check_param(name, value)
        Y.register(name).check_write(checked)  # the table's gaps (special function 5)
        return checked

    async def read_param(self, name: str) -> int:
        self.param_info(checks.param_name(name))
        return await self._read(name)

    async def write_param(self, name: str, value: int) -> None:
        checked = self._check_param(name, value)
        await self._write(name, checked)
        if name == "target_speed" and self._speed_mode:
            self._cruise_rpm = None  # the user's value is the speed from now on
        if name == "special_function":
            self._speed_mode = checked == Y.SpecialFunction.SPEED_MODE

    async def read_id(self) -> int:
        return await self._read("device_address")

    async def assign_id(self, new_id: int) -> None:
        check_address(new_id)
        await self._write("device_address", new_id)
        await self.save_parameters()
        self._id = new_id

    async def ping(self, timeout: float = 0.05) -> bool:
        """One read of the alarm register, no retry. An exception reply still answers."""
        try:
            await self.read_words(R["alarm_code"].address, retries=0, timeout=timeout)
        except DriveTimeout:
            return False
        except (DriveError, ProtocolError):
            return True
        return True

    # ------------------------------------------------------------- connection
    async def sibling(self, drive_id: int) -> ModbusAxis:
        return ModbusAxis(self.client, drive_id, owns_client=False)

    async def add_trace(self, hook: AxisTraceHook) -> None:
        self.client.add_trace(hook)

    async def close(self) -> None:
        if self._owns_client:
            await self.client.close()
            closers, self._closers = self._closers, []
            for closer in closers:
                await closer()

    def __repr__(self) -> str:
        return f"<ModbusAxis motor {self._id}>"
