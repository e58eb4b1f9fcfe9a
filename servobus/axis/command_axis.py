"""CommandAxis: the AsyncAxis of a DMM protocol whose client executes pure ``make_*`` commands.

A protocol supplies a commands module (the :class:`CommandSet` vocabulary, whose builders
return :class:`Request` objects typed by their result) and a client with ``execute``
(:class:`CommandClient`: a ``Request[T]`` in, its ``T`` out, by the rules of
:mod:`servobus.link.transaction`); this class maps the Axis API onto them once, in the Axis
units: counts are
converted to the drive's command units through GEAR_NUM (read from the drive once, then
tracked through this axis's own writes; see :mod:`servobus.families.dmm.family`), the
status byte becomes an AxisStatus, the torque readout amperes. Dyn232Axis and DynCanAxis
only add what their protocol really has on its own (CAN parameter groups, sync moves,
Position Direct, the 10 ms wait after an id change).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, ClassVar, Never, Protocol, TypeVar, cast

from servobus.axis import checks
from servobus.axis.base import DEFAULT_WAIT_TIMEOUT_S, AxisTraceHook, check_int
from servobus.axis.client_axis import ClientAxis
from servobus.errors import DriveTimeout, MoveFailed, NotSupported, ProtocolError
from servobus.families.base import AxisStatus, Family, ParamInfo, StreamProfile
from servobus.families.dmm import units as U
from servobus.families.dmm import vocabulary as V
from servobus.families.dmm.family import DYN2, axis_status, command_to_counts, counts_to_command
from servobus.families.dmm.registers import DriveConfig, DriveStatus, ServoMode
from servobus.link.eeprom_guard import EepromGuard
from servobus.link.transaction import TransactionManager

T = TypeVar("T")
T_co = TypeVar("T_co", covariant=True)


class Request(Protocol[T_co]):
    """A pure command of some protocol; executing it gives ``T_co`` (None: no reply).

    A protocol's command class is generic in its result (``Command[DriveStatus]``) and has
    ``parse``: reply -> result. What a reply is (an int, a CAN frame) is the protocol's
    business, so the seam only knows that ``parse`` takes *something* (``Never``: any
    one-argument callable fits) and what it returns.
    """

    @property
    def drive_id(self) -> int: ...
    @property
    def parse(self) -> Callable[[Never], T_co]: ...


class CommandSet(Protocol):
    """The pure builders a protocol's commands module offers (range checks happen there)."""

    def check_drive_id(self, drive_id: int) -> int: ...
    def make_move_absolute(self, drive_id: int, position: int) -> Request[None]: ...
    def make_move_relative(self, drive_id: int, distance: int) -> Request[None]: ...
    def make_turn_const_speed(self, drive_id: int, rpm: int) -> Request[None]: ...
    def make_square_wave(self, drive_id: int, amplitude: int) -> Request[None]: ...
    def make_sine_wave(self, drive_id: int, amplitude: int) -> Request[None]: ...
    def make_wave_frequency(self, drive_id: int, hz: int) -> Request[None]: ...
    def make_set_origin(self, drive_id: int) -> Request[None]: ...
    def make_enable(self, drive_id: int) -> Request[None]: ...
    def make_disable(self, drive_id: int) -> Request[None]: ...
    def make_reset(self, drive_id: int) -> Request[None]: ...
    def make_read_status(self, drive_id: int) -> Request[DriveStatus]: ...
    def make_read_config(self, drive_id: int) -> Request[DriveConfig]: ...
    def make_set_config(self, drive_id: int, config: DriveConfig | int) -> Request[None]: ...
    def make_read_position(self, drive_id: int) -> Request[int]: ...
    def make_read_speed(self, drive_id: int) -> Request[int]: ...
    def make_read_torque(self, drive_id: int) -> Request[int]: ...
    def make_read_param(self, drive_id: int, name: str) -> Request[int]: ...
    def make_set_param(self, drive_id: int, name: str, value: int) -> Request[None]: ...
    def make_read_id(self, drive_id: int) -> Request[int]: ...
    def make_assign_id(self, drive_id: int, new_id: int) -> Request[None]: ...
    @property
    def REACHABLE_PARAMS(self) -> tuple[str, ...]: ...


