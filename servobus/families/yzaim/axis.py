"""YzaimAxis: the AsyncAxis of a YZ-AIM register-map motor, whatever wire reaches it.

A protocol supplies only the register primitives (:meth:`YzaimAxis._read`,
:meth:`YzaimAxis._read_words`, :meth:`YzaimAxis._write`) and what its wire does its
own way (the emergency stop, the position clear); the mapping of the Axis API onto the
YZ-AIM registers lives here once (YZ-AIM manual sections; docs/easycan.md, docs/modbus.md):

* ``move_to(p)`` writes the absolute position 0x16/0x17, ``move_by(d)`` the increment
  0x0C/0x0D (5.4a), after special function 0x19 = 0 when the motor may be in speed mode
  (unknown after connecting, or after ``turn``). With gear numerator 0 (communication
  control, 4.7/4.8) writing 0 there is special (0 to 0x16 clears the position, 0 to 0x0C
  stops), so a target of 0 is sent as 1, as 5.4a goes "back to the origin" (one count, 0.011
  deg, inside its +-10 counts), and ``move_by(0)`` sends nothing.
* In position (5.4a): the motor reports none; the axis remembers the target it sent (a
  relative move adds to it; with none known it starts from the position the protocol gets)
  and the family's ``axis_status`` compares the position with it (+-10 counts).
* ``turn(rpm)``: speed mode (0x19 = 3) at |rpm| on 0x02 target_speed, the sign on 0x09
  dir_polarity (0 = increasing position). 0x02 is also the cruise speed of position moves:
  the axis keeps the value it replaced and writes it back when it returns to position mode.
* **A stop leaves the motor ready for the next position move** (decision, issue 28):
  ``stop()`` = ``turn(0)`` writes 0x02 = 0 and 0x19 = 3 (the ramp down at 0x03 that also
  interrupts a position move), then 0x19 = 0 (position mode; leaving speed mode keeps
  ramping down and holds, as the virtual motor models it - the manual is silent) and 0x02 =
  the cruise speed. The cruise speed lives on the drive, not only in this process, so a
  stop by one program (``servobus stop``, Ctrl-C, a GUI or gateway shutdown) never leaves
  the next program's move at 0 rpm. The cruise speed a stop restores: the one this axis
  replaced; else 0x02 as read in position mode; else, when the axis finds the motor in
  speed mode left by another program (the cruise it replaced is lost with that program),
  the table's power-on value 1000 rpm (:data:`FALLBACK_CRUISE_RPM`, logged).
* **One mode sequence at a time** (decision, the HAL stop defect): a stop, a turn, a
  position move and a stream target each write 0x02 and 0x19 in several steps; an axis
  runs them one after the other (a lock), never interleaved. Two stops that interleaved
  (``servobus hal``'s sync group and its SIGTERM both stopping the motor) could write
  0x19 = 3 after the other stop had restored 0x02 to the cruise speed: speed mode at 1000
  rpm until the next write, the motor turning after it had been stopped. A sequence cut
  short by a cancellation leaves the next one safe: it writes 0x02 = 0 again before 0x19
  = 3.
* A position move whose cruise speed would be 0 is refused before anything is written
  (:class:`~servobus.errors.MotionRefused`): the motor would never get there. The axis
  knows 0x02 from its own writes and reads; it reads 0x19 and 0x02 once when it does not
  (a change another program makes afterwards is not seen).
* ``write_param``: a write that starts open-ended motion - 0x19 = 3 (speed mode), or 0x02 >
  0 while the motor is in speed mode (0x19 read once when the axis does not know) - is
  refused before it is written (MotionRefused) unless the axis is ``continuous``; motion
  goes through ``turn`` and the machine's leased commands instead.
* ``enable()``: modbus_enable 1 (communication control), then output_enable 1;
  ``disable()``: output_enable 0; ``reset()``: output_enable 0 then 1, which clears a
  latched stall/over-current alarm (YZ-AIM has no reset command; 2.3 says only "downtime").
* ``current()``: the motor reports only its supply current (0x0F, x/2000 A); the sign is
  that of the output duty 0x13 (decision: the one signed current-like reading there is).
* ``save_parameters()``: the save flag 0x14 = 1 (parameters are RAM until then).
* ``assign_id(new)``: writes 0x15 and the save flag; the motor answers on the new address
  after its next power cycle (5.2), and this axis addresses it from now on.
* ``ping()``: one read of the alarm register without retry; any reply, an error reply too,
  proves a motor answered (decision).
"""

