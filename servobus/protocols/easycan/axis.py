"""EasyCanAxis: one YZ-AIM motor on an EasyCan bus, in the Axis units (docs/easycan.md).

Positions are the motor's own counts (32,768 per revolution) on the wire, speeds rpm.
What the Axis calls become (YZ-AIM manual sections; decisions marked as such):

* ``move_to``: 0x19 special_function 0 first when the motor may be in speed mode (unknown
  after connecting, or after ``turn``), then 0x16 absolute_position. A target of 0 is sent
  as 1: with gear numerator 0 (communication control, 4.7/4.8) writing 0 clears the position
  instead of moving, and 5.4a itself goes "back to the origin" by sending 1 (one count, 0.011
  deg, inside the +-10 counts of 5.4a). ``move_by``: 0x0C incremental_position; a distance
  of 0 sends nothing (at gear 0 it would be an emergency stop).
* ``turn(rpm)``: speed mode (5.4a: special function 3) at |rpm| on 0x02 target_speed, sign on
  0x09 dir_polarity (0 = increasing position). 0x02 is also the cruise speed of position
  moves: the axis remembers the value it replaced and writes it back when it returns to
  position mode. ``stop()`` = ``turn(0)``: ramps down at 0x03 and holds.
* ``status()``: one 0x12 read of output_enable, alarm_code, motor_speed, plus the position
  when this axis commanded a target (families.yzaim_family.axis_status).
* ``current()``: the motor reports only its supply current (0x0F, x/2000 A); the sign is
  that of the output duty 0x13 (decision: the one signed current-like reading there is).
* ``enable()``: modbus_enable 1 (communication control), then output_enable 1;
  ``disable()``: output_enable 0; ``reset()``: output_enable 0 then 1, which clears a
  latched stall/over-current alarm (YZ-AIM has no reset command; the manual only says
  "downtime"); ``set_origin()``: the 0x11 absolute position clear (no reply).
* ``assign_id(new)``: writes 0x15 and the save flag; the motor answers on the new address
  after its next power cycle (5.2), and this axis addresses it from now on.
* ``save_parameters()``: the save flag 0x14 = 1 (parameters are RAM until then).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from servobus.axis import checks
from servobus.axis.base import AsyncAxis, AxisTraceHook, check_int
from servobus.errors import ArgumentRangeError, DriveTimeout, ProtocolError
from servobus.families import yzaim
from servobus.families.base import AxisStatus, Family, ParamInfo
from servobus.families.yzaim_family import YZAIM, axis_status
from servobus.protocols.easycan import commands as cmds
from servobus.protocols.easycan.client import AsyncEasyCanClient

PROTOCOL = "easycan"
_STATUS = ("output_enable", "alarm_code", "motor_speed")
_CURRENT = ("system_current", "output_pwm")
_SPEED = yzaim.BY_NAME["target_speed"]
_ORIGIN_TARGET = 1  # 5.4a: "going back to the origin, send 1" (module docstring)
_PARAMS: tuple[ParamInfo, ...] = tuple(p for p in YZAIM.params
                                       if p.name in set(cmds.REACHABLE_PARAMS))
_PARAM_BY_NAME: dict[str, ParamInfo] = {p.name: p for p in _PARAMS}


class EasyCanAxis(AsyncAxis):
    def __init__(self, client: AsyncEasyCanClient, address: int, *,
                 owns_client: bool = True) -> None:
        self.client = client
        self._id = cmds.check_address(address)
        self._owns_client = owns_client
        self._closers: list[Callable[[], Awaitable[None]]] = []
        self._reads: dict[tuple[object, ...], cmds.EasyCanCommand] = {}
        self._params: dict[str, cmds.EasyCanCommand] = {}  # parameter reads, built once
        self._target: int | None = None  # last commanded absolute target, counts
        self._speed_mode: bool | None = None  # None: unknown (another host may have set it)
        self._cruise_rpm: int | None = None  # target_speed replaced by turn()

    def on_close(self, closer: Callable[[], Awaitable[None]]) -> None:
        self._closers.append(closer)

    def _read_cmd(self, factory: Callable[..., cmds.EasyCanCommand],
                  *args: Any) -> cmds.EasyCanCommand:
        key = (factory, *args)
        found = self._reads.get(key)
        if found is None:
            found = self._reads[key] = factory(self._id, *args)
        return found

    # ------------------------------------------------------------- identity
    @property
    def drive_id(self) -> int:
        return self._id

    @property
    def protocol(self) -> str:
        return PROTOCOL

    @property
    def family(self) -> Family:
        return YZAIM

    @property
    def drive_ids(self) -> range:
        return range(cmds.MIN_ADDRESS, cmds.MAX_ADDRESS + 1)

    # ------------------------------------------------------------- motion
    def _check_move(self, value: object, *, relative: bool) -> int:
        counts = super()._check_move(value, relative=relative)
        name = "incremental_position" if relative else "absolute_position"
        yzaim.PAIR_BY_NAME[name].check(counts)
        return counts

    async def _position_mode(self) -> None:
        if self._speed_mode is False:
            return
        await self._write("special_function", yzaim.SpecialFunction.PULSE_DIRECTION)
        if self._cruise_rpm is not None:
            await self._write("target_speed", self._cruise_rpm)
            self._cruise_rpm = None
        self._speed_mode = False

    async def _send_move_to(self, position: int) -> None:
        self._check_move(position, relative=False)
        await self._position_mode()
        wire = _ORIGIN_TARGET if position == 0 else position
        self._target = None
        await self.client.execute(cmds.make_move_absolute(self._id, wire))
        self._target = position

    async def _send_move_by(self, distance: int) -> None:
        self._check_move(distance, relative=True)
        if distance == 0:
            return
        await self._position_mode()
        base = self._target
        self._target = None
        now = await self.client.position_write(cmds.make_move_relative(self._id, distance))
        start = base if base is not None else now
        self._target = None if start is None else start + distance

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
            await self._write("special_function", yzaim.SpecialFunction.SPEED_MODE)
            self._speed_mode = True

    async def emergency_stop(self) -> None:
        """0x10: the motor stops at once (5.3d); speed mode ends."""
        self._target = None
        await self.client.execute(cmds.make_emergency_stop(self._id))

    async def set_origin(self) -> None:
        await self.client.send_only(cmds.make_clear_position(self._id))
        self._target = None

    async def enable(self) -> None:
        await self._write("modbus_enable", 1)
        await self._write("output_enable", 1)

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
        await self._write("save_flag", yzaim.SaveFlag.SAVE)

    # ------------------------------------------------------------- readouts
    async def status(self) -> AxisStatus:
        words = await self.client.read_words(
            self._read_cmd(cmds.make_read_registers, _STATUS))
        error = None
        if self._target is not None:
            error = await self.position() - self._target
        return axis_status(words[0], words[1], words[2], error)

    async def position(self) -> int:
        return await self.client.read(self._read_cmd(cmds.make_read, "absolute_position"))

    async def speed(self) -> float:
        raw = await self.client.read(self._read_cmd(cmds.make_read, "motor_speed"))
        return yzaim.BY_NAME["motor_speed"].to_engineering(raw)

    async def current(self) -> float:
        supply, pwm = await self.client.read_words(
            self._read_cmd(cmds.make_read_registers, _CURRENT))
        amps = yzaim.BY_NAME["system_current"].to_engineering(supply)
        return -amps if yzaim.to_signed16(pwm) < 0 else amps

    async def position_window(self) -> int:
        return yzaim.POSITION_TOLERANCE_COUNTS

    # ------------------------------------------------------------- parameters and id
    def parameters(self) -> tuple[ParamInfo, ...]:
        return _PARAMS

    def param_info(self, name: str) -> ParamInfo:
        found = _PARAM_BY_NAME.get(name) if isinstance(name, str) else None
        return found if found is not None else super().param_info(name)

    def _check_param(self, name: str, value: object) -> int:
        checked = super()._check_param(name, value)
        yzaim.register(name).check_write(checked)  # the table's gaps (special function 5)
        return checked

    async def read_param(self, name: str) -> int:
        command = self._params.get(name) if isinstance(name, str) else None
        if command is None:
            self.param_info(checks.param_name(name))
            command = self._params[name] = cmds.make_read(self._id, name)
        return await self.client.read(command)

    async def write_param(self, name: str, value: int) -> None:
        checked = self._check_param(name, value)
        await self._write(name, checked)
        if name == "target_speed" and self._speed_mode:
            self._cruise_rpm = None  # the user's value is the speed from now on
        if name == "special_function":
            self._speed_mode = checked == yzaim.SpecialFunction.SPEED_MODE

    async def _write(self, name: str, value: int) -> None:
        await self.client.execute(cmds.make_write(self._id, name, int(value)))

    async def read_id(self) -> int:
        return await self.client.read(self._read_cmd(cmds.make_read, "device_address"))

    async def assign_id(self, new_id: int) -> None:
        cmds.check_address(new_id)
        await self._write("device_address", new_id)
        await self.save_parameters()
        self._id = new_id
        self._reads.clear()
        self._params.clear()

    async def ping(self, timeout: float = 0.05) -> bool:
        try:
            await self.client.execute(self._read_cmd(cmds.make_read, "alarm_code"), retries=0,
                                      timeout=timeout)
        except DriveTimeout:
            return False
        except ProtocolError:
            return True
        return True

    # ------------------------------------------------------------- connection
    async def sibling(self, drive_id: int) -> EasyCanAxis:
        return EasyCanAxis(self.client, drive_id, owns_client=False)

    async def add_trace(self, hook: AxisTraceHook) -> None:
        self.client.add_trace(hook)

    async def close(self) -> None:
        if self._owns_client:
            await self.client.close()
            closers, self._closers = self._closers, []
            for closer in closers:
                await closer()

    def __repr__(self) -> str:
        return f"<EasyCanAxis motor {self._id}>"
