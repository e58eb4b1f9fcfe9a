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
(``protocols/modbus/pacing.py``), on :class:`PacedLine`: what a serial line in wall-clock time
does whatever its framing (host ports with their receive buffers, reply release, taps,
lifecycle).

Receive buffer (paced; a servobus decision, docs/dyn232.md and docs/modbus.md: neither
manual gives a size). Each host port may have at most ``RX_BUFFER_BYTES`` = 256 bytes
accepted but not yet arrived at the drives; bytes beyond that are lost, as bytes are when a
serial bridge's or UART's receive buffer overflows (RS-485 has no flow control). A host that
waits for its replies never loses a byte; a flood costs the line a bounded time, and no
memory. Replies still pending for a port that closes are dropped (``close_port``).
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Generic, TypeVar

from servobus.sim.wall_clock import Clocked, RealtimeClock, cancel_and_wait
from servobus.transport.base import Direction, TraceHook

COARSE_S = 0.0015  # epoll-based loops round timeouts up to 1 ms (+ wake-up jitter)
FINE_COARSE_S = 0.0004  # loops on a microsecond selector (servobus.sim.fine_selector)
SPIN_S = 0.00012  # time.sleep overshoots by ~50-100 us (timer slack): spin the last part
RX_BUFFER_BYTES = 256  # per host port, accepted ahead of the wire (see the module doc)

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
        await cancel_and_wait(task)
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


class PacedPort:
    """One host connection on a paced line (TCP client, PTY, in-process stream)."""

    def __init__(self, deliver: Callable[[bytes], None]) -> None:
        self._deliver = deliver
        self.closed = False
        self.pending = 0  # paced replies scheduled for this port, not yet released
        self.on_idle: Callable[[], None] | None = None  # called when ``pending`` drops to 0
        self.rx_queued = 0  # bytes accepted, not yet arrived (paced receive buffer)
        self.rx_inflight: deque[tuple[float, int]] = deque()  # (arrival of the last, count)
        self.rx_dropped = 0  # bytes lost to a full receive buffer

    def deliver(self, data: bytes) -> None:
        if not self.closed:
            self._deliver(data)


P = TypeVar("P", bound=PacedPort)


class PacedLine(Generic[P]):
    """The framing-free half of a serial line in wall-clock time; a protocol's runner adds
    ``open_port`` and ``submit`` (framing, execution, the wire's direction model)."""

    def __init__(self, drives: Sequence[Clocked], clock: RealtimeClock | None, *,
                 paced: bool, coarse_s: float, spin_s: float) -> None:
        self.clock = clock if clock is not None else RealtimeClock(drives)
        self.paced = paced
        self.releases = TimedReleases(coarse_s=coarse_s, spin_s=spin_s)
        self.rx_buffer_bytes = RX_BUFFER_BYTES
        self.rx_dropped = 0  # bytes lost to full receive buffers, all ports
        self.taps: list[TraceHook] = []

    def start(self) -> None:
        """Start the clock ticker and the release task on the running loop (idempotent)."""
        self.clock.start()
        if self.paced:
            self.releases.start()

    async def close(self) -> None:
        await self.clock.stop()
        await self.releases.close()

    def close_port(self, port: P) -> None:
        """The host has gone: its pending replies are dropped (memory freed at once)."""
        port.closed = True
        port.on_idle = None
        if port.pending:
            port.pending = 0
            self.releases.drop(port)

    def add_tap(self, hook: TraceHook) -> None:
        """``hook(direction, bytes, monotonic time)`` for everything on the line, in order."""
        self.taps.append(hook)

    @property
    def max_late_s(self) -> float:
        """Worst lateness of a release (diagnostics, benchmarks)."""
        return self.releases.max_late_s

    def _accept(self, port: P, data: bytes, now: float, wire: WireClock
                ) -> tuple[bytes, float, float]:
        """Put on ``wire`` the part of ``data`` that fits the port's receive buffer (module
        doc): (that part, possibly empty; when it starts; when its last byte has arrived)."""
        inflight = port.rx_inflight
        while inflight and inflight[0][0] <= now:
            port.rx_queued -= inflight.popleft()[1]
        room = self.rx_buffer_bytes - port.rx_queued
        if room < len(data):
            lost = len(data) - max(room, 0)
            port.rx_dropped += lost
            self.rx_dropped += lost
            data = data[:room] if room > 0 else b""
        if not data:
            return data, now, now
        start, end = wire.send(len(data), now)
        inflight.append((end, len(data)))
        port.rx_queued += len(data)
        return data, start, end

    def _reply_at(self, port: P, reply: bytes, when: float) -> None:
        """Hand ``reply`` to ``port`` (and the taps) at ``when``, when its last byte has left."""
        port.pending += 1

        def release() -> None:
            port.pending -= 1
            if self.taps:
                self._tap(Direction.RX, reply, when)
            port.deliver(reply)
            if not port.pending and port.on_idle is not None:
                port.on_idle()

        self.releases.at(when, release, port)

    def _tap(self, direction: Direction, data: bytes, when: float) -> None:
        for hook in self.taps:
            hook(direction, data, when)