from __future__ import annotations

import asyncio
import logging
import math
from abc import abstractmethod
from functools import cache
from typing import ClassVar, TypeVar

from servobus import checks
from servobus.axis.base import check_int
from servobus.axis.client_axis import ClientAxis, LinkClient
from servobus.axis.types import AxisStatus, Family, ParamInfo, StreamProfile
from servobus.errors import (
    ArgumentRangeError,
    DriveError,
    DriveTimeout,
    MotionRefused,
    NotSupported,
    ProtocolError,
)
from servobus.families.yzaim import registers as Y
from servobus.families.yzaim.family import YZAIM, axis_status

log = logging.getLogger(__name__)

R = Y.BY_NAME
ABS = Y.PAIR_BY_NAME["absolute_position"]
INC = Y.PAIR_BY_NAME["incremental_position"]
ADDRESS = R["device_address"]
_SPEED = R["target_speed"]
_ORIGIN_TARGET = 1  # 5.4a: "going back to the origin, send 1" (module docstring)
#: The cruise speed a stop restores when the one in use is lost (module docstring).
FALLBACK_CRUISE_RPM = _SPEED.default or 1000
_SPEED_MODE = Y.SpecialFunction.SPEED_MODE
#: The registers of one status read and of one current read.
STATUS_REGISTERS = ("output_enable", "alarm_code", "motor_speed")
CURRENT_REGISTERS = ("system_current", "output_pwm")

C = TypeVar("C", bound=LinkClient)


@cache
def _reachable(names: tuple[str, ...]) -> dict[str, ParamInfo]:
    """The family's ParamInfos a protocol reaches, by name, in the family's order."""
    reach = set(names)
    return {p.name: p for p in YZAIM.params if p.name in reach}


