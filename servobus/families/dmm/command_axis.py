"""CommandAxis: the DMM profile over a protocol whose client executes pure ``make_*`` commands.

DYN232M and DYN CAN share the DMM command vocabulary (:mod:`servobus.families.dmm.vocabulary`).
A protocol supplies a commands module (the :class:`CommandSet`, whose builders return
:class:`Request` objects typed by their result) and a client with ``execute``
(:class:`CommandClient`: a ``Request[T]`` in, its ``T`` out, by the rules of
:mod:`servobus.link.transaction`). This class gives :class:`~servobus.families.dmm.axis.DmmAxis`
its hooks from them once: each profile action is one builder, the status byte is the DYN2's
(7.3), the torque readout becomes amperes through ``amps_per_torque_unit``. Dyn232Axis and
DynCanAxis only add what their protocol really has on its own (CAN parameter groups, sync
moves, Position Direct, the 10 ms wait after an id change).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, ClassVar, Never, Protocol, TypeVar, cast

from servobus import checks
from servobus.axis.base import AxisTraceHook
from servobus.axis.client_axis import ClientAxis
from servobus.axis.types import AxisStatus, Family, ParamInfo
from servobus.errors import DriveTimeout, MoveFailed, NotSupported, ProtocolError
from servobus.families.dmm.axis import Action, DmmAxis, Readout
from servobus.families.dmm.family import DYN2, axis_status
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


class CommandAxis(ClientAxis[CommandClient], DmmAxis[DriveStatus]):
    """One DYN2/DC2/DYN4 drive on one connection, driven through a protocol's CommandSet."""

    commands: ClassVar[CommandSet]
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
        return DYN2

    @property
    def drive_ids(self) -> range:
        return self.drive_id_range

    # ------------------------------------------------------------- DmmAxis hooks
    def _build(self, action: Action, value: int) -> Request[None]:
        """The command of one profile action (the builders check their ranges)."""
        c, i = self.commands, self._id
        match action:
            case Action.MOVE_ABSOLUTE:
                return c.make_move_absolute(i, value)
            case Action.MOVE_RELATIVE:
                return c.make_move_relative(i, value)
            case Action.TURN:
                return c.make_turn_const_speed(i, value)
            case Action.SQUARE_WAVE:
                return c.make_square_wave(i, value)
            case Action.SINE_WAVE:
                return c.make_sine_wave(i, value)
            case Action.WAVE_FREQUENCY:
                return c.make_wave_frequency(i, value)
            case Action.SET_ORIGIN:
                return c.make_set_origin(i)
            case Action.ENABLE:
                return c.make_enable(i)
            case Action.DISABLE:
                return c.make_disable(i)
            case Action.RESET:
                return c.make_reset(i)

    async def _send(self, action: Action, value: int = 0) -> None:
        await self._run(self._build(action, value))

    def _check_action(self, action: Action, value: int) -> None:
        self._build(action, value)  # the builders check their ranges

    async def _read_value(self, readout: Readout) -> int:
        c = self.commands
        factory = {Readout.POSITION: c.make_read_position, Readout.SPEED: c.make_read_speed,
                   Readout.TORQUE: c.make_read_torque}[readout]
        return await self._run(self._read(factory))

    async def _read_status(self) -> DriveStatus:
        return await self.drive_status()

    def _status_busy(self, status: DriveStatus) -> bool:
        return status.motion_busy

    def _axis_status(self, status: DriveStatus, speed_rpm: float | None) -> AxisStatus:
        return axis_status(status, speed_rpm=speed_rpm)

    def _torque_amps(self, raw: int) -> float:
        return raw * self.amps_per_torque_unit

    async def _write_param(self, name: str, value: int) -> None:
        await self._run(self.commands.make_set_param(self._id, name, value))

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

    # ------------------------------------------------------------- registers
    async def drive_status(self) -> DriveStatus:
        """The DYN2 status byte as decoded by the family (7.3)."""
        return await self._run(self._read(self.commands.make_read_status))

    async def config(self) -> DriveConfig:
        return await self._run(self._read(self.commands.make_read_config))

    async def set_config(self, cfg: DriveConfig) -> None:
        await self._run(self.commands.make_set_config(self._id, cfg))

    # ------------------------------------------------------------- parameters and id
    def parameters(self) -> tuple[ParamInfo, ...]:
        reach = set(self.commands.REACHABLE_PARAMS)
        return tuple(p for p in self.family.params if p.name in reach)

    def _check_param(self, name: str, value: object) -> int:
        checked = super()._check_param(name, value)
        self.commands.make_set_param(self._id, name, checked)  # the protocol's own checks
        return checked

    async def read_param(self, name: str) -> int:
        checks.param_name(name)  # before it keys the read cache
        return await self._run(self._read_param(name))

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

