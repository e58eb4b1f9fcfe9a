"""DynCanAxis: one DYN2/DYN4 drive on a DYN CAN bus, on the shared client
(:mod:`servobus.protocols.dyncan.client`): CommandAxis plus what only CAN has."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any, ClassVar

from servobus.axis.base import AsyncAxis
from servobus.families.dmm import units as U
from servobus.families.dmm.command_axis import CommandAxis, CommandSet
from servobus.protocols.dyncan import codec as c
from servobus.protocols.dyncan import commands as cmds
from servobus.protocols.dyncan.client import ID_REINIT_S, AsyncDynCanClient, open_can_client


class DynCanAxis(CommandAxis):
    """One DYN2/DYN4 drive on a DYN CAN bus: CommandAxis plus what only CAN has.

    ``torque_raw()`` reads General_Read 0x1E: 700 = peak current, positive = CCW; the Axis
    ``current()`` converts with the peak current of the DYN2-TL model (20 A; pass
    ``peak_current_a=`` to the axis for another drive) and flips the sign so positive is
    towards increasing position, as on every Axis.
    """

    commands: ClassVar[CommandSet] = cmds
    protocol_name = "dyncan"
    drive_id_range = range(c.MIN_DRIVE_ID, c.MAX_DRIVE_ID + 1)
    amps_per_torque_unit = -U.MODELS[U.DEFAULT_MODEL].peak_current_a / U.CAN_TORQUE_FULL_SCALE
    id_settle_s = ID_REINIT_S
    client: AsyncDynCanClient

    async def position_direct(self, step: int) -> None:
        await self._run(cmds.make_position_direct(self._id, step))

    async def load_sync(self, value: int, *, relative: bool = False) -> None:
        """Load a synchronized move; start it with ``client.sync_trigger`` / sync_move."""
        await self._run(cmds.make_sync_load(self._id, value, relative=relative))

    def sync_group(self) -> object | None:
        """Drives on one client (one bus) start together: Sync_Trigger is a broadcast."""
        return self.client

    async def sync_move_to(self, moves: Sequence[tuple[AsyncAxis, int]]) -> None:
        """Load each drive's synchronized absolute move, then one Sync_Trigger (section 6)."""
        self._check_sync_moves(moves)
        targets: dict[int, int] = {}
        for axis, counts in moves:
            assert isinstance(axis, DynCanAxis)
            targets[axis.drive_id] = await axis.to_command(counts)
        await self.client.sync_move(targets)

    async def echo(self, data: bytes) -> bytes:
        return await self._run(cmds.make_echo(self._id, data))

    async def counter(self) -> int:
        return await self.client.heartbeat(self._id)

    async def read_params(self, names: Iterable[str] | None = None) -> dict[str, int]:
        """One group read per group touched (at most three frames for all nine)."""
        wanted = [p.name for p in self.parameters()] if names is None else [
            self.param_info(n).name for n in names]
        groups = dict.fromkeys(cmds.group_of(n)[1] for n in wanted)
        values: dict[str, int] = {}
        for fn in groups:
            values.update(await self._run(cmds.make_read_group(self._id, fn)))
        return {n: values[n] for n in wanted}

    async def write_params(self, values: Mapping[str, int]) -> None:
        """One group write per group touched; the untouched fields travel as 0 (unchanged)."""
        for name, value in values.items():
            self._check_param(name, value)
        await self.client.execute_all(cmds.make_set_params(self._id, dict(values)))
        if "gear_num" in values:
            self._gear_num = values["gear_num"]


async def open_can_axis(can: str, *, drive_id: int, timeout: float | None = None,
                        **options: Any) -> AsyncAxis:
    """Used by ``connect(can=...)``: the AsyncAxis of ``drive_id`` on bus ``can``."""
    cmds.check_drive_id(drive_id)  # before opening anything
    client = await open_can_client(can, timeout=timeout, **options)
    return DynCanAxis(client, drive_id)