class YzaimAxis(ClientAxis[C]):
    """One YZ-AIM motor; subclasses supply the register primitives of their wire."""

    address_word = "motor"
    #: The YZ-AIM parameter names the protocol reaches (``parameters()``).
    reachable_params: ClassVar[tuple[str, ...]]

    def __init__(self, client: C, drive_id: int, *, owns_client: bool = True) -> None:
        super().__init__(client, drive_id, owns_client=owns_client)
        self._target: int | None = None  # last commanded absolute target, counts
        self._speed_mode: bool | None = None  # None: unknown (another host may have set it)
        self._cruise_rpm: int | None = None  # target_speed replaced by turn()
        self._speed_word: int | None = None  # what 0x02 holds, as last written or read here
        self._stream_rpm: int | None = None  # 0x02 a lease runs at (stream_to)
        self._stream_cruise: int | None = None  # the cruise speed the lease replaced
        #: Held by every sequence that writes 0x02/0x19 (module docstring: one at a time).
        self._sequence = asyncio.Lock()

    # ------------------------------------------------------------- primitives
    @abstractmethod
    async def _read(self, name: str) -> int:
        """The value of one register or 32-bit pair (retried, bounded)."""

    @abstractmethod
    async def _read_words(self, names: tuple[str, ...]) -> tuple[int, ...]:
        """The raw 16-bit words of 2..3 single registers, in the order named (retried)."""

    @abstractmethod
    async def _write(self, name: str, value: int) -> None:
        """Write one register or 32-bit pair (range-checked; a move is never re-sent)."""

    @abstractmethod
    async def _probe(self, timeout: float) -> None:
        """One read of the alarm register without retry (``ping``)."""

    async def _write_increment(self, distance: int, *, need_start: bool) -> int | None:
        """Write the increment; return the position before it when ``need_start`` (a wire
        whose write reply carries the position overrides this to save the read)."""
        start = await self.position() if need_start else None
        await self._write("incremental_position", distance)
        return start

    async def _read_status(self, *, with_position: bool) -> tuple[int, int, int, int | None]:
        """output_enable, alarm_code, motor_speed words and, if asked, the position."""
        enable, alarm, speed = await self._read_words(STATUS_REGISTERS)
        return enable, alarm, speed, (await self.position() if with_position else None)

    def _forget_address(self) -> None:
        """Drop whatever was built for the old address (after ``assign_id``)."""

    # ------------------------------------------------------------- identity
    @property
    def family(self) -> Family:
        return YZAIM

    @property
    def drive_ids(self) -> range:
        return range(ADDRESS.minimum, ADDRESS.maximum + 1)

    async def position_window(self) -> int:
        return Y.POSITION_TOLERANCE_COUNTS

    # ------------------------------------------------------------- motion
    def _check_move(self, value: object, *, relative: bool) -> int:
        counts = super()._check_move(value, relative=relative)
        return (INC if relative else ABS).check(counts)

    def _move_limits(self, relative: bool) -> tuple[int, int] | None:
        pair = INC if relative else ABS
        return pair.minimum, pair.maximum

    async def _write_speed(self, rpm: int) -> None:
        """Write 0x02 and remember what it holds."""
        self._speed_word = None
        await self._write("target_speed", rpm)
        self._speed_word = rpm

    async def _target_speed(self) -> int:
        """0x02 as this axis knows it (one read when it does not)."""
        if self._speed_word is None:
            self._speed_word = await self._read("target_speed")
        return self._speed_word

    async def _cruise(self) -> int:
        """The cruise speed position moves run at once in position mode (module docstring):
        reads 0x19 and 0x02 only when this axis does not know them."""
        if self._cruise_rpm is not None:
            return self._cruise_rpm
        if self._speed_mode is None:
            await self._learn_mode()
            if self._speed_mode:  # another program left it turning: its cruise is lost
                self._cruise_rpm = self._lost_cruise()
                return self._cruise_rpm
        return await self._target_speed()

    async def _learn_mode(self) -> None:
        """Read 0x19 and note speed mode. Anything else stays unknown: the next position
        move writes 0x19 = 0 as it does after connecting (another special function, or
        another program switching it meanwhile, is set right by that write)."""
        if await self._read("special_function") == _SPEED_MODE:
            self._speed_mode = True

    def _lost_cruise(self) -> int:
        log.warning("motor %s: found in speed mode, the cruise speed it replaced is not known: "
                    "position moves run at %d rpm (target_speed 0x02)", self.drive_id,
                    FALLBACK_CRUISE_RPM)
        return FALLBACK_CRUISE_RPM

    async def _check_cruise(self) -> None:
        """MotionRefused before a position move whose cruise speed is 0."""
        if await self._cruise() <= 0:
            raise MotionRefused(
                f"motor {self.drive_id}: the cruise speed (target_speed 0x02) is 0 rpm: a "
                "position move would never get there; nothing was written - set "
                f"target_speed (1..{_SPEED.maximum} rpm) first")

    async def _position_mode(self) -> None:
        if self._speed_mode is False:
            return
        self._speed_mode = None  # unknown until the write is answered (a cancel)
        await self._write("special_function", Y.SpecialFunction.PULSE_DIRECTION)
        if self._cruise_rpm is not None:
            await self._write_speed(self._cruise_rpm)
            self._cruise_rpm = None
        self._speed_mode = False

    async def _send_move_to(self, position: int) -> None:
        self._check_move(position, relative=False)
        async with self._sequence:
            await self._move_to_sequence(position)

    async def _move_to_sequence(self, position: int) -> None:
        await self._end_stream()
        await self._check_cruise()
        await self._position_mode()
        wire = _ORIGIN_TARGET if position == 0 else position
        self._target = None
        await self._write("absolute_position", wire)
        self._target = position

    async def _send_move_by(self, distance: int) -> None:
        self._check_move(distance, relative=True)
        if distance == 0:
            return  # 0 would be the emergency stop at gear numerator 0 (4.7)
        async with self._sequence:
            await self._move_by_sequence(distance)

    async def _move_by_sequence(self, distance: int) -> None:
        await self._end_stream()
        await self._check_cruise()
        await self._position_mode()
        base = self._target
        self._target = None
        start = await self._write_increment(distance, need_start=base is None)
        origin = base if base is not None else start
        self._target = None if origin is None else origin + distance

    async def stream_profile(self) -> StreamProfile:
        """Cruise speeds up to 0x02's maximum; the acceleration of 0x03 (at 60000 and above
        the motor runs no curve of its own: taken as 60000 rpm/s for the lead)."""
        accel = await self._read("acceleration")
        return StreamProfile(float(_SPEED.maximum), float(min(max(1, accel), Y.NO_PROFILE_ACCEL)))

    async def stream_to(self, position: int, rpm: float) -> None:
        """The absolute position at cruise speed ``rpm`` (0x02, rounded up, written when it
        changes). The cruise speed it replaced is what the next stop restores, and what the
        next move runs at (:meth:`_end_stream`)."""
        counts = self._check_move(position, relative=False)
        cruise = checks.positive("rpm", abs(rpm) if isinstance(rpm, int | float) else rpm,
                                 "rpm")
        wanted = min(_SPEED.maximum, max(1, math.ceil(cruise)))
        async with self._sequence:
            await self._stream_to_sequence(counts, wanted)

    async def _stream_to_sequence(self, counts: int, wanted: int) -> None:
        await self._position_mode()
        if self._stream_rpm is None:
            self._stream_cruise = await self._cruise()
        if await self._target_speed() != wanted:
            await self._write_speed(wanted)
        self._stream_rpm = wanted
        self._target = None
        await self._write("absolute_position", _ORIGIN_TARGET if counts == 0 else counts)
        self._target = counts

    async def _end_stream(self) -> None:
        """A move after a lease runs at the cruise speed the lease replaced."""
        if self._stream_rpm is None:
            return
        cruise, self._stream_rpm = self._stream_cruise, None
        if cruise is not None and cruise > 0 and await self._target_speed() != cruise:
            await self._write_speed(cruise)

    async def turn(self, rpm: int) -> None:
        rpm = check_int("rpm", rpm)
        async with self._sequence:
            await self._turn_sequence(rpm)

    async def position_mode_alone(self) -> None:
        """Position mode, as one sequence (module docstring): what a cyclic stream or a
        synchronised move of several motors asks of each motor first."""
        async with self._sequence:
            await self._position_mode()

    async def _turn_sequence(self, rpm: int) -> None:
        if self._stream_rpm is not None:  # a stop after a lease restores what it replaced
            self._stream_rpm = None
            if self._cruise_rpm is None and self._stream_cruise:
                self._cruise_rpm = self._stream_cruise
        if abs(rpm) > _SPEED.maximum:
            raise ArgumentRangeError(f"rpm={rpm} is outside -{_SPEED.maximum}.."
                                     f"{_SPEED.maximum} (target_speed 0x02)")
        if self._speed_mode is not True and self._cruise_rpm is None:
            self._cruise_rpm = await self._cruise()
        if rpm == 0:
            await self._stop_ready()
            return
        self._target = None
        await self._write("dir_polarity", 1 if rpm < 0 else 0)
        await self._write_speed(abs(rpm))
        if self._speed_mode is not True:
            self._speed_mode = None
            await self._write("special_function", _SPEED_MODE)
            self._speed_mode = True

    async def _stop_ready(self) -> None:
        """Ramp down and hold, then back to position mode at the cruise speed (module
        docstring: a stop leaves the motor ready for the next position move)."""
        cruise = self._cruise_rpm if self._cruise_rpm is not None else await self._cruise()
        if cruise <= 0:  # 0x02 = 0 in speed mode: a stop of a stop; nothing to restore
            cruise = self._lost_cruise()
        self._target = None
        await self._write_speed(0)
        if self._speed_mode is not True:
            self._speed_mode = None  # unknown until the write is answered (a cancel)
            await self._write("special_function", _SPEED_MODE)
            self._speed_mode = True
        self._speed_mode = None
        await self._write("special_function", Y.SpecialFunction.PULSE_DIRECTION)
        self._speed_mode = False
        await self._write_speed(cruise)
        self._cruise_rpm = None

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

    async def home(self) -> None:
        """No homing a host starts (decision, nothing sent): the mechanical-origin search
        (special function 0x19 = 1 or 4, manual 4.6 and 5.2) runs at power-on once saved,
        against the mechanical stop (a stall); the manual does not say that writing 0x19
        starts it at once, and the virtual motor models no mechanical stop."""
        raise NotSupported(
            f"a {self.family.title} motor homes only by itself at power-on (special_function "
            "1 or 4, saved: it stalls against the mechanical stop, then sets its origin); "
            "servobus starts none: set the zero where the axis "
            "stands (origin)", family=self.family.name)

    async def _move_profile_values(self, rpm: float | None,
                                   accel_rpm_s: float | None) -> dict[str, int]:
        """target_speed 0x02 (the cruise of position moves, rounded up) and acceleration
        0x03 (rounded down, below 60000: at 60000 and above the motor runs no curve)."""
        values: dict[str, int] = {}
        if rpm is not None:
            if rpm > _SPEED.maximum:
                raise ArgumentRangeError(f"{rpm:g} rpm is above the fastest cruise speed "
                                         f"(target_speed {_SPEED.maximum} rpm)")
            values["target_speed"] = max(1, math.ceil(rpm))
        if accel_rpm_s is not None:
            values["acceleration"] = min(Y.NO_PROFILE_ACCEL - 1, max(1, math.floor(accel_rpm_s)))
        return values

    async def save_parameters(self) -> None:
        """Save flag 0x14 = 1: every saved register goes to EEPROM (5.2, 5.4a)."""
        await self._write("save_flag", Y.SaveFlag.SAVE)

    # ------------------------------------------------------------- readouts
    async def status(self) -> AxisStatus:
        target = self._target
        enable, alarm, speed, position = await self._read_status(
            with_position=target is not None)
        error = None if target is None or position is None else position - target
        return axis_status(enable, alarm, speed, error)

    async def position(self) -> int:
        return await self._read("absolute_position")

    async def speed(self) -> float:
        return R["motor_speed"].to_engineering(await self._read("motor_speed"))

    async def current(self) -> float:
        supply, pwm = await self._read_words(CURRENT_REGISTERS)
        first, last = (R[name] for name in CURRENT_REGISTERS)
        amps = first.to_engineering(first.from_word(supply))
        return -amps if last.from_word(pwm) < 0 else amps

    # ------------------------------------------------------------- parameters and id
    def parameters(self) -> tuple[ParamInfo, ...]:
        return tuple(_reachable(self.reachable_params).values())

    def param_info(self, name: str) -> ParamInfo:
        found = _reachable(self.reachable_params).get(name) if isinstance(name, str) else None
        return found if found is not None else super().param_info(name)

    def _check_param(self, name: str, value: object) -> int:
        checked = super()._check_param(name, value)
        Y.register(name).check_write(checked)  # the table's gaps (special function 5)
        if name == "special_function" and checked == _SPEED_MODE:
            self._refuse_open_ended(f"special_function = {checked} (speed mode)")
        if name == "target_speed" and checked and self._speed_mode:
            self._refuse_open_ended(f"target_speed = {checked} rpm in speed mode")
        return checked

    def _refuse_open_ended(self, what: str) -> None:
        """MotionRefused for a register write that starts open-ended motion (module doc)."""
        if not self.continuous:
            raise MotionRefused(
                f"motor {self.drive_id}: {what} would turn the motor until told to stop, "
                "and this axis is not continuous; nothing was written - move it with "
                "move/turn (the machine's leased commands), or mark the axis continuous "
                "(?continuous=1 on its URL, continuous = true in a machine file)")

    async def read_param(self, name: str) -> int:
        self.param_info(checks.param_name(name))
        value = await self._read(name)
        if name == "target_speed":
            self._speed_word = value
        return value

    async def write_param(self, name: str, value: int) -> None:
        async with self._sequence:  # 0x02 and 0x19 belong to the mode sequences
            await self._write_param(name, value)

    async def _write_param(self, name: str, value: int) -> None:
        checked = self._check_param(name, value)
        if name == "target_speed" and checked and self._speed_mode is None \
                and not self.continuous:
            await self._learn_mode()
            self._check_param(name, checked)
        await self._write(name, checked)
        if name == "target_speed":
            self._speed_word = checked
            self._stream_rpm = None  # the user's value wins
        if name == "target_speed" and self._speed_mode:
            self._cruise_rpm = None  # the user's value is the speed from now on
        if name == "special_function":
            self._speed_mode = checked == _SPEED_MODE

    async def read_id(self) -> int:
        return await self._read("device_address")

    async def assign_id(self, new_id: int) -> None:
        self._check_id(new_id)
        await self._write("device_address", new_id)
        await self.save_parameters()
        self._id = new_id
        self._forget_address()

    async def ping(self, timeout: float = 0.05) -> bool:
        try:
            await self._probe(timeout)
        except DriveTimeout:
            return False
        except (DriveError, ProtocolError):
            return True
        return True
