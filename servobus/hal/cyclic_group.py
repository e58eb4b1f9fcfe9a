"""Position axes that stream as one group (docs/linuxcnc.md, "Sync groups").

Axes whose drives offer ``Capability.CYCLIC_GROUP`` with one group key
(``AsyncMachineAxis.cyclic_group``: the motors of one YZ-AIM EasyCan bus) stream their
``position-cmd`` in one stream: each cycle one position per axis and one synchronisation
signal for the group. Decisions:

* the group starts when every position axis of it is enabled (each by its own ``enable``
  rising edge, as LinuxCNC's joints are enabled together); until then none streams;
* the group stops together: when one axis stops streaming (a fault, a refused step, its
  ``enable`` falling) the stream ends for all and every axis of the group is stopped; a
  fault of one latches the others ("stopped with its sync group"), so each needs
  ``fault-reset`` and a new ``enable`` edge; a disabled one only ends the others' stream
  (they need a new ``enable`` edge, they never resume by themselves);
* an axis that enables while its group already streams without it is not streamed (it
  was offline when the group formed): disable the group and enable it again.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

from servobus.errors import ServobusError
from servobus.link.stats import StreamStats

if TYPE_CHECKING:
    from servobus.machine.axis import AsyncMachineAxis

log = logging.getLogger(__name__)

#: How long a stop waits for the group's stream to end and its axes to stop (the stream
#: ends at its next cycle, 2 ms; each stop is four register writes).
END_S = 1.0


class Member(Protocol):
    """What a group needs of one of its axes (servobus.hal.bridge.AxisBridge; a protocol
    here, so that the bridge imports the group and not the other way round)."""

    axis: AsyncMachineAxis
    latched: str | None
    streaming: bool
    moved: bool  # streamed since its last completed stop
    cyclic_stats: StreamStats | None

    @property
    def fault(self) -> bool: ...

    def latch(self, why: str) -> None: ...

    def next_cyclic(self) -> float | None: ...


class CyclicGroup:
    """The position axes of one group key and their one stream."""

    def __init__(self, key: object) -> None:
        self.key = key
        self.members: list[Member] = []
        self._joined: list[Member] = []
        self.task: asyncio.Task[None] | None = None
        self.stats: StreamStats | None = None  # the last stream's figures

    @property
    def names(self) -> str:
        return ", ".join(m.axis.name for m in self.members)

    def join(self, member: Member, members: Sequence[Member]) -> bool:
        """``member`` is enabled and ready; the stream starts once every one of
        ``members`` (the group's position axes now) is. False: the group streams without
        it (module docstring)."""
        if self.task is not None:
            return member in self.members and member in self._joined
        self.members = list(members)
        if member not in self._joined:
            self._joined.append(member)
        if all(m in self._joined for m in self.members):
            self.task = asyncio.create_task(self._run(), name=f"hal sync group {self.names}")
        return True

    async def leave(self, member: Member) -> None:
        """``member`` stopped streaming: the group's stream ends (at its next cycle)."""
        if member in self._joined:
            self._joined.remove(member)
        task = self.task
        if task is not None and task is not asyncio.current_task():
            try:
                await asyncio.wait_for(asyncio.shield(task), END_S)
            except TimeoutError:
                log.warning("sync group %s: the stream did not end within %g s: cancelled",
                            self.names, END_S)
                task.cancel()

    async def _run(self) -> None:
        """The stream, then the stop of every axis; ``task`` stays set until both are done,
        so that :meth:`leave` (the component's exit too) waits for the stops and never
        stops a motor at the same time as they do."""
        try:
            await self._stream_and_stop(list(self.members))
        finally:
            self.task = None
            self._joined.clear()

    async def _stream_and_stop(self, members: list[Member]) -> None:
        log.info("sync group %s: streaming position-cmd every cycle, one sync signal",
                 self.names)
        lead = members[0]
        try:
            self.stats = await lead.axis.stream_cycles_together(
                [(m.axis, m.next_cyclic) for m in members])
        except ServobusError as exc:
            for m in members:
                m.latch(f"the sync group's cyclic stream failed: {exc}")
        self._joined.clear()  # the stream is over: an enable now joins no stream
        for m in members:
            m.cyclic_stats = self.stats
        cause = next((m for m in members if m.fault), None)
        for m in members:
            if m.streaming and cause is not None and not m.fault:
                m.latch(f"stopped with its sync group (axis {cause.axis.name}: "
                        f"{cause.latched or 'fault'})")
            m.streaming = False
        log.info("sync group %s: stopped", self.names)
        await asyncio.gather(*(_stop(m) for m in members))


async def _stop(member: Member) -> None:
    with contextlib.suppress(ServobusError):
        await member.axis.stop()
        member.moved = False
