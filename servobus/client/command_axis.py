"""CommandAxis: the AsyncAxis of any protocol whose client executes pure ``make_*`` commands.

A protocol supplies a commands module (the :class:`CommandSet` vocabulary) and a client with
``execute``; this class maps the Axis API onto them once. Dyn232Axis and DynCanAxis only add
what their protocol really has on its own (CAN parameter groups, sync moves, Position
Direct, the 10 ms wait after an id change).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, ClassVar, Protocol

from servobus.client import checks
from servobus.client.axis import AsyncAxis, AxisTraceHook
from servobus.client.eeprom_guard import EepromGuard
from servobus.drive.registers import DriveConfig, DriveStatus
from servobus.errors import DriveTimeout, ProtocolError


class CommandSet(Protocol):
    """The pure builders a protocol's commands module offers (range checks happen there)."""

    def check_drive_id(self, drive_id: int) -> int: ...
    def make_move_absolute(self, drive_id: int, position: int) -> Any: ...
    def make_move_relative(self, drive_id: int, distance: int) -> Any: ...
    def make_turn_const_speed(self, drive_id: int, rpm: int) -> Any: ...
    def make_square_wave(self, drive_id: int, amplitude: int) -> Any: ...
    def make_sine_wave(self, drive_id: int, amplitude: int) -> Any: ...
    def make_wave_frequency(self, drive_id: int, hz: int) -> Any: ...
    def make_set_origin(self, drive_id: int) -> Any: ...
    def make_enable(self, drive_id: int) -> Any: ...
    def make_disable(self, drive_id: int) -> Any: ...
    def make_reset(self, drive_id: int) -> Any: ...
    def make_read_status(self, drive_id: int) -> Any: ...
    def make_read_config(self, drive_id: int) -> Any: ...
    def make_set_config(self, drive_id: int, config: DriveConfig | int) -> Any: ...
    def make_read_position(self, drive_id: int) -> Any: ...
    def make_read_speed(self, drive_id: int) -> Any: ...
    def make_read_torque(self, drive_id: int) -> Any: ...
    def make_read_param(self, drive_id: int, name: str) -> Any: ...
    def make_set_param(self, drive_id: int, name: str, value: int) -> Any: ...
    def make_read_id(self, drive_id: int) -> Any: ...
    def make_assign_id(self, drive_id: int, new_id: int) -> Any: ...


class CommandClient(Protocol):
    guard: EepromGuard

    async def execute(self, command: Any, *, retries: int | None = None,
                      timeout: float | None = None) -> Any: ...
    def add_trace(self, hook: AxisTraceHook) -> None: ...
    async def close(self) -> None: ...


class CommandAxis(AsyncAxis):
    """One drive on one connection, driven through a protocol's CommandSet."""

    commands: ClassVar[CommandSet]
    protocol_name: ClassVar[str]
    #: Wait after Assign_Drive_ID before using the new id (DYN CAN: 10 ms re-initialisation).
    id_settle_s: ClassVar[float] = 0.0

    def __init__(self, client: CommandClient, drive_id: int, *, owns_client: bool = True) -> None:
        self.client = client
        self._id = self.commands.check_drive_id(drive_id)
        self._owns_client = owns_client
        self._reads: dict[tuple[object, ...], Any] = {}  # read commands are immutable

    def _read(self, factory: Callable[..., Any], *args: Any) -> Any:
        """The read command for this drive, built once (polling loops reuse it)."""
        key = (factory, *args)
        command = self._reads.get(key)
        if command is None:
            command = self._reads[key] = factory(self._id, *args)
        return command

    async def _run(self, command: Any, **kw: Any) -> Any:
        return await self.client.execute(command, **kw)

    @property
    def drive_id(self) -> int:
        return self._id

    @property
    def protocol(self) -> str:
        return self.protocol_name

    # ------------------------------------------------------------- motion
    async def _send_move_to(self, position: int) -> None:
        await self._run(self.commands.make_move_absolute(self._id, position))

    async def _send_move_by(self, distance: int) -> None:
        await self._run(self.commands.make_move_relative(self._id, distance))

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

    # ------------------------------------------------------------- registers and readouts
    async def status(self) -> DriveStatus:
        result: DriveStatus = await self._run(self._read(self.commands.make_read_status))
        return result

    async def config(self) -> DriveConfig:
        result: DriveConfig = await self._run(self._read(self.commands.make_read_config))
        return result

    async def set_config(self, cfg: DriveConfig) -> None:
        await self._run(self.commands.make_set_config(self._id, cfg))

    async def position(self) -> int:
        return int(await self._run(self._read(self.commands.make_read_position)))

    async def speed(self) -> int:
        return int(await self._run(self._read(self.commands.make_read_speed)))

    async def torque(self) -> int:
        return int(await self._run(self._read(self.commands.make_read_torque)))

    # ------------------------------------------------------------- parameters and id
    def _check_param(self, name: str, value: int) -> None:
        self.commands.make_set_param(self._id, name, value)  # range + reachable here

    def _check_move(self, value: int, *, relative: bool) -> None:
        build = self.commands.make_move_relative if relative else self.commands.make_move_absolute
        build(self._id, value)  # type + range, nothing sent

    async def read_param(self, name: str) -> int:
        checks.param_name(name)  # before it keys the read cache
        return int(await self._run(self._read(self.commands.make_read_param, name)))

    async def write_param(self, name: str, value: int) -> None:
        await self._run(self.commands.make_set_param(self._id, name, value))

    async def read_id(self) -> int:
        return int(await self._run(self._read(self.commands.make_read_id)))

    async def assign_id(self, new_id: int) -> None:
        """Assign_Drive_ID; after the protocol's settle time this axis addresses ``new_id``."""
        await self._run(self.commands.make_assign_id(self._id, new_id))
        if self.id_settle_s:
            await asyncio.sleep(self.id_settle_s)
        self.client.guard.rename_drive(self._id, new_id)
        self._id = new_id
        self._reads.clear()

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

    # ------------------------------------------------------------- connection
    async def sibling(self, drive_id: int) -> CommandAxis:
        return type(self)(self.client, drive_id, owns_client=False)

    async def add_trace(self, hook: AxisTraceHook) -> None:
        self.client.add_trace(hook)

    async def close(self) -> None:
        if self._owns_client:
            await self.client.close()

    def __repr__(self) -> str:
        return f"<{type(self).__name__} id {self._id}>"
