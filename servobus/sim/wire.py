"""Serial-wire time for the paced virtual lines (protocol-free): when bytes have passed, and
a release queue that hands bytes over at those instants.

A paced line never sleeps per byte. It computes, against the monotonic clock, when each
byte has passed the wire (:class:`WireClock`, 8N1 or any character size) and queues the
delivery of a reply for the instant its last byte has left (:class:`TimedReleases`). The
queue's one task waits precisely: an asyncio sleep for all but the last ``coarse_s`` (an
epoll loop wakes only to the millisecond; a loop on ``servobus.sim.fine_selector`` to the
microsecond, hence the smaller ``FINE_COARSE_S``), a blocking ``time.sleep`` for most of
the rest, then a spin for the final ``spin_s``. The loop is blocked at most ``coarse_s``
per release; a serial line is serial anyway.

Both paced serial lines use them: DYN232M (``protocols/dyn232/pacing.py``) and Modbus RTU
(``protocols/modbus/pacing.py``).
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import time
from collections.abc import Callable

COARSE_S = 0.0015  # epoll-based loops round timeouts up to 1 ms (+ wake-up jitter)
FINE_COARSE_S = 0.0004  # loops on a microsecond selector (servobus.sim.fine_selector)
SPIN_S = 0.00012  # time.sleep overshoots by ~50-100 us (timer slack): spin the last part

Action = Callable[[], None]


class WireClock:
    """One wire (or one direction of it): when the bytes handed to it have passed."""

    def __init__(self, byte_time_s: float) -> None:
        if not byte_time_s > 0:
            raise ValueError(f"byte time must be > 0 s, got {byte_time_s!r}")
        self.byte_time_s = byte_time_s
        self.free_at = 0.0  # monotonic time the wire is next idle

    def send(self, n_bytes: int, ready_at: float) -> tuple[float, float]:
        """Occupy the wire with ``n_bytes`` ready at ``ready_at``; return (start, end)."""
        start = max(ready_at, self.free_at)
        self.free_at = start + n_bytes * self.byte_time_s
        return start, self.free_at


class TimedReleases:
    """Actions run at given monotonic instants, in time order, by one task on the loop."""

    def __init__(self, *, coarse_s: float = COARSE_S, spin_s: float = SPIN_S) -> None:
        self.coarse_s = coarse_s
        self.spin_s = spin_s
        self.max_late_s = 0.0  # worst lateness of a release (diagnostics, benchmarks)
        self._heap: list[tuple[float, int, object, Action]] = []
        self._seq = itertools.count()
        self._task: asyncio.Task[None] | None = None
        self._waiter: asyncio.Future[None] | None = None

    def __len__(self) -> int:
        return len(self._heap)

    def at(self, when: float, action: Action, owner: object = None) -> None:
        """Run ``action`` at ``when``; ``owner`` lets :meth:`drop` remove it unrun."""
        heapq.heappush(self._heap, (when, next(self._seq), owner, action))
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def drop(self, owner: object) -> int:
        """Forget every pending action of ``owner`` (a host that has gone); how many."""
        before = len(self._heap)
        self._heap[:] = [e for e in self._heap if e[2] is not owner]
        heapq.heapify(self._heap)
        return before - len(self._heap)

    def start(self) -> None:
        """Start the release task on the running loop (idempotent)."""
        if self._task is None or self._task.done():
            self._task = asyncio.get_running_loop().create_task(self._run(), name="sim-wire")

    async def close(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        self._heap.clear()

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        heap = self._heap
        while True:
            if not heap:
                await self._wait(loop, None)
                continue
            when = heap[0][0]
            remaining = when - time.monotonic()
            if remaining > self.coarse_s:
                await self._wait(loop, remaining - self.coarse_s)
                continue  # something earlier may have been queued meanwhile
            precise_sleep_until(when, self.spin_s)
            while heap and heap[0][0] <= time.monotonic():
                due, _, _, action = heapq.heappop(heap)
                self.max_late_s = max(self.max_late_s, time.monotonic() - due)
                action()
            await asyncio.sleep(0)  # let the transports move the bytes

    async def _wait(self, loop: asyncio.AbstractEventLoop, timeout: float | None) -> None:
        fut: asyncio.Future[None] = loop.create_future()
        self._waiter = fut
        handle = None if timeout is None else loop.call_later(timeout, _resolve, fut)
        try:
            await fut
        finally:
            self._waiter = None
            if handle is not None:
                handle.cancel()


def _resolve(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


def precise_sleep_until(deadline: float, spin_s: float = SPIN_S) -> None:
    """Block until ``deadline`` (monotonic): sleep, then spin the last ``spin_s``."""
    remaining = deadline - time.monotonic()
    if remaining > spin_s:
        time.sleep(remaining - spin_s)
    while time.monotonic() < deadline:
        pass
