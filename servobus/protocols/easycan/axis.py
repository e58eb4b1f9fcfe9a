"""EasyCanAxis: one YZ-AIM motor on an EasyCan bus, in the Axis units (docs/easycan.md).

Positions are the motor's own counts (32,768 per revolution) on the wire, speeds rpm. The
mapping of the Axis calls onto the YZ-AIM registers is :mod:`servobus.families.yzaim.axis`'s
(shared with Modbus RTU); what EasyCan does its own way (YZ-AIM manual sections):

* registers are read with 0x03 (one register or a 32-bit pair), the status and current
  registers with one 0x12 read, and written with 0x06; the commands are built once per
  motor and reused.
* ``move_by``: 0x0C incremental_position; the reply carries the position the relative move
  starts from, so no read is needed when the axis knows no target.
* ``emergency_stop()``: 0x10, the motor stops at once (5.3d); ``set_origin()``: the 0x11
  absolute position clear (no reply).
* ``save_parameters()``: the save flag passes the client's EEPROM guard.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any

from servobus.axis.base import AsyncAxis
from servobus.axis.capabilities import Capability
from servobus.errors import ArgumentRangeError
from servobus.families.yzaim.axis import YzaimAxis
from servobus.link.stats import StreamStats
from servobus.protocols.easycan import commands as cmds
from servobus.protocols.easycan.client import AsyncEasyCanClient
from servobus.protocols.easycan.describe import describe
from servobus.protocols.easycan.messages import Message
from servobus.protocols.easycan.sync import SyncGroup


class EasyCanAxis(YzaimAxis[AsyncEasyCanClient]):
    protocol_name = "easycan"
    reachable_params = cmds.REACHABLE_PARAMS
    protocol_capabilities = YzaimAxis.protocol_capabilities | {Capability.CYCLIC_POSITION,
                                                               Capability.CYCLIC_GROUP}

    def __init__(self, client: AsyncEasyCanClient, address: int, *,
                 owns_client: bool = True) -> None:
        super().__init__(client, address, owns_client=owns_client)
        self._reads: dict[tuple[object, ...], cmds.EasyCanCommand] = {}

    def _check_id(self, drive_id: int) -> int:
        return cmds.check_address(drive_id)

    def _read_cmd(self, factory: Callable[..., cmds.EasyCanCommand],
                  *args: Any) -> cmds.EasyCanCommand:
        key = (factory, *args)
        found = self._reads.get(key)
        if found is None:
            found = self._reads[key] = factory(self._id, *args)
        return found

    def _forget_address(self) -> None:
        self._reads.clear()

    # ------------------------------------------------------------- register primitives
    async def _read(self, name: str) -> int:
        return await self.client.read(self._read_cmd(cmds.make_read, name))

    async def _read_words(self, names: tuple[str, ...]) -> tuple[int, ...]:
        return await self.client.read_words(self._read_cmd(cmds.make_read_registers, names))

    async def _write(self, name: str, value: int) -> None:
        await self.client.execute(cmds.make_write(self._id, name, int(value)))

    def ping_deadline(self) -> float:
        """The client's per-attempt deadline, ``timeout`` (a frame each way takes well under
        a millisecond on the bus; the rest is the motor's reply time and the adapter's)."""
        return self.client.timeout

    def describe_traced(self, item: object, from_drive: bool) -> str | None:
        """A traced EasyCan message in the sniff decoder's words (not its repr)."""
        return describe(item) if isinstance(item, Message) else None

    async def _probe(self, timeout: float) -> None:
        await self.client.execute(self._read_cmd(cmds.make_read, "alarm_code"), retries=0,
                                  timeout=timeout)

    async def _write_increment(self, distance: int, *, need_start: bool) -> int | None:
        return await self.client.position_write(cmds.make_move_relative(self._id, distance))

    # ------------------------------------------------------------- synchronised start
    def sync_group(self) -> object | None:
        """Motors on one client (one bus) start together through their position caches."""
        return self.client

    async def sync_move_to(self, moves: Sequence[tuple[AsyncAxis, int]]) -> None:
        """Position mode for each, load every cache with sync off, one synchronisation
        signal to all (servobus.protocols.easycan.sync.SyncGroup.move), then sync off again
        so the motors take ordinary moves afterwards (a motor keeps the cache it took)."""
        self._check_sync_moves(moves)
        motors: list[tuple[EasyCanAxis, int]] = []
        for axis, counts in moves:
            assert isinstance(axis, EasyCanAxis)
            motors.append((axis, counts))
        for axis, _ in motors:
            await axis.position_mode_alone()
            axis._target = None
        group = SyncGroup(self.client, [a.drive_id for a, _ in motors])
        await group.move({a.drive_id: counts for a, counts in motors})
        for axis, counts in motors:
            axis._target = counts
        await group.stop()

    async def stream_cycles(self, next_position: Callable[[], int | None]) -> StreamStats:
        """The 2 ms position cache with the sync signal (5.4c/d, SyncGroup.stream), this
        motor alone (:meth:`stream_cycles_together`)."""
        return await self.stream_cycles_together([(self, next_position)])

    async def stream_cycles_together(
            self, streams: Sequence[tuple[AsyncAxis, Callable[[], int | None]]],
    ) -> StreamStats:
        """The 2 ms position cache of every motor of ``streams`` (all on this client) with
        one sync signal for them all (5.4c/d, SyncGroup.stream): position mode, each cache
        loaded with where its motor stands and sync on (so the first cycle moves nothing),
        then one cache frame per motor per cycle until a ``next_position()`` returns None;
        sync off again whatever ends the stream (each motor keeps the last cache it took)."""
        motors: list[tuple[EasyCanAxis, Callable[[], int | None]]] = []
        for axis, next_position in streams:
            if not isinstance(axis, EasyCanAxis) or axis.sync_group() is not self.sync_group():
                raise ArgumentRangeError(f"{axis!r} does not stream together with {self!r}")
            motors.append((axis, next_position))
        for axis, _ in motors:
            await axis.position_mode_alone()
            axis._target = None
        group = SyncGroup(self.client, [a.drive_id for a, _ in motors])
        await group.move({a.drive_id: await a.position() for a, _ in motors})

        def cycles() -> Iterator[dict[int, int]]:
            while True:
                targets: dict[int, int] = {}
                for axis, next_position in motors:
                    position = next_position()
                    if position is None:
                        return
                    targets[axis.drive_id] = axis._check_move(position, relative=False)
                yield targets

        try:
            return await group.stream(cycles())
        finally:
            await group.stop()

    # ------------------------------------------------------------- EasyCan's own frames
    async def emergency_stop(self) -> None:
        """0x10: the motor stops at once (5.3d); speed mode ends."""
        self._target = None
        await self.client.execute(cmds.make_emergency_stop(self._id))

    async def set_origin(self) -> None:
        await self.client.send_only(cmds.make_clear_position(self._id))
        self._target = None
