"""Run virtual drives in wall-clock time (servers and the in-process ``sim://`` line).

The drives' simulated time is ``time.monotonic() - t0``. Front ends call ``sync(t)`` before
each packet; a background task calls ``sync()`` every few milliseconds so motion, alarms and
timeouts progress while the line is idle (and no single ``advance`` has to cover a long gap).

``sync`` never moves a drive backwards: the paced line may already have advanced the drives
to the (future) wire arrival time of a queued packet; see :mod:`servobus.protocols.dyn232.pacing`.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Sequence
from typing import Any, Protocol

DEFAULT_TICK_S = 0.004


class Clocked(Protocol):
    """What the clock drives: a VirtualDrive, or another family's motor built on one."""

    @property
    def time(self) -> float: ...

    def advance_to(self, t: float) -> None: ...
  # background advance period (2-5 ms keeps each step short)


async def cancel_and_wait(task: asyncio.Task[Any] | None) -> None:
    """Cancel ``task`` (None: nothing to do) and wait until it has ended (a sim server's
    background task at close)."""
    if task is not None:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


class RealtimeClock:
    """Maps monotonic wall-clock time onto the drives' simulated time."""

    def __init__(self, drives: Sequence[Clocked], *, tick_s: float = DEFAULT_TICK_S) -> None:
        self.drives = drives
        self.tick_s = tick_s
        # Drives created earlier (or stepped by a test) keep their own time: start from it.
        self.t0 = time.monotonic() - max((d.time for d in drives), default=0.0)
        self._task: asyncio.Task[None] | None = None

    def sim_time(self, mono: float | None = None) -> float:
        return (time.monotonic() if mono is None else mono) - self.t0

    def sync(self, mono: float | None = None) -> None:
        """Advance every drive to the simulated time of monotonic instant ``mono`` (now)."""
        t = self.sim_time(mono)
        for drive in self.drives:
            if t > drive.time:
                drive.advance_to(t)

    def start(self) -> None:
        """Start the background ticker on the running event loop (idempotent)."""
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(self._run(), name="sim-clock")

    async def _run(self) -> None:
        while True:
            self.sync()
            await asyncio.sleep(self.tick_s)

    async def stop(self) -> None:
        task, self._task = self._task, None
        await cancel_and_wait(task)
