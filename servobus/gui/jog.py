"""Jog while held: constant speed that stops when the button is released, when the page's
WebSocket drops, or when the page stops confirming it is held (a frozen tab, a cable pulled
out of the laptop: the WebSocket may stay open for minutes).

A jog is a lease: the page repeats ``{"type": "jog", ...}`` every 150 ms while the button is
down; :data:`LEASE_S` without one stops the axis. Each axis has at most one jogging owner
(the last page to jog it).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass

from servobus.errors import ConnectionLost, ServobusError
from servobus.gui.fleet import Fleet

log = logging.getLogger(__name__)

LEASE_S = 0.6
WATCH_S = 0.05
MAX_JOG_RPM = 6000


@dataclass
class Lease:
    owner: int
    rpm: int
    until: float


class JogControl:
    def __init__(self, fleet: Fleet, lease_s: float = LEASE_S) -> None:
        self.fleet = fleet
        self.lease_s = lease_s
        self.leases: dict[int, Lease] = {}
        self.stops = 0  # jogs ended by this class (release, drop, lease)
        self.closed = False  # the GUI is shutting down: no new jog
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        self._task = asyncio.create_task(self._watch(), name="gui-jog-watch")

    async def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        await self.stop_all_jogs()

    def close(self) -> None:
        """The GUI shuts down (its stop of every axis follows): refuse jogs, drop leases."""
        self.closed = True
        self.leases.clear()

    async def jog(self, owner: int, axis_id: int, rpm: int) -> None:
        """Start, change or keep jogging ``axis_id`` at ``rpm`` (0 = release)."""
        handle = self.fleet.get(axis_id)
        if self.closed:
            raise ConnectionLost("the GUI is shutting down: every axis is being stopped")
        if isinstance(rpm, bool) or not isinstance(rpm, int) or abs(rpm) > MAX_JOG_RPM:
            raise ValueError(f"jog speed must be an integer rpm within +-{MAX_JOG_RPM}")
        if rpm == 0:
            await self.release(owner, axis_id)
            return
        lease = self.leases.get(axis_id)
        until = time.monotonic() + self.lease_s
        if lease is not None and lease.owner == owner and lease.rpm == rpm:
            lease.until = until
            return
        await handle.call(handle.axis.turn(rpm))  # refused (range, link): no lease taken
        self.leases[axis_id] = Lease(owner, rpm, until)

    async def release(self, owner: int, axis_id: int | None = None) -> None:
        """The button went up (``axis_id``), or every jog of ``owner`` (its page left)."""
        for aid, lease in list(self.leases.items()):
            if lease.owner == owner and (axis_id is None or aid == axis_id):
                await self._end(aid)

    async def stop_all_jogs(self) -> None:
        for aid in list(self.leases):
            await self._end(aid)

    def forget(self) -> None:
        """Drop every lease without commanding (STOP ALL has just stopped the axes)."""
        self.leases.clear()

    async def _end(self, axis_id: int) -> None:
        if self.leases.pop(axis_id, None) is None:
            return
        self.stops += 1
        handle = self.fleet.get(axis_id)
        try:
            await handle.call(handle.axis.stop())
        except ServobusError as exc:  # the watchdog keeps running; the log says why
            log.warning("jog stop of axis %s failed: %s", axis_id, exc)

    async def _watch(self) -> None:
        while True:
            await asyncio.sleep(WATCH_S)
            now = time.monotonic()
            for aid, lease in list(self.leases.items()):
                if now > lease.until:
                    await self._end(aid)
