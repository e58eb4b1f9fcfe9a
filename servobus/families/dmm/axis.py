"""DmmAxis: the DMM drive profile, written once over a few wire hooks (docs/axis.md).

Every DMM drive runs one firmware profile, whatever reaches it: a DYN2/DC2/DYN4 on DYN232M
or DYN CAN (the ``make_*`` command sets, :mod:`servobus.families.dmm.command_axis`), a DYN5
over EtherNet/IP (its Parameter object, :mod:`servobus.families.dyn5.axis`). This class maps
the Axis API onto that profile once, in the Axis units (as canopen's ``BaseNode402`` maps
CiA 402 onto a node's primitives):

* Moves: counts -> command units through GEAR_NUM (a command moves ``command x 4096 /
  GEAR_NUM x 4`` counts: DYN2 manual 7.4.1, DYN5 Appendix B), read from the drive on the
  first move, then tracked through this axis's own writes. A move no GEAR_NUM can reach is
  refused before even the gear read; the command range is checked again at the drive's
  GEAR_NUM before anything is sent (:mod:`servobus.families.dmm.family`). Never re-sent.
* Status: the drive's status, and the speed when no profile runs (moving = the motor turns,
  :func:`~servobus.axis.types.motion_state`): a constant speed leaves the busy bit clear.
  ``readings()`` reads the speed once for both (3 requests, not 4).
* ``stream_profile()``: Max Speed and Max Accel at GEAR_NUM: a target update (DTPU) runs
  the point-to-point profile; never written per motion (EEPROM, docs/safety.md).
* ``position_window()``: OnRange (1/16384 rev) in counts, the drive's own window.
* ``set_move_profile()``: Max Speed and Max Accel at GEAR_NUM, written only where the
  drive's differ (EEPROM). ``home()`` is each wire's own: a DYN2 homes by a reset in
  absolute mode, a DYN5 runs no homing.

A wire supplies the hooks: :meth:`_send` (one profile :class:`Action` with its value),
:meth:`_check_action` (the same value checked, nothing sent), :meth:`_read_value` (a
:class:`Readout`), :meth:`_read_status` / :meth:`_status_busy` / :meth:`_axis_status`,
:meth:`_torque_amps`, :meth:`_write_param` and ``read_param``; plus what it alone has.
"""

from __future__ import annotations

import asyncio
from abc import abstractmethod
from enum import Enum
from typing import ClassVar, Generic, TypeVar

from servobus.axis.base import DEFAULT_WAIT_TIMEOUT_S, AsyncAxis, check_int
from servobus.axis.types import AxisStatus, StreamProfile
from servobus.families.dmm import units as U
from servobus.families.dmm import vocabulary as V
from servobus.families.dmm.family import command_to_counts, counts_to_command

S = TypeVar("S")


class Action(Enum):
    """What the profile asks a wire to send (one value each; 0 where it takes none)."""

    MOVE_ABSOLUTE = "move_absolute"  # command units
    MOVE_RELATIVE = "move_relative"  # command units
    TURN = "turn"  # rpm
    SQUARE_WAVE = "square_wave"  # amplitude, 4096 = 180 deg
    SINE_WAVE = "sine_wave"
    WAVE_FREQUENCY = "wave_frequency"  # Hz
    SET_ORIGIN = "set_origin"
    ENABLE = "enable"
    DISABLE = "disable"
    RESET = "reset"


class Readout(Enum):
    """What the profile reads besides the status and the parameters."""

    POSITION = "position"  # counts
    SPEED = "speed"  # rpm
    TORQUE = "torque"  # the wire's own torque unit (see _torque_amps)


def _move(relative: bool) -> Action:
    return Action.MOVE_RELATIVE if relative else Action.MOVE_ABSOLUTE


