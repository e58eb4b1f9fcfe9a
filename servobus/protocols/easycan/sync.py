"""Synchronised multi-axis motion on EasyCan: the 2 ms position cache of several motors.

YZ-AIM manual 5.2 (0x1A-0x1C) and 5.4c/d: the host writes each motor's absolute-position
cache (silent frames 0x100|address, 4 bytes each); with 0x1C > 0 a motor takes its cache
every 2 ms on its own time base, and a write of 0x1C is the synchronisation signal that
restarts that time base and takes a cache loaded before it. So:

* :meth:`SyncGroup.move` loads every motor's cache with sync off, then signals all motors
  (the 0x1C writes go out back to back, one frame time apart): they start together.
* :meth:`SyncGroup.start` signals all motors and reads where they are (5.4c steps 1-2);
  :meth:`SyncGroup.stream` then sends one absolute position per motor per cycle (step 3-4).

Streaming decisions (servobus): cycles are slots ``t0 + k x cycle`` on the loop clock, with
``t0`` a quarter cycle after the signal was *sent*: the path to the motors (adapter, driver,
socketcand) delays the signal and the cache frames alike, so a frame sent between 0 and 1.5
ms after its slot reaches its motor within the same 2 ms cycle; a motor refuses a second
cache write within one cycle (5.5 error 0x05). asyncio timers wake up to a millisecond late
(epoll rounds to milliseconds), so the stream sleeps until ``spin_s`` (1.2 ms) before each
slot and then yields to the loop (``sleep(0)``) until the slot: on time within tens of
microseconds, at the cost of keeping the loop busy for that stretch of every cycle
(``spin_s=0`` turns it off). A cycle whose slot passed by more than 1.5 ms would reach the
motors in the next slot's cycle: it is skipped, not sent late (every cache value is an
absolute position, the next one supersedes it; ``StreamStats.skipped``). The final
positions are sent once more in the slot after the last cycle (a skipped or refused last
cycle would otherwise be lost; resending an absolute position is harmless), and the stream
then waits one cycle, so the motors have taken them before a ``stop()``. Every position of
a cycle is range-checked before any frame of it is sent.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable, Mapping

from servobus.errors import ArgumentRangeError
from servobus.families.yzaim import registers as yzaim
from servobus.link.stats import StreamStats
from servobus.protocols.easycan import commands as cmds
from servobus.protocols.easycan.client import AsyncEasyCanClient

CYCLE_S = yzaim.SYNC_CYCLE_S
PHASE = 0.25  # slots sit this fraction of a cycle after the synchronisation signal was sent
SYNC_ON = 1
SPIN_S = 0.0012  # wake this early and yield until the slot (asyncio timers wake ~1 ms late)


class SyncGroup:
    """Motors on one EasyCan client moved together through their position caches."""

    def __init__(self, client: AsyncEasyCanClient, addresses: Iterable[int], *,
                 cycle: float = CYCLE_S, spin_s: float = SPIN_S) -> None:
        self.client = client
        self.addresses = tuple(cmds.check_address(a) for a in addresses)
        if not self.addresses or len(set(self.addresses)) != len(self.addresses):
            raise ArgumentRangeError(f"a sync group needs distinct motors, got "
                                     f"{self.addresses}")
        if not 0 < cycle < 1:
            raise ArgumentRangeError(f"cycle={cycle!r} must be a number of seconds in (0, 1)")
        self.cycle = cycle
        if not 0 <= spin_s <= cycle:
            raise ArgumentRangeError(f"spin_s={spin_s!r} must be within 0..{cycle}")
        self.spin_s = spin_s
        self._t0: float | None = None

    def _caches(self, targets: Mapping[int, int]) -> list[cmds.EasyCanCommand]:
        unknown = set(targets) - set(self.addresses)
        if unknown:
            raise ArgumentRangeError(f"motors {sorted(unknown)} are not in this sync group")
        return [cmds.make_cache(a, targets[a]) for a in self.addresses if a in targets]

    async def _write_all(self, name: str, value: int) -> None:
        commands = [cmds.make_write(a, name, value) for a in self.addresses]
        await asyncio.gather(*(self.client.execute(c) for c in commands))

    async def signal(self) -> None:
        """The synchronisation signal (0x1C = 1) to every motor, back to back."""
        sent = asyncio.get_running_loop().time()
        await self._write_all("sync_control", SYNC_ON)
        self._t0 = sent + PHASE * self.cycle

    async def positions(self) -> dict[int, int]:
        """Every motor's absolute position (5.4c step 2)."""
        reads = [cmds.make_read(a, "absolute_position") for a in self.addresses]
        values = await asyncio.gather(*(self.client.read(r) for r in reads))
        return dict(zip(self.addresses, values, strict=True))

    async def move(self, targets: Mapping[int, int]) -> None:
        """Load each motor's cache with sync off, then signal them all: they start together.

        Each motor moves with its own curve (0x02 speed, 0x03 acceleration)."""
        caches = self._caches(targets)
        await self.stop()
        await self.client.send_only(*caches)
        await self.signal()

    async def start(self) -> dict[int, int]:
        """Synchronous mode on for every motor (one signal); returns where they are."""
        await self.signal()
        return await self.positions()

    async def stream(self, cycles: Iterable[Mapping[int, int]]) -> StreamStats:
        """One absolute position per motor per cycle, in the slots after :meth:`start`."""
        if self._t0 is None:
            await self.start()
        assert self._t0 is not None
        loop = asyncio.get_running_loop()
        stats = StreamStats()
        begin = loop.time()
        slot = max(0, int((begin - self._t0) // self.cycle) + 1)
        last: list[cmds.EasyCanCommand] = []
        for targets in cycles:
            caches = last = self._caches(targets)  # checked before any frame of the cycle
            due = self._t0 + slot * self.cycle
            delay = due - loop.time()
            if delay > self.spin_s:
                await asyncio.sleep(delay - self.spin_s)
            while loop.time() < due:  # the last stretch: yield, but do not sleep
                await asyncio.sleep(0)
            late = loop.time() - due
            if late > (1 - PHASE) * self.cycle:
                # it would reach the motors after their next tick, in the next slot's cycle:
                # skipped, the next positions replace these (module docstring)
                stats.skipped += 1
                slot += max(1, int(late // self.cycle))
                continue
            stats.max_lateness_s = max(stats.max_lateness_s, late)
            await self.client.send_only(*caches)
            stats.frames += len(caches)
            stats.cycles += 1
            slot += 1
        if last:  # the final positions once more (skipped or refused, they would be lost)
            delay = self._t0 + slot * self.cycle - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            await self.client.send_only(*last)
            await asyncio.sleep(self.cycle)  # the motors take them
        stats.elapsed_s = loop.time() - begin
        return stats

    async def stop(self) -> None:
        """Synchronous mode off (0x1C = 0) for every motor; caches are only stored then."""
        await self._write_all("sync_control", 0)
        self._t0 = None