class CommandClient(Protocol):
    """What CommandAxis needs of a protocol client. ``execute`` refuses (ArgumentRangeError)
    a Request built by another protocol's CommandSet."""

    transactions: TransactionManager[Any, Any, Any]

    @property
    def guard(self) -> EepromGuard: ...
    def reply_deadline_s(self) -> float:
        """Per-attempt deadline of a short read (wire time + the drive's reply time)."""
        ...
    async def execute(self, command: Request[T], *, retries: int | None = None,
                      timeout: float | None = None) -> T: ...
    def add_trace(self, hook: AxisTraceHook) -> None: ...
    async def close(self) -> None: ...


class CommandAxis(ClientAxis[CommandClient]):
    """One drive on one connection, driven through a protocol's CommandSet."""

    commands: ClassVar[CommandSet]
    family_model: ClassVar[Family] = DYN2
    drive_id_range: ClassVar[range]
    #: Torque readout -> amperes (positive = towards increasing position).
    amps_per_torque_unit: ClassVar[float] = 1.0
    #: Wait after Assign_Drive_ID before using the new id (DYN CAN: 10 ms re-initialisation).
    id_settle_s: ClassVar[float] = 0.0

    def __init__(self, client: CommandClient, drive_id: int, *, owns_client: bool = True) -> None:
        super().__init__(client, drive_id, owns_client=owns_client)
        #: Read commands of this drive, built once (they are immutable; polling reuses them).
        self._reads: dict[Callable[[int], Request[object]], Request[object]] = {}
        self._param_reads: dict[str, Request[int]] = {}
        self._gear_num: int | None = None  # read on the first move (Axis units -> command)

    def _check_id(self, drive_id: int) -> int:
        return self.commands.check_drive_id(drive_id)

    def _read(self, factory: Callable[[int], Request[T]]) -> Request[T]:
        """The read command of ``factory`` for this drive, built once."""
        command = self._reads.get(factory)
        if command is None:
            command = self._reads[factory] = factory(self._id)
        return cast("Request[T]", command)  # stored under its own factory: the same T

    def _read_param(self, name: str) -> Request[int]:
        command = self._param_reads.get(name)
        if command is None:
            command = self._param_reads[name] = self.commands.make_read_param(self._id, name)
        return command

    async def _run(self, command: Request[T]) -> T:
        return await self.client.execute(command)

    @property
    def family(self) -> Family:
        return self.family_model

    @property
    def drive_ids(self) -> range:
        return self.drive_id_range

    # ------------------------------------------------------------- units
    async def gear_num(self) -> int:
        """GEAR_NUM as this axis knows it (read from the drive the first time)."""
        if self._gear_num is None:
            self._gear_num = await self.read_param("gear_num")
        return self._gear_num

    async def to_command(self, counts: int) -> int:
        """Encoder counts -> the drive's point-to-point command units (rounded)."""
        return counts_to_command(counts, await self.gear_num())

    # ------------------------------------------------------------- motion
    async def _send_move_to(self, position: int) -> None:
        command = await self.to_command(position)
        self._check_limits(position, False)  # now at the drive's GEAR_NUM
        await self._run(self.commands.make_move_absolute(self._id, command))

    async def _send_move_by(self, distance: int) -> None:
        command = await self.to_command(distance)
        self._check_limits(distance, True)
        await self._run(self.commands.make_move_relative(self._id, command))

    def _move_limits(self, relative: bool) -> tuple[int, int] | None:
        """The 28-bit command range in counts at the GEAR_NUM known so far (the widest,
        GEAR_NUM's minimum, before it is read)."""
        gear = self._gear_num or self.family.param("gear_num").minimum
        return command_to_counts(V.VALUE_MIN, gear), command_to_counts(V.VALUE_MAX, gear)

    def _limits_note(self) -> str:
        return f" at GEAR_NUM {self._gear_num}" if self._gear_num else ""

    async def move_range(self, *, relative: bool = False) -> tuple[int, int] | None:
        await self.gear_num()
        return self._move_limits(relative)

    async def stream_profile(self) -> StreamProfile:
        """Max Speed and Max Accel at GEAR_NUM: a target update (DTPU) runs the
        point-to-point profile; never written per motion (EEPROM, docs/safety.md)."""
        return StreamProfile(*U.stream_profile(await self.read_param("max_speed"),
                                               await self.read_param("max_accel"),
                                               await self.gear_num()))

    async def move_to_command(self, command: int, *, wait: bool = False,
                              timeout: float | None = None) -> None:
        """Absolute move in raw command units (x 4096/GEAR_NUM x 4 counts), no conversion."""
        await self._run(self.commands.make_move_absolute(self._id, check_int("command", command)))
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if timeout is None else timeout)

    async def move_by_command(self, command: int, *, wait: bool = False,
                              timeout: float | None = None) -> None:
        """Relative move in raw command units, no conversion."""
        await self._run(self.commands.make_move_relative(self._id, check_int("command", command)))
        if wait:
            await self.wait_idle(DEFAULT_WAIT_TIMEOUT_S if timeout is None else timeout)

    async def turn(self, rpm: int) -> None:
        await self._run(self.commands.make_turn_const_speed(self._id, rpm))

    async def square_wave(self, amplitude: int) -> None:
        await self._run(self.commands.make_square_wave(self._id, amplitude))

    async def sine_wave(self, amplitude: int) -> None:
        await self._run(self.commands.make_sine_wave(self._id, amplitude))

    async def wave_frequency(self, hz: int) -> None:
        await self._run(self.commands.make_wave_frequency(self._id, hz))

    async def set_origin(self) -> None:
        await self._run(self.commands.make_set_origin(self._id))

    async def enable(self) -> None:
        await self._run(self.commands.make_enable(self._id))

    async def disable(self) -> None:
        await self._run(self.commands.make_disable(self._id))

    async def reset(self) -> None:
        await self._run(self.commands.make_reset(self._id))

    async def home(self) -> None:
        """DMM absolute-encoder homing (DYN2 manual 7.1 "Absolute encoder homing", 7.3
        config b2; DYN CAN 6 Set_Origin): in absolute mode the drive returns to its stored
        zero after a power-on reset - the nearest one, within half a turn (the encoder is
        single-turn) - and takes no command until it is there. The reset selector is that
        reset (it also clears a latched alarm). In relative mode there is no stored zero:
        NotSupported, nothing sent."""
        cfg = await self.config()
        if not cfg.absolute:
            raise NotSupported(
                f"drive {self._id} is in relative mode (config b2 = 0): a {self.family.title} "
                "homes only in absolute mode, returning to the zero stored by Set_Origin after "
                "a power-on reset: set absolute mode in its config, or set "
                "the zero where the axis stands (origin)", family=self.family.name)
        if cfg.free or cfg.servo_mode is not ServoMode.POSITION:
            how = ("with the motor free (b5 = 1)" if cfg.free
                   else f"in {cfg.servo_mode.name.lower()} mode")
            raise MoveFailed(f"drive {self._id} would not home: its config starts it {how}, "
                             "and only a drive in position mode returns to its zero; nothing "
                             "was sent", drive_id=self._id)
        await self.reset()

    async def _move_profile_values(self, rpm: float | None,
                                   accel_rpm_s: float | None) -> dict[str, int]:
        """Max Speed and Max Accel (EEPROM) at the drive's GEAR_NUM (units.profile_params)."""
        return U.profile_params(rpm, accel_rpm_s, await self.gear_num())

    # ------------------------------------------------------------- registers and readouts
    async def drive_status(self) -> DriveStatus:
        """The DYN2 status byte as decoded by the family (7.3)."""
        return await self._run(self._read(self.commands.make_read_status))

    async def status(self) -> AxisStatus:
        """The status byte, and the speed when no profile runs (moving = the motor turns,
        family.axis_status): a constant speed leaves the busy bit clear."""
        status = await self.drive_status()
        return axis_status(status, speed_rpm=None if status.motion_busy else await self.speed())

    async def readings(self) -> tuple[int, float, AxisStatus]:
        """One speed read serves both the speed and :meth:`status` (3 requests, not 4)."""
        status, position, speed = await asyncio.gather(
            self.drive_status(), self.position(), self.speed())
        return position, speed, axis_status(
            status, speed_rpm=None if status.motion_busy else speed)

    async def config(self) -> DriveConfig:
        return await self._run(self._read(self.commands.make_read_config))

    async def set_config(self, cfg: DriveConfig) -> None:
        await self._run(self.commands.make_set_config(self._id, cfg))

    async def position(self) -> int:
        return await self._run(self._read(self.commands.make_read_position))

    async def speed(self) -> float:
        return float(await self._run(self._read(self.commands.make_read_speed)))

    async def torque_raw(self) -> int:
        """The protocol's torque readout as sent (see ``amps_per_torque_unit``)."""
        return await self._run(self._read(self.commands.make_read_torque))

    async def current(self) -> float:
        return await self.torque_raw() * self.amps_per_torque_unit

    # ------------------------------------------------------------- parameters and id
    def parameters(self) -> tuple[ParamInfo, ...]:
        reach = set(self.commands.REACHABLE_PARAMS)
        return tuple(p for p in self.family.params if p.name in reach)

    def _check_param(self, name: str, value: object) -> int:
        checked = super()._check_param(name, value)
        self.commands.make_set_param(self._id, name, checked)  # the protocol's own checks
        return checked

    def _check_move(self, value: object, *, relative: bool) -> int:
        """Type, and range at the GEAR_NUM known so far (the widest, GEAR_NUM's minimum, before
        it is read): a value no gear can reach is refused before even the gear read."""
        counts = super()._check_move(value, relative=relative)
        gear = self._gear_num or self.family.param("gear_num").minimum
        build = self.commands.make_move_relative if relative else self.commands.make_move_absolute
        build(self._id, counts_to_command(counts, gear))
        return counts

    async def position_window(self) -> int:
        """OnRange (1/16384 rev) in counts: the drive's own in-position window."""
        return max(1, round(U.onrange_to_counts(await self.read_param("on_range"))))

    async def read_param(self, name: str) -> int:
        checks.param_name(name)  # before it keys the read cache
        return await self._run(self._read_param(name))

    async def write_param(self, name: str, value: int) -> None:
        self._check_param(name, value)
        await self._run(self.commands.make_set_param(self._id, name, value))
        if name == "gear_num":
            self._gear_num = value

    async def read_id(self) -> int:
        return await self._run(self._read(self.commands.make_read_id))

    async def assign_id(self, new_id: int) -> None:
        """Assign_Drive_ID; after the protocol's settle time this axis addresses ``new_id``."""
        await self._run(self.commands.make_assign_id(self._id, new_id))
        if self.id_settle_s:
            await asyncio.sleep(self.id_settle_s)
        self.client.guard.rename_drive(self._id, new_id)
        self._id = new_id
        self._reads.clear()
        self._param_reads.clear()

    def ping_deadline(self) -> float:
        return self.client.reply_deadline_s()

    async def ping(self, timeout: float = 0.05) -> bool:
        """One status read without retry. A corrupt reply still proves something answered."""
        try:
            await self.client.execute(self._read(self.commands.make_read_status), retries=0,
                                      timeout=timeout)
        except DriveTimeout:
            return False
        except ProtocolError:
            return True
        return True