class DmmAxis(AsyncAxis, Generic[S]):
    """The DMM profile of one drive (module docstring); ``S`` is the wire's raw status."""

    #: The command range of a point-to-point move (28-bit signed on every DMM drive).
    command_range: ClassVar[tuple[int, int]] = (V.VALUE_MIN, V.VALUE_MAX)
    #: GEAR_NUM as this axis knows it (None: not read yet, or forgotten by the drive).
    _gear_num: int | None = None

    # ------------------------------------------------------------- the wire's hooks
    @abstractmethod
    async def _send(self, action: Action, value: int = 0) -> None:
        """Send one profile action (checked by the wire; a motion is never re-sent)."""

    @abstractmethod
    def _check_action(self, action: Action, value: int) -> None:
        """ArgumentRangeError when the wire would refuse ``value`` for ``action``."""

    @abstractmethod
    async def _read_value(self, readout: Readout) -> int:
        """One readout as the drive sends it."""

    @abstractmethod
    async def _read_status(self) -> S:
        """The drive's status as the wire decodes it."""

    @abstractmethod
    def _status_busy(self, status: S) -> bool:
        """A built-in profile runs (the busy bit)."""

    @abstractmethod
    def _axis_status(self, status: S, speed_rpm: float | None) -> AxisStatus:
        """``status`` (and the speed, None when a profile already says moving) as AxisStatus."""

    @abstractmethod
    def _torque_amps(self, raw: int) -> float:
        """The torque readout in amperes, positive towards increasing position."""

    @abstractmethod
    async def _write_param(self, name: str, value: int) -> None:
        """Write one checked parameter value."""

    # ------------------------------------------------------------- units
    async def gear_num(self) -> int:
        """GEAR_NUM as this axis knows it (read from the drive the first time)."""
        if self._gear_num is None:
            self._gear_num = await self.read_param("gear_num")
        return self._gear_num

    async def to_command(self, counts: int) -> int:
        """Encoder counts -> the drive's point-to-point command units (rounded)."""
        return counts_to_command(counts, await self.gear_num())

    def _gear_or_widest(self) -> int:
        """GEAR_NUM known so far, else its minimum (the widest range in counts)."""
        return self._gear_num or self.family.param("gear_num").minimum

    def _check_move(self, value: object, *, relative: bool) -> int:
        """Type, then the command range at the GEAR_NUM known so far: a value no GEAR_NUM
        can reach is refused before even the gear read."""
        counts = super()._check_move(value, relative=relative)
        self._check_action(_move(relative), counts_to_command(counts, self._gear_or_widest()))
        return counts

    def _move_limits(self, relative: bool) -> tuple[int, int] | None:
        low, high = self.command_range
        gear = self._gear_or_widest()
        return command_to_counts(low, gear), command_to_counts(high, gear)

    def _limits_note(self) -> str:
        return f" at GEAR_NUM {self._gear_num}" if self._gear_num else ""

    async def move_range(self, *, relative: bool = False) -> tuple[int, int] | None:
        await self.gear_num()
        return self._move_limits(relative)

    async def position_window(self) -> int:
        """OnRange (1/16384 rev) in counts: the drive's own in-position window."""
        return max(1, round(U.onrange_to_counts(await self.read_param("on_range"))))

    async def stream_profile(self) -> StreamProfile:
        """Max Speed and Max Accel at GEAR_NUM (module docstring)."""
        return StreamProfile(*U.stream_profile(await self.read_param("max_speed"),
                                               await self.read_param("max_accel"),
                                               await self.gear_num()))

    async def _move_profile_values(self, rpm: float | None,
                                   accel_rpm_s: float | None) -> dict[str, int]:
        """Max Speed and Max Accel (EEPROM; DYN5: High Speed and High Accel, the same
        formulas, Appendix B) at the drive's GEAR_NUM (units.profile_params)."""
        return U.profile_params(rpm, accel_rpm_s, await self.gear_num())

    # ------------------------------------------------------------- motion
    async def _send_move_to(self, position: int) -> None:
        command = await self.to_command(position)
        self._check_limits(position, False)  # now at the drive's GEAR_NUM
        await self._send(Action.MOVE_ABSOLUTE, command)

    async def _send_move_by(self, distance: int) -> None:
        command = await self.to_command(distance)
        self._check_limits(distance, True)
        await self._send(Action.MOVE_RELATIVE, command)

    async def move_to_command(self, command: int, *, wait: bool = False,
                              timeout: float | None = None) -> None:
        """Absolute move in raw command units (x 4096/GEAR_NUM x 4 counts), no conversion."""
        await self._send(Action.MOVE_ABSOLUTE, check_int("command", command))
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if timeout is None else timeout)

    async def move_by_command(self, command: int, *, wait: bool = False,
                              timeout: float | None = None) -> None:
        """Relative move in raw command units, no conversion."""
        await self._send(Action.MOVE_RELATIVE, check_int("command", command))
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if timeout is None else timeout)

    async def turn(self, rpm: int) -> None:
        await self._send(Action.TURN, check_int("rpm", rpm))

    async def square_wave(self, amplitude: int) -> None:
        """Square-wave motion, 4096 = 180 deg (send ``wave_frequency`` first)."""
        await self._send(Action.SQUARE_WAVE, amplitude)

    async def sine_wave(self, amplitude: int) -> None:
        await self._send(Action.SINE_WAVE, amplitude)

    async def wave_frequency(self, hz: int) -> None:
        await self._send(Action.WAVE_FREQUENCY, hz)

    async def set_origin(self) -> None:
        await self._send(Action.SET_ORIGIN)

    async def enable(self) -> None:
        await self._send(Action.ENABLE)

    async def disable(self) -> None:
        await self._send(Action.DISABLE)

    async def reset(self) -> None:
        await self._send(Action.RESET)

    # ------------------------------------------------------------- readouts
    async def status(self) -> AxisStatus:
        """The status, and the speed when no profile runs (module docstring)."""
        status = await self._read_status()
        busy = self._status_busy(status)
        return self._axis_status(status, None if busy else await self.speed())

    async def readings(self) -> tuple[int, float, AxisStatus]:
        """One speed read serves both the speed and :meth:`status` (3 requests, not 4)."""
        status, position, speed = await asyncio.gather(
            self._read_status(), self.position(), self.speed())
        busy = self._status_busy(status)
        return position, speed, self._axis_status(status, None if busy else speed)

    async def position(self) -> int:
        return await self._read_value(Readout.POSITION)

    async def speed(self) -> float:
        return float(await self._read_value(Readout.SPEED))

    async def torque_raw(self) -> int:
        """The torque readout as the drive sends it (see ``_torque_amps``)."""
        return await self._read_value(Readout.TORQUE)

    async def current(self) -> float:
        return self._torque_amps(await self.torque_raw())

    # ------------------------------------------------------------- parameters
    async def write_param(self, name: str, value: int) -> None:
        checked = self._check_param(name, value)
        await self._write_param(name, checked)
        if name == "gear_num":
            self._gear_num = checked
